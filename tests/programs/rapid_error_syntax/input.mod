MODULE Syn
  PROC main()
    MoveL p1, v100, fine, tool0;
    IF x > THEN
    ENDIF
  ENDPROC
ENDMODULE
