MODULE Open
  CONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9];
  PROC main()
  ENDPROC
ENDMODULE
