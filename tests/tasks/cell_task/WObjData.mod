MODULE WObjData
  ! work objects of the cell
  PERS wobjdata wTable:=[FALSE,TRUE,"",[[700,-150,420],[0.996195,0,0,0.087156]],[[0,0,0],[1,0,0,0]]];
  TASK PERS wobjdata wFixture:=[FALSE,TRUE,"",[[850,250,300],[1,0,0,0]],[[10,5,0],[0.999048,0,0,-0.043619]]];
ENDMODULE
