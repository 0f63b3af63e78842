// unfragmented.geo -- two OpenCASCADE rectangles (0,1)x(0,1) and (1,2)x(0,1) that touch
// along x = 1 but were NOT fragmented (the forgotten BooleanFragments): each surface is
// meshed on its own, so the interface carries two copies of every node and no triangle
// connects the halves.  Issue 26, finding 7.
//
//   gmsh -2 unfragmented.geo -format msh41 -o unfragmented.msh
//
// Groups: "Γ1" = left side x = 0, "ends" = both sides x = 0 and x = 2 (clamps both halves),
// "Γ2" = the top of both halves, "Γ3,1" = the bottom of both halves, "Ω" = both.
SetFactory("OpenCASCADE");
h = 0.125;
Rectangle(1) = {0, 0, 0, 1, 1};
Rectangle(2) = {1, 0, 0, 1, 1};
MeshSize{PointsOf{Surface{1, 2};}} = h;
left() = Curve In BoundingBox{-0.1, -0.1, -1, 0.1, 1.1, 1};
right() = Curve In BoundingBox{1.9, -0.1, -1, 2.1, 1.1, 1};
top() = Curve In BoundingBox{-0.1, 0.9, -1, 2.1, 1.1, 1};
bottom() = Curve In BoundingBox{-0.1, -0.1, -1, 2.1, 0.1, 1};
Physical Curve("Γ1", 1) = {left()};
Physical Curve("Γ2", 2) = {top()};
Physical Curve("Γ3,1", 3) = {bottom()};
Physical Curve("ends", 5) = {left(), right()};
Physical Surface("Ω", 10) = {1, 2};
