MODULE Semi
  VAR num a := 1
  VAR num b := 2;
ENDMODULE
