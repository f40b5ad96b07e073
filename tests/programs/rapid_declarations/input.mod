%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

module Decls(SYSMODULE, NOSTEPIN, VIEWONLY)
  ! numbers in every style RAPID writes
  CONST robtarget pA:=[[9E9,9E+09,9E+9],[1,0,0,0],[0,0,0,0],[9E9,9E+09,9E+9,9E9,9E9,9E9]];
  pers robtarget pB := [ [ 1.10307E-06 , -0.5 , +12 ] , [ 2 , 0 , 0 , 0 ] , [ -1 , 0 , -1 , 1 ] , [ 0 , 0 , 0 , 0 , 0 , 0 ] ];
  VAR robtarget pC:=[[.5,5.,0.25],[0.5,0.5,0.5,0.5],[0,-1,2,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  LOCAL CONST robtarget pD:=[[1,2,3],[0.707107,0,0.707107,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  TASK PERS robtarget pE:=[[4,5,6],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST jointtarget jA:=[[0,-10.5,20,0,90,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PERS tooldata tA:=[TRUE,[[0,0,150],[1,0,0,0]],[1.5,[0,0,50],[1,0,0,0],0,0,0]];
  PERS tooldata tFixed:=[FALSE,[[500,300,400],[0,0,1,0]],[0.001,[0,0,0.001],[1,0,0,0],0,0,0]];
  PERS wobjdata wA:=[FALSE,TRUE,"",[[1000,0,0],[0.707107,0,0,0.707107]],[[10,20,0],[1,0,0,0]]];
  PERS wobjdata wConv:=[FALSE,FALSE,"CNV1",[[0,0,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST speeddata vA:=[100,500,5000,1000];
  CONST zonedata zA:=[FALSE,1,1,1,0.1,1,0.1];
  CONST confdata cA:=[0,0,0,0];
  RECORD pair
    num a;
    string label;
  ENDRECORD
  CONST pair prA:=[1,"a [bracket] in a string"];
  VAR robtarget pTemp;
  VAR num reg{3}:=[1,2,3];
ENDmodule
