MODULE Named
  PERS tooldata tGun:=[TRUE,[[0,0,200],[1,0,0,0]],[2,[0,0,50],[1,0,0,0],0,0,0]];
  CONST robtarget p10:=[[900,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR jointtarget jt;
  PROC main()
    MoveL p10, v100, fine, Tool:=tGun;
    MoveJ ToPoint:=p10, v200, z10, tool0;
    MoveL ToPoint := [[910,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, Tool:=tGun \WObj:=wobj0;
    jt := CalcJointT(p10, Tool:=tGun \WObj:=wobj0);
  ENDPROC
ENDMODULE
