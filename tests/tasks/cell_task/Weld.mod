MODULE Weld
  ! a LOCAL work object hides the global wTable in this module only
  LOCAL PERS wobjdata wTable:=[FALSE,TRUE,"",[[760,-80,380],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget pWeld10:=[[120,40,30],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pWeld20:=[[180,60,30],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pWeld30:=[[150,-20,60],[0,0.087156,0.996195,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PERS robtarget pShared:=[[100,100,50],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];

  PROC weld_seam()
    MoveJ pWeld10,v200,z10,tGun\WObj:=wTable;
    MoveL pWeld20,v100,fine,tGun\WObj:=wTable;
    MoveL pWeld30,v100,fine,tGun\WObj:=wTable;
  ENDPROC

  PROC approach(robtarget p)
    MoveL Offs(p,0,0,100),v200,z10,tGrip\WObj:=wFixture;
  ENDPROC
ENDMODULE
