MODULE Values
  CONST robtarget pPath{4}:=[
    [[900,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[900,50,800],[0,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[900,100,800],[0,0,1,0],[0,1E309,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[900,150,800],[0,0,1,0],[0,0,1e308,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
  PROC main()
    FOR i FROM 1 TO 4 DO
      MoveL pPath{i}, v100, z10, tool0;
    ENDFOR
  ENDPROC
ENDMODULE
