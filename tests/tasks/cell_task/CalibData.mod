MODULE CalibData
  ! the cell's tools, kept apart from the motions
  PERS tooldata tGun:=[TRUE,[[12.5,-3.2,215.4],[0.976296,0,0.21644,0]],[2.1,[0,0,90],[1,0,0,0],0,0,0]];
  PERS tooldata tGrip:=[TRUE,[[0,0,165],[1,0,0,0]],[1.2,[0,0,60],[1,0,0,0],0,0,0]];
ENDMODULE
