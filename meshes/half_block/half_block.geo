// half_block.geo -- the half y < 0.5 of the block of meshes/3d/block.geo, for
// examples/half_block.toml: Omega = (0,2) x (0,0.5) x (0,1) (metres), cut from the block
// (0,2) x (0,1) x (0,1) by its plane of symmetry y = 0.5 (the block's loads do not depend
// on y).
//
// Structured as block.geo: with h = 1/n every edge of length l has l n cells, every cube of
// side h is cut into 6 tetrahedra.  The geometry is four boxes glued by BooleanFragments
// (the transfinite algorithm needs 6-face volumes, so all are split at x = 1, y = 0.375):
//   (0,1) x (0,0.375) x (0,1), (0,1) x (0.375,0.5) x (0,1)   under them the contact face Γ3,1
//   (1,2) x (0,0.375) x (0,1)      under it the friction face Γ3,2
//   (1,2) x (0.375,0.5) x (0,1)    under it a traction-free strip along the plane
// The friction face stops one cell (at n = 8) short of the plane y = 0.5: in 3D a friction
// node may not have a component held (docs/scene.md, "Dirichlet conditions"), while the
// contact face may meet the plane (the plane holds y, a tangent of the contact normal z).
// n must be a multiple of 8 (the strip is 1/8 wide).
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"    = 1  : left face x = 0                               clamped
//   "Γ2"    = 2  : top z = 1, right x = 2, front y = 0, the plane y = 0.5 and the strip
//                  bottom z = 0, x in [1,2], y in [0.375,0.5]   traction (none on the last two)
//   "Γ3,1"  = 3  : bottom z = 0, x in [0,1]                      contact (meets the plane)
//   "Γ3,2"  = 4  : bottom z = 0, x in [1,2], y in [0,0.375]      friction
//   "top"   = 5  : top face z = 1        "right" = 6 : right face x = 2   (inside Γ2)
//   "sym"   = 7  : y = 0.5, the plane of symmetry (inside Γ2: Γ1, Γ2 and Γ3 partition the
//                  boundary, as in every mesh of meshes/)
//   "Ω"     = 10 : the volume
// (n + 1)(2n + 1)(n/2 + 1) nodes: 765 at n = 8.
//
//   gmsh -3 half_block.geo -format msh41 -o half_block.msh     (default n = 8)

If (!Exists(n))
  n = 8;
EndIf
If (n < 8 || n % 8 != 0)
  Error("half_block.geo: n must be a multiple of 8 (got %g)", n);
  Abort;
EndIf

SetFactory("OpenCASCADE");
Mesh.SaveAll = 0;
General.NumThreads = 1;

Box(1) = {0, 0, 0, 1, 0.375, 1};
Box(2) = {0, 0.375, 0, 1, 0.125, 1};
Box(3) = {1, 0, 0, 1, 0.375, 1};
Box(4) = {1, 0.375, 0, 1, 0.125, 1};
BooleanFragments{ Volume{1, 2, 3, 4}; Delete; }{}

// every curve gets (its length) n cells: the nodes are (i, j, k)/n to rounding
curves() = Curve{:};
For i In {0 : #curves() - 1}
  bb() = BoundingBox Curve{curves(i)};
  len = Max(bb(3) - bb(0), Max(bb(4) - bb(1), bb(5) - bb(2)));
  Transfinite Curve{curves(i)} = Round(len * n) + 1;
EndFor
Transfinite Surface{:};
Transfinite Volume{:};

e = 1e-6;
left() = Surface In BoundingBox{-e, -e, -e, e, 0.5+e, 1+e};
right() = Surface In BoundingBox{2-e, -e, -e, 2+e, 0.5+e, 1+e};
front() = Surface In BoundingBox{-e, -e, -e, 2+e, e, 1+e};
sym() = Surface In BoundingBox{-e, 0.5-e, -e, 2+e, 0.5+e, 1+e};
top() = Surface In BoundingBox{-e, -e, 1-e, 2+e, 0.5+e, 1+e};
contact() = Surface In BoundingBox{-e, -e, -e, 1+e, 0.5+e, e};
friction() = Surface In BoundingBox{1-e, -e, -e, 2+e, 0.375+e, e};
strip() = Surface In BoundingBox{1-e, 0.375-e, -e, 2+e, 0.5+e, e};
If (#left() != 2 || #right() != 2 || #front() != 2 || #sym() != 2 || #top() != 4 ||
    #contact() != 2 || #friction() != 1 || #strip() != 1)
  Error("half_block.geo: a boundary face was not found by its bounding box");
  Abort;
EndIf

Physical Surface("Γ1", 1) = {left()};
Physical Surface("Γ2", 2) = {top(), right(), front(), sym(), strip()};
Physical Surface("Γ3,1", 3) = {contact()};
Physical Surface("Γ3,2", 4) = {friction()};
Physical Surface("top", 5) = {top()};
Physical Surface("right", 6) = {right()};
Physical Surface("sym", 7) = {sym()};
Physical Volume("Ω", 10) = Volume{:};
