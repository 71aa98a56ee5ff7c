( LinuxCNC post, inch, radius-format arcs )
( generated in the style of a LinuxCNC/EMC2 post: lower case, spaces, ; comments )
g20 g17 g40 g49 g80 g90 g94 ; units inch
g64 p0.0005
g91.1
t3 m6 ; 1/4" flat end mill
s10000 m3
m8
g54
g0 x0.0000 y0.0000
g0 z0.2000
g1 z-0.0500 f12.0
; slot with a semicircular end, R form (<= 180 deg with R > 0)
g1 x1.0000 f30.0
g3 x1.0000 y0.5000 r0.2500
g1 x0.0000
; 270 deg arc: R < 0 selects the large arc
g2 x-0.2500 y0.2500 r-0.2500
; full circle in centre format around (0.5, 0.25)
g1 x0.7500 y0.2500
g3 x0.7500 y0.2500 i-0.2500 j0.0000
/ g1 x0.7500 y0.2500 z-0.0800 ; optional deeper pass
g4 p0.5 ; dwell 0.5 s
; helical bore, two turns in one block with P
g0 z0.0500
g0 x2.1000 y0.2500
g1 z0.0000 f12.0
g3 x2.1000 y0.2500 z-0.1000 i-0.1000 j0.0000 p2
g1 x2.0000
g0 z0.2000
m9
m5
m2
