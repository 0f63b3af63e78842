// patch_square.geo -- an unstructured unit square for the constant-strain patch test
// (tests/solutions/patch.rs): "Γ1" = left edge x = 0 (clamped), "Γ2" = bottom, right and top edges.
//   gmsh -2 patch_square.geo -format msh41 -o patch_square.msh
SetFactory("Built-in");
lc = 0.23;
Point(1) = {0, 0, 0, lc};
Point(2) = {1, 0, 0, lc*0.6};
Point(3) = {1, 1, 0, lc};
Point(4) = {0, 1, 0, lc*1.4};
Point(5) = {0.43, 0.57, 0, lc*0.3};
Line(1) = {1, 2};
Line(2) = {2, 3};
Line(3) = {3, 4};
Line(4) = {4, 1};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Point{5} In Surface{1};
Physical Curve("Γ1", 1) = {4};
Physical Curve("Γ2", 2) = {1, 2, 3};
Physical Surface("Ω", 10) = {1};
Mesh.Algorithm = 6;
