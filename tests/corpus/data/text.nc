time,intensity
0,1
