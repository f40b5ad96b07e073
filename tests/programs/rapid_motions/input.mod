MODULE Moves
  PERS tooldata tWeld:=[TRUE,[[0,0,300],[1,0,0,0]],[3,[0,0,100],[1,0,0,0],0,0,0]];
  PERS wobjdata wFix:=[FALSE,TRUE,"",[[600,0,200],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget p1:=[[100,0,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p2:=[[200,0,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p3:=[[300,0,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pFound;
  PROC main()
    MoveL [[400,50,60],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,z10,tWeld\WObj:=wFix;
    MoveAbsJ [[0,0,0,0,90,0],[9E9,9E9,9E9,9E9,9E9,9E9]]\NoEOffs,v1000,z50,tool0;
    MoveL \Conc, p1, v100, z10, tWeld\WObj:=wFix;
    MoveJ p2, v100\V:=120, z10\Z:=15, tWeld \WObj:=wFix \TLoad:=load0;
    MoveL p3\ID:=10, v100, fine, tWeld\WObj?wFix;
    MoveLDO p1, v100, fine, tWeld, do1, 1;
    SearchL \Stop, di1, pFound, p2, v50, tWeld\WObj:=wFix;
    ArcLStart p1, v100, seam1, weld1, fine, tWeld\WObj:=wFix;
    ArcL p2, v100, seam1, weld1\Weave:=weave1, z1, tWeld\WObj:=wFix;
    ArcC p2, p3, v100, seam1, weld1, z1, tWeld\WObj:=wFix;
    ArcLEnd p3, v100, seam1, weld1, fine, tWeld\WObj:=wFix;
    SyncMoveOn sync1, all_tasks;
    MoveL p1\ID:=20, v100, fine, tWeld\WObj:=wFix;
    SyncMoveOff sync2;
    ConfL \Off;
    SingArea \Wrist;
    MoveC p1, p2, v100, z10, tWeld
      \WObj:=wFix;
    MoveL p3, v100, fine, [TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,10],[1,0,0,0],0,0,0]];
  ENDPROC
ENDMODULE
