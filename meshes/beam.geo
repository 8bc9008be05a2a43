// Structured hexahedral mesh of the unit beam block (x, eta, zeta) in [0,1] x [-1/2,1/2]^2.
// fxflex (fxflex/mesh/solid.py) maps every node onto the twisted tapered beam afterwards:
// X = R + L x, (Y, Z) = rotation(theta(x)) . (b(x) eta, h(x) zeta)  -- see fxflex/mesh/geometry.py.
// Divisions come in through ONELAB: nx along the length, ny along y~, nz along z~.
DefineConstant[ nx = {100, Name "nx"}, ny = {12, Name "ny"}, nz = {6, Name "nz"} ];

Point(1) = {0, -0.5, -0.5};
Point(2) = {0,  0.5, -0.5};
Line(1) = {1, 2};
Transfinite Curve{1} = ny + 1;
root[] = Extrude {0, 0, 1} { Curve{1}; Layers{nz}; Recombine; };     // root[1]: face x = 0
body[] = Extrude {1, 0, 0} { Surface{root[1]}; Layers{nx}; Recombine; }; // body[0]: face x = 1

Physical Surface("root", 1) = {root[1]};
Physical Surface("tip", 2) = {body[0]};
Physical Volume("beam", 1) = {body[1]};
