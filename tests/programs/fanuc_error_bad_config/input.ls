/PROG  INPUT
/ATTR
OWNER		= MNEDITOR;
/MN
   1:J P[1] 100% FINE    ;
/POS
P[1]{
   GP1:
	UF : 0, UT : 0,		CONFIG : 'N X T, 0, 0, 0',
	X =  1800.000  mm,	Y =      .000  mm,	Z =   900.000  mm,
	W =   180.000 deg,	P =      .000 deg,	R =      .000 deg
};
/END
