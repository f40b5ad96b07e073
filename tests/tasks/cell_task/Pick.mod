MODULE Pick
  CONST robtarget pPick10:=[[50,20,40],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pPick20:=[[60,-30,80],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pTable:=[[200,170,20],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pLost:=[[150,100,100],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pNever:=[[180,90,120],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  ! the same persistent as in Weld: one variable
  PERS robtarget pShared:=[[100,100,50],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];

  PROC pick()
    MoveJ pPick10,v500,z20,tGrip\WObj:=wFixture;
    MoveL pPick20,v200,fine,tGrip\WObj:=wFixture;
    MoveL pShared,v200,fine,tGrip\WObj:=wFixture;
    MoveL pTable,v200,fine,tGun\WObj:=wTable;
    MoveL pService,v200,fine,tProbe;
    approach pPick10;
    MoveL pLost,v100,fine,tMissing\WObj:=wTable;
  ENDPROC
ENDMODULE
