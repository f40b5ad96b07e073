%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE CellA
  ! Zelle A: Schweißvorrichtung für Prüfteil Ø40, Bediener: Jürgen Müller
  ! ABB IRB 2400/16 (reach 1.55 m), targets written offline, tool pointing down
  PERS tooldata tGun:=[TRUE,[[120.5,0,210],[0.92388,0,0.382683,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];
  TASK PERS wobjdata wTable:=[FALSE,TRUE,"",[[700,-300,300],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST speeddata vWeld:=[25,500,5000,1000];
  CONST zonedata zTight:=[FALSE,1,1,1,0.1,1,0.1];
  CONST jointtarget jHome:=[[0,0,0,0,30,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pApproach:=[[950,0,1100],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p10:=[[1020.35,-250.4,620.1],[0.0436194,0,0.999048,0],[-1,1,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p20:=[[1100,-120.75,540.5],[0,0,1,0],[-1,0,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p30:=[[1150.2,0,500],[0,0,1,0],[0,-2,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p40:=[[1100,120.75,540.5],[0,0,1,0],[0,-1,1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p50:=[[1020.35,250.4,620.1],[0.0436194,0,0.999048,0],[0,-2,1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget p60:=[[880,400,750],[0,0.258819,0.965926,0],[0,-1,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p70:=[[760.5,-480,900.25],[0,-0.258819,0.965926,0],[-1,0,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p80:=[[1190,-60,350],[0.0871557,0,0.996195,0],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p90:=[[1190,60,350],[0.0871557,0,0.996195,0],[0,-2,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p100:=[[705,-100,1180],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p110:=[[705,100,1180],[0,0,1,0],[0,-1,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p120:=[[990,-330,420],[0,0,1,0],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p130:=[[990,330,420],[0,0,1,0],[0,-2,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p140:=[[1.05E+03,0,8.5E+02],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  ! weld seam on the table, in the work object wTable (x 0..400, y 0..600, z 0..500 mm)
  CONST robtarget pWeld{6}:=[
    [[50,100,20],[0,0,1,0],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[120,100,20],[0,0,1,0],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[190,100,20],[0,0,1,0],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[260,100,20],[0,0,1,0],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[330,100,20],[0,0,1,0],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[400,100,20],[0,0,1,0],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
  PERS robtarget pPick:=[[200,450,120.5],[0,0.707107,0.707107,0],[0,-1,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PERS robtarget pPlace:=[[380,520,80],[0,0.707107,0.707107,0],[0,-1,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pService:=[[800,0,1000],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR num nCycle:=0;

  PROC main()
    MoveAbsJ jHome\NoEOffs, v1000, z50, tool0;
    MoveJ pApproach, v1000, z50, tGun;
    MoveL p10, v500, z10, tGun;
    MoveL p20, v500, z10, tGun;
    MoveC p30, p40, v200, z10, tGun;
    MoveL p50, v500, z10, tGun;
    MoveJ p60, v1000, z50, tGun;
    MoveJ p70, v1000, z50, tGun;
    MoveL p80, v200, fine, tGun;
    MoveL p90, v200, fine, tGun;
    MoveJ p100, v1000, z50, tGun;
    MoveJ p110, v1000, z50, tGun;
    MoveL p120, v500, z10, tGun;
    MoveL p130, v500, z10, tGun;
    MoveL p140, v500, z10, tGun;
    weld_seam;
    MoveL [[1000.5,250,600],[0.0436194,0,0.999048,0],[0,-2,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v500, fine, tGun;
    MoveJ pApproach, v1000, z50, tGun;
    MoveAbsJ jHome\NoEOffs, v1000, z50, tool0;
  ENDPROC

  PROC weld_seam()
    MoveJ Offs(pWeld{1}, 0, 0, 50), v1000, z50, tGun\WObj:=wTable;
    FOR i FROM 1 TO 6 DO
      MoveL pWeld{i}, vWeld, zTight, tGun\WObj:=wTable;
    ENDFOR
    MoveL RelTool(pWeld{6}, 0, 0, -50), v500, z10, tGun\WObj:=wTable;
    IF nCycle > 100 THEN
      nCycle := 0;
    ELSE
      Incr nCycle;
    ENDIF
    MoveJ pPick, v1000, z20, tGun\WObj:=wTable;
    MoveL pPlace, v500, fine, tGun\WObj:=wTable;
  ENDPROC
ENDMODULE
