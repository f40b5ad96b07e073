MODULE Copies
  PERS tooldata tTorch:=[TRUE,[[0,0,250],[1,0,0,0]],[2,[0,0,50],[1,0,0,0],0,0,0]];
  CONST robtarget pStart:=[[900,0,700],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pA;
  VAR robtarget pB;
  PROC main()
    pA := [[900,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    MoveL pA, v100, fine, tTorch;
    pB := pStart;
    ArcLStart pB, v100, seam1, weld1, fine, tTorch;
    pA := [[950,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    MoveJ pA, v100, z10, tTorch;
  ENDPROC
ENDMODULE
