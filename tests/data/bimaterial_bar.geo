// bimaterial_bar.geo -- the bar (0,2) x (0,1) of two materials bonded along x = 1, for
// `[[material.region]]` (tests/solutions/regions.rs): surface 1 (x < 1) and surface 2
// (x > 1) share the line x = 1, so the mesh has element edges on the interface and the
// piecewise linear displacement of the bar in tension is exactly P1. Unstructured.
//   "Γ1"    = 1  : left edge x = 0 (clamped)
//   "Γ2"    = 2  : right edge x = 2 (the traction boundary), "right" = 6 : the same edge
//   "bond"  = 7  : the interface x = 1 (a curve: refused as a region)
//   "soft"  = 11 : surface 1,  "stiff" = 12 : surface 2,  "Ω" = 10 : both (overlaps them)
//
//   gmsh -2 bimaterial_bar.geo -format msh41 -o bimaterial_bar.msh
SetFactory("Built-in");
lc = 0.3;
Point(1) = {0, 0, 0, lc};
Point(2) = {1, 0, 0, lc*0.7};
Point(3) = {2, 0, 0, lc};
Point(4) = {2, 1, 0, lc*1.2};
Point(5) = {1, 1, 0, lc*0.8};
Point(6) = {0, 1, 0, lc};
Line(1) = {1, 2};
Line(2) = {2, 5};
Line(3) = {5, 6};
Line(4) = {6, 1};
Line(5) = {2, 3};
Line(6) = {3, 4};
Line(7) = {4, 5};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Curve Loop(2) = {5, 6, 7, -2};
Plane Surface(2) = {2};
Physical Curve("Γ1", 1) = {4};
Physical Curve("Γ2", 2) = {6};
Physical Curve("right", 6) = {6};
Physical Curve("bond", 7) = {2};
Physical Surface("Ω", 10) = {1, 2};
Physical Surface("soft", 11) = {1};
Physical Surface("stiff", 12) = {2};
Mesh.Algorithm = 6;
