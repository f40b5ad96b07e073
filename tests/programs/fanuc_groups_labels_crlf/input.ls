/PROG  INPUT
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "sequence";
PROG_SIZE	= 0;
CREATE		= DATE 24-06-11  TIME 14:02:10;
MODIFIED	= DATE 24-06-11  TIME 14:02:10;
FILE_NAME	= INPUT;
VERSION		= 0;
LINE_COUNT	= 6;
MEMORY_SIZE	= 0;
PROTECT		= READ_WRITE;
TCD:  STACK_SIZE	= 0,
      TASK_PRIORITY	= 50,
      TIME_SLICE	= 0,
      BUSY_LAMP_OFF	= 0,
      ABORT_REQUEST	= 0,
      PAUSE_REQUEST	= 0;
DEFAULT_GROUP	= 1,1,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/MN
   1:  UTOOL_NUM=2 ;
   2:  UFRAME_NUM=0 ;
   3:J P[1:App] 100% FINE    ;
   4:L P[2] 250mm/sec CNT100    ;
   5:L P[R[3]] 250mm/sec FINE    ;
   6:J P[3] 100% FINE    ;
/POS
P[1:App]{
   GP1:
	UF : 0, UT : 0,		CONFIG : 'F U T, 0, 0, 0',
	X =	2226.385	mm,	Y =	218.873	mm,	Z =	1208.093	mm,
	W =	37.888	deg,	P =	-44.402	deg,	R =	144.729	deg
   GP2:
	UF : 0, UT : 0,	
	J1=     6.425 deg
};
P[2]{
   GP1:
	UF : 0, UT : 0,		CONFIG : 'N U T, 0, 0, 0',
	X =	1686.506	mm,	Y =	-194.801	mm,	Z =	654.989	mm,
	W =	-152.194	deg,	P =	-4.589	deg,	R =	-6.609	deg
   GP2:
	UF : 0, UT : 0,	
	J1=   -12.500 deg
};
P[3]{
   GP1:
	UF : 0, UT : F,		CONFIG : 'N U T, 0, 0, 0',
	X =	1686.506	mm,	Y =	-194.801	mm,	Z =	754.989	mm,
	W =	-152.194	deg,	P =	-4.589	deg,	R =	-6.609	deg
   GP2:
	UF : 0, UT : 0,	
	J1=     0.000 deg
};
/END
