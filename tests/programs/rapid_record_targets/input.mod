MODULE Records
  RECORD targetdata
    robtarget pos;
    num speed;
  ENDRECORD
  VAR targetdata Welds{2} := [[[[900,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],5],
    [[[900,0,810],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],5]];
  PROC main()
    ! MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tool0;
    MoveL Welds{1}.pos, v100, fine, tool0;
    MoveL Offs([[900,0,600],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],0,0,10), v100, fine, tool0;
  ENDPROC
ENDMODULE
