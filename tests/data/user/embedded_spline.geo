// A square with an embedded spline (Curve In Surface, as in gmsh's benchmarks) carried by an
// unused physical curve "crack", and a physical point "corner": groups a scene does not use.
//   gmsh -2 embedded_spline.geo -format msh41 -o embedded_spline.msh
//   ... -setnumber Mesh.SaveParametric 1 -o embedded_spline_parametric.msh
//   ... -part 2 -o embedded_spline_partitioned.msh
h = 0.2;
Point(1) = {0, 0, 0, h}; Point(2) = {2, 0, 0, h}; Point(3) = {2, 1, 0, h}; Point(4) = {0, 1, 0, h};
Point(5) = {0.5, 0.3, 0, h}; Point(6) = {1.0, 0.6, 0, h}; Point(7) = {1.5, 0.4, 0, h};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Spline(5) = {5, 6, 7};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Curve{5} In Surface{1};
Physical Curve("Γ1", 1) = {4};
Physical Curve("Γ2", 2) = {3, 2};
Physical Curve("Γ3,1", 3) = {1};
Physical Curve("crack", 7) = {5};
Physical Point("corner", 8) = {1};
Physical Surface("Ω", 10) = {1};
