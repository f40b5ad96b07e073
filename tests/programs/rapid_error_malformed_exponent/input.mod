MODULE Bad
  PROC main()
    MoveL [[900,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,1e,9E9,9E9,9E9]], v100, fine, tool0;
  ENDPROC
ENDMODULE
