// edge_box.geo -- the box (0,1) x (0,1) x (0,0.5) whose bottom z = 0 is in unilateral
// contact (Γ3,1) and whose side x = 1 slides with friction (Γ3,2): the two faces meet
// along the edge x = 1, z = 0, where every node carries a contact row along −e_z and two
// friction rows whose tangent plane contains e_z (dependent rows, issue 11). Clamped on
// top (Γ1), tractions on x = 0 (Γ2). Unstructured tetrahedra, h = 0.25.
//
//   gmsh -3 edge_box.geo -format msh41 -o edge_box.msh
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 1, 1, 0.5};
Mesh.CharacteristicLengthMax = 0.25;
e = 1e-6;
bottom() = Surface In BoundingBox{-e, -e, -e, 1 + e, 1 + e, e};
side() = Surface In BoundingBox{1 - e, -e, -e, 1 + e, 1 + e, 0.5 + e};
top() = Surface In BoundingBox{-e, -e, 0.5 - e, 1 + e, 1 + e, 0.5 + e};
left() = Surface In BoundingBox{-e, -e, -e, e, 1 + e, 0.5 + e};
Physical Surface("Γ3,1", 3) = {bottom()};
Physical Surface("Γ3,2", 4) = {side()};
Physical Surface("Γ1", 1) = {top()};
Physical Surface("Γ2", 2) = {left()};
Physical Volume("Ω", 10) = {1};
