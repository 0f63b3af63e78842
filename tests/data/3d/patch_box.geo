// patch_box.geo -- a small unstructured tetrahedral mesh of a box for the 3D patch tests
// of tests/solutions/three_d.rs: Omega = (0,1) x (0,0.8) x (0,0.6), clamped on x = 0, every other face
// in the traction boundary, with one load group per face so that a test can put the exact
// traction sigma.n of any constant stress on it.
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1" = 1  : face x = 0 (area 0.48)                      clamped
//   "Γ2" = 2  : the five other faces (area 3.28)            traction
//   "x1" = 11 : x = 1      "y0" = 12 : y = 0     "y1" = 13 : y = 0.8
//   "z0" = 14 : z = 0      "z1" = 15 : z = 0.6              load groups inside Γ2
//   "Ω"  = 10 : the volume
// Unstructured (Frontal-Delaunay faces, Delaunay volume), target size lc = 0.2 (144 nodes,
// 397 tetrahedra, 14 of the nodes inside), one thread: deterministic output.
//
//   gmsh -3 patch_box.geo -format msh41 -o patch_box.msh
//   gmsh -3 patch_box.geo -setnumber lc 2 -order 2 -format msh41 -o quadratic_tets.msh
//     (the coarsest mesh with 10-node tetrahedra and 6-node triangles: refused)

If (!Exists(lc))
  lc = 0.2;
EndIf

SetFactory("OpenCASCADE");
Mesh.SaveAll = 0;
Mesh.Algorithm = 6;
Mesh.Algorithm3D = 1;
General.NumThreads = 1;

Box(1) = {0, 0, 0, 1, 0.8, 0.6};
MeshSize{PointsOf{Volume{1};}} = lc;

e = 1e-6;
x0() = Surface In BoundingBox{-e, -e, -e, e, 0.8+e, 0.6+e};
x1() = Surface In BoundingBox{1-e, -e, -e, 1+e, 0.8+e, 0.6+e};
y0() = Surface In BoundingBox{-e, -e, -e, 1+e, e, 0.6+e};
y1() = Surface In BoundingBox{-e, 0.8-e, -e, 1+e, 0.8+e, 0.6+e};
z0() = Surface In BoundingBox{-e, -e, -e, 1+e, 0.8+e, e};
z1() = Surface In BoundingBox{-e, -e, 0.6-e, 1+e, 0.8+e, 0.6+e};
If (#x0() != 1 || #x1() != 1 || #y0() != 1 || #y1() != 1 || #z0() != 1 || #z1() != 1)
  Error("patch_box.geo: a face was not found by its bounding box");
  Abort;
EndIf

Physical Surface("Γ1", 1) = {x0()};
Physical Surface("Γ2", 2) = {x1(), y0(), y1(), z0(), z1()};
Physical Surface("x1", 11) = {x1()};
Physical Surface("y0", 12) = {y0()};
Physical Surface("y1", 13) = {y1()};
Physical Surface("z0", 14) = {z0()};
Physical Surface("z1", 15) = {z1()};
Physical Volume("Ω", 10) = {1};
