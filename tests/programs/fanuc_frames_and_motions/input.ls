/PROG  INPUT
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "golden case";
PROG_SIZE	= 1520;
CREATE		= DATE 24-05-02  TIME 09:14:20;
MODIFIED	= DATE 24-05-02  TIME 09:30:02;
FILE_NAME	= ;
VERSION		= 0;
LINE_COUNT	= 12;
MEMORY_SIZE	= 1980;
PROTECT		= READ_WRITE;
TCD:  STACK_SIZE	= 0,
      TASK_PRIORITY	= 50,
      TIME_SLICE	= 0,
      BUSY_LAMP_OFF	= 0,
      ABORT_REQUEST	= 0,
      PAUSE_REQUEST	= 0;
DEFAULT_GROUP	= 1,*,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/APPL
/MN
   1:  UFRAME_NUM=0 ;
   2:  UTOOL_NUM=0 ;
   3:  !Approach the fixture ;
   4:J P[1:"Approach"] 100% FINE    ;
   5:L P[2] 500mm/sec CNT50    ;
   6:C P[3]    
    :  P[4] 200mm/sec FINE    ;
   7:L PR[5:Drop] 300mm/sec FINE    ;
   8:L P[2] 500mm/sec FINE Offset,PR[2]    ;
   9:  //L P[7] 100mm/sec FINE    ;
  10:J P[8] 50% CNT100    ;
  11:  UFRAME_NUM=1 ;
  12:L P[6] 100mm/sec FINE    ;
/POS
P[1:"Approach"]{
   GP1:
	UF : 0, UT : 0,		CONFIG : 'N U T, 0, 0, 0',
	X =  2092.343  mm,	Y =   332.616  mm,	Z =   849.420  mm,
	W =   144.589 deg,	P =   -24.014 deg,	R =    55.783 deg
};
P[2]{
   GP1:
	UF : 0, UT : 0,		CONFIG : 'N U T, 0, 0, 0',
	X =  1750.643  mm,	Y =  -754.184  mm,	Z =  1252.238  mm,
	W =  -132.812 deg,	P =   -13.401 deg,	R =   -82.444 deg
};
P[3]{
   GP1:
	UF : 0, UT : 0,		CONFIG : 'N U T, 0, 0, 0',
	X =  2074.176  mm,	Y =  1117.736  mm,	Z =   513.167  mm,
	W =   133.401 deg,	P =    17.272 deg,	R =   110.477 deg
};
P[4]{
   GP1:
	UF : 0, UT : 0,		CONFIG : 'N U T, 0, 0, 0',
	X =  1940.747  mm,	Y =      .708  mm,	Z =   717.426  mm,
	W =   172.454 deg,	P =   -13.796 deg,	R =    13.345 deg
};
P[6]{
   GP1:
	UF : F, UT : 0,		CONFIG : 'N U T, 0, 0, 0',
	X =   400.000  mm,	Y =   120.500  mm,	Z =    55.000  mm,
	W =   180.000 deg,	P =      .000 deg,	R =    90.000 deg
};
P[7]{
   GP1:
	UF : 0, UT : 0,		CONFIG : 'N U T, 0, 0, 0',
	X =  1800.000  mm,	Y =      .000  mm,	Z =   900.000  mm,
	W =   180.000 deg,	P =      .000 deg,	R =      .000 deg
};
P[8]{
   GP1:
	UF : 0, UT : 0,	
	J1=    10.000 deg,	J2=    20.000 deg,	J3=   -10.000 deg,
	J4=    15.000 deg,	J5=   -40.000 deg,	J6=    30.000 deg
};
/END
