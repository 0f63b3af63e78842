// overlap.geo -- the rectangle (0,2)x(0,1) with its bottom split at x = 1 (C1, C2) and the
// contact group "Γ3,1" = {C1, C2} overlapping the friction group "Γ3,2" = {C2}: the edges
// of C2 would carry both conditions.  Issue 26, finding 9.
//
//   gmsh -2 overlap.geo -format msh41 -o overlap.msh
h = 0.125;
Point(1) = {0, 0, 0, h};
Point(2) = {1, 0, 0, h};
Point(3) = {2, 0, 0, h};
Point(4) = {2, 1, 0, h};
Point(5) = {0, 1, 0, h};
Line(1) = {1, 2};
Line(2) = {2, 3};
Line(3) = {3, 4};
Line(4) = {4, 5};
Line(5) = {5, 1};
Curve Loop(1) = {1, 2, 3, 4, 5};
Plane Surface(1) = {1};
Physical Curve("Γ1", 1) = {5};
Physical Curve("Γ2", 2) = {3, 4};
Physical Curve("Γ3,1", 3) = {1, 2};
Physical Curve("Γ3,2", 4) = {2};
Physical Surface("Ω", 10) = {1};
