MODULE Runtime
  CONST robtarget p10:=[[500,0,400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pWork:=[[600,0,400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pNow;
  PROC main()
    MoveL Offs(p10, 0, 0, 50), v100, z10, tool0;
    MoveL RelTool(p10, 0, 0, -20 \Rz:=45), v100, z10, tool0;
    pNow := CRobT(\Tool:=tool0 \WObj:=wobj0);
    pWork.trans.z := pWork.trans.z + 10;
    MoveL pWork, v100, fine, tool0;
    MoveL pNow, v100, fine, tool0;
    go_to p10;
    MoveL *, v100, fine, tool0;
  ENDPROC
  PROC go_to(robtarget target)
    MoveJ target, v200, z10, tool0;
  ENDPROC
ENDMODULE
