MODULE Flow
  CONST robtarget pA:=[[1,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pB:=[[2,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR intnum irStop;
  VAR num n:=0;
  PROC main()
    IF n > 2 AND NOT n = 5 THEN
      MoveL pA, v100, fine, tool0;
    ELSEIF n = 1 THEN
      MoveL pB, v100, fine, tool0;
    ELSE
      Stop;
    ENDIF
    IF n < 0 MoveJ pA, v100, fine, tool0;
    FOR i FROM 10 TO 1 STEP -1 DO
      n := n + i * 2 DIV 3 MOD 4;
    ENDFOR
    WHILE n < 10 DO
      Incr n;
    ENDWHILE
    TEST n
    CASE 1, 2:
      MoveJ pB, v100, z10, tool0;
    CASE 3:
      %"routine" + NumToStr(n, 0)% pA;
    DEFAULT:
      TPWrite "n = " \Num:=n;
    ENDTEST
    CONNECT irStop WITH tStop;
  next:
    GOTO next;
  ERROR
    IF ERRNO = ERR_PATH_STOP THEN
      RETRY;
    ENDIF
    TRYNEXT;
  ENDPROC
  FUNC num twice(num x)
    RETURN 2 * x;
  ENDFUNC
  TRAP tStop
    StopMove;
  ENDTRAP
ENDMODULE
