// half_block.geo -- half of a block on a foundation, for the symmetry test of
// tests/solutions/symmetry.rs: Omega = (0,2) x (0,0.5) x (0,1), the half y < 0.5 of the
// block (0,2) x (0,1) x (0,1), whose loads do not depend on y.  mirror.py reflects this mesh
// in the plane y = 0.5 to make whole_block.msh, the whole block meshed symmetrically.
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"   = 1  : x = 0                                    clamped
//   "Γ2"   = 2  : top z = 1, right x = 2, front y = 0      traction
//   "Γ3,1" = 3  : bottom z = 0, x in [0,1]                 contact (meets the plane y = 0.5)
//   "Γ3,2" = 4  : bottom z = 0, x in [1,2], y in [0,0.25]  friction (away from the plane)
//   "top"  = 5  : z = 1        "right" = 6 : x = 2         load groups inside Γ2
//   "sym"  = 7  : y = 0.5, the symmetry plane (half model only)
//   "Ω"    = 10 : the volume
// The bottom x in [1,2], y in [0.25,0.5] is in no group (traction free).  Unstructured, one
// thread: deterministic output.
//
//   gmsh -3 half_block.geo -format msh41 -o half_block.msh

SetFactory("OpenCASCADE");
Mesh.SaveAll = 0;
Mesh.Algorithm = 6;
Mesh.Algorithm3D = 1;
General.NumThreads = 1;
lc = 0.25;

Box(1) = {0, 0, 0, 1, 0.5, 1};
Box(2) = {1, 0, 0, 1, 0.25, 1};
Box(3) = {1, 0.25, 0, 1, 0.25, 1};
BooleanFragments{ Volume{1, 2, 3}; Delete; }{}
MeshSize{PointsOf{Volume{:};}} = lc;

e = 1e-6;
x0() = Surface In BoundingBox{-e, -e, -e, e, 0.5+e, 1+e};
x2() = Surface In BoundingBox{2-e, -e, -e, 2+e, 0.5+e, 1+e};
y0() = Surface In BoundingBox{-e, -e, -e, 2+e, e, 1+e};
ym() = Surface In BoundingBox{-e, 0.5-e, -e, 2+e, 0.5+e, 1+e};
z1() = Surface In BoundingBox{-e, -e, 1-e, 2+e, 0.5+e, 1+e};
contact() = Surface In BoundingBox{-e, -e, -e, 1+e, 0.5+e, e};
friction() = Surface In BoundingBox{1-e, -e, -e, 2+e, 0.25+e, e};

Physical Surface("Γ1", 1) = {x0()};
Physical Surface("Γ2", 2) = {z1(), x2(), y0()};
Physical Surface("Γ3,1", 3) = {contact()};
Physical Surface("Γ3,2", 4) = {friction()};
Physical Surface("top", 5) = {z1()};
Physical Surface("right", 6) = {x2()};
Physical Surface("sym", 7) = {ym()};
Physical Volume("Ω", 10) = {Volume{:}};
