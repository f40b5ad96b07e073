MODULE Arrays
  CONST robtarget row{3}:=[[[10,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],[[20,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],[[30,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
  ! a 2 x 2 grid over several lines, with comments inside the value
  PERS robtarget grid{2,2}:=[
    [ ! first row
      [[100,100,50],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
      [[100,200,50],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]
    ],
    [ ! second row
      [[200,100,50],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
      [[200,200,50],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]
    ]
  ];
  CONST jointtarget jrow{2}:=[[[0,0,0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],[[10,0,0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
  PROC main()
    MoveL row{2}, v100, fine, tool0;
    MoveJ grid{2,1}, v100, z10, tool0;
    MoveAbsJ jrow{1}, v100, fine, tool0;
  ENDPROC
ENDMODULE
