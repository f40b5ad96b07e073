MODULE Crlf
  ! Température 23 °C, Schweißnaht Ø 6 mm
  CONST robtarget pX:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]; ! fin de ligne é
  PROC main()
    MoveL pX, v100, fine, tool0;
  ENDPROC
ENDMODULE
