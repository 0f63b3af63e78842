// unfragmented_3d.geo -- two OpenCASCADE boxes (0,1)^3 and (1,2)x(0,1)^2 that touch along
// x = 1 but were NOT fragmented: the interface carries two copies of every node and no
// tetrahedron connects the halves.  The 3D twin of unfragmented.geo (issue 26, finding 7).
//
//   gmsh -3 unfragmented_3d.geo -format msh41 -o unfragmented_3d.msh
//
// Groups: "Γ1" = the face x = 0, "ends" = the faces x = 0 and x = 2, "Γ2" = the top (z = 1),
// "Γ3,1" = the bottom faces (z = 0), "Ω" = both volumes.
SetFactory("OpenCASCADE");
h = 0.5;
Box(1) = {0, 0, 0, 1, 1, 1};
Box(2) = {1, 0, 0, 1, 1, 1};
MeshSize{PointsOf{Volume{1, 2};}} = h;
left() = Surface In BoundingBox{-0.1, -0.1, -0.1, 0.1, 1.1, 1.1};
right() = Surface In BoundingBox{1.9, -0.1, -0.1, 2.1, 1.1, 1.1};
top() = Surface In BoundingBox{-0.1, -0.1, 0.9, 2.1, 1.1, 1.1};
bottom() = Surface In BoundingBox{-0.1, -0.1, -0.1, 2.1, 1.1, 0.1};
Physical Surface("Γ1", 1) = {left()};
Physical Surface("Γ2", 2) = {top()};
Physical Surface("Γ3,1", 3) = {bottom()};
Physical Surface("ends", 5) = {left(), right()};
Physical Volume("Ω", 10) = {1, 2};
