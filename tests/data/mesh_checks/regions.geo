// regions.geo -- two unit squares side by side (surface 1 left, surface 2 right, sharing
// the line x = 1) in three overlapping physical surfaces, defined in this order:
// "Ω" = 10 = {1, 2}, "inner" = 5 = {2}, "left" = 20 = {1}.  gmsh writes $PhysicalNames
// sorted by tag, so the output's `region` holds 5 on surface 2 and 10 on surface 1
// (docs/meshes.md).  Issue 26, finding 9.
//
//   gmsh -2 regions.geo -format msh41 -o regions.msh
h = 0.5;
Point(1) = {0, 0, 0, h};
Point(2) = {1, 0, 0, h};
Point(3) = {2, 0, 0, h};
Point(4) = {2, 1, 0, h};
Point(5) = {1, 1, 0, h};
Point(6) = {0, 1, 0, h};
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
Physical Surface("Ω", 10) = {1, 2};
Physical Surface("inner", 5) = {2};
Physical Surface("left", 20) = {1};
