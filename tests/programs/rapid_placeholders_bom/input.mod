%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%
MODULE Holes
  CONST robtarget p1:=[[900,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR num <ID>;
  VAR num count{<DIM>};
  PROC main()
    <SMT>
    MoveL p1, v100, fine, tool0;
    IF <EXP> THEN
      <SMT>
    ENDIF
    WaitTime <ARG>;
    MoveL <EXP>, v100, fine, tool0;
    count{1} := <VAR>;
  ENDPROC
ENDMODULE
