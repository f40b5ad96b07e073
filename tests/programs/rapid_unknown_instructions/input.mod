MODULE Unknown
  CONST robtarget pWeld:=[[900,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveL pWeld, v100, fine, tool0;
    ArcAdaptLStart [[500,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,adapt1,seam1,weld1,weave1,fine,tool0,track1;
    LaserTrackL pWeld, v100, fine, tool0;
    Helper pWeld;
  ENDPROC
  PROC Helper(robtarget p)
    MoveL p, v100, fine, tool0;
  ENDPROC
ENDMODULE
