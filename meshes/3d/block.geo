// block.geo -- the paper's rectangle extruded in depth: a block on a foundation,
// Omega = (0,2) x (0,1) x (0,1)  (metres): x = length, y = depth, z = height.
//
// Structured ("uniform") tetrahedral mesh: with h = 1/n, [0,2] is divided into 2n equal
// parts and [0,1] (in y and in z) into n parts, giving 2 n^3 cubes of side h; gmsh's
// transfinite volume algorithm cuts every cube into 6 tetrahedra of volume h^3/6 (no
// Recombine), with face diagonals that match across neighbouring cubes.  (2n+1)(n+1)^2
// nodes, 12 n^3 tetrahedra, 20 n^2 boundary triangles.  n must be even and >= 2 (as in
// rect.geo; the geometry itself would take any n >= 1).  The nodes of the mesh for n are
// nodes of the mesh for 2n.  The benchmark mesh (n = 24: 30625 nodes, 91875 dofs) is
// not committed: `meshes/generate.sh block 24` writes meshes/3d/block_024.msh.
//
//   gmsh -3 block.geo -setnumber n 16 -format msh41 -o block_016.msh     (default n = 8)
//
//      z
//      |      (0,1,1) +------------------------------------+ (2,1,1)
//      |             /|          top: z = 1               /|
//      |            / |                                  / |
//      |   (0,0,1) +------------------------------------+  |
//      |           |  |                                 |  |
//      |     Γ1:   |  |      front y = 0, back y = 1    |  |  right: x = 2
//      |     x = 0 |  +---------------------------------|--+ (2,1,0)
//      |           | / (0,1,0)                          | /
//      |           |/                                   |/
//      |   (0,0,0) +-----------------+------------------+ (2,0,0)
//      |                  Γ3,1    (1,0,0)    Γ3,2         bottom: z = 0
//      +-------------------------------------------------------- x   (y into the page)
//
// The geometry is two unit cubes V1 = (0,1)^3 and V2 = (1,2) x (0,1)^2 glued along the
// face x = 1 (Coherence, i.e. BooleanFragments): the transfinite volume algorithm needs
// 6-face volumes, and the bottom must be two OCC surfaces split at x = 1.  The faces
// y = 0, y = 1 and z = 1 are therefore split at x = 1 too; the inner face x = 1 is in
// no group (not saved).
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"    = 1  : left face x = 0                   (area 1)                clamped
//   "Γ2"    = 2  : top z = 1, right x = 2, front y = 0, back y = 1  (area 7) traction
//   "Γ3,1"  = 3  : bottom z = 0, x in [0,1]          (area 1)                contact
//   "Γ3,2"  = 4  : bottom z = 0, x in [1,2]          (area 1)                friction
//   "top"   = 5  : top face z = 1                    (area 2)   load group inside Γ2
//   "right" = 6  : right face x = 2                  (area 1)   load group inside Γ2
//   "sides" = 7  : front y = 0 and back y = 1        (area 4)   load group inside Γ2
//   "Ω"     = 10 : the domain (volumes V1, V2)
// Only physical entities are saved (Mesh.SaveAll = 0): the elements of the file are the
// 12 n^3 tetrahedra (gmsh type 4) and the 3-node boundary triangles (type 2).
//
// The OpenCASCADE kernel is used on purpose (see rect.geo): the nodes are (i, j, k)/n to
// rounding, so the meshes for n and 2n share their nodes exactly.

If (!Exists(n))
  n = 8;
EndIf
If (n < 2 || n % 2 != 0)
  Error("block.geo: n must be even and >= 2 (got %g)", n);
  Abort;
EndIf

// -setnumber height H: the block cut to the height H (0 < H <= 1; the default 1 is the
// block), a plate lying on its foundation; only with unstructured tetrahedra (below), as
// the structured cells are cubes.  The plate of issue 29: `-setnumber height 0.25
// -setnumber unstructured 1 -setnumber Mesh.MeshSizeMax 0.03` (54 990 dofs, 1 402 contact
// and 1 436 friction nodes); examples/bench_contact.rs makes it as `plate:0.03`.
If (!Exists(height))
  height = 1;
EndIf
If (!Exists(unstructured))
  unstructured = 0;
EndIf
If (height <= 0 || height > 1 || (height != 1 && !unstructured))
  Error("block.geo: height must be in (0, 1], and below 1 only with unstructured 1 (got %g)", height);
  Abort;
EndIf

SetFactory("OpenCASCADE");
Mesh.SaveAll = 0;

Box(1) = {0, 0, 0, 1, 1, height};   // V1: x in [0,1]
Box(2) = {1, 0, 0, 1, 1, height};   // V2: x in [1,2]
Coherence;                     // share the face x = 1 (conforming mesh)

// -setnumber unstructured 1: gmsh's own tetrahedra of size about h = 1/n instead (Delaunay,
// no common diagonals, nodes not nested), for timings and checks on a mesh that is not
// structured: `-setnumber n 24 -setnumber unstructured 1 -setnumber Mesh.MeshSizeMax 0.042`
// gives 23 959 nodes and 703 contact nodes (the structured n = 24 has 30 625 and 600).
If (unstructured)
  If (Mesh.MeshSizeMax > 2)
    Mesh.MeshSizeMax = 1 / n;
  EndIf
Else
  Transfinite Curve{:} = n + 1;  // every edge has length 1: n cells of side h = 1/n
  Transfinite Surface{:};
  Transfinite Volume{:};
EndIf

// Faces are picked by bounding box: a surface is taken if it lies inside the box.
e = 1e-6;
h = height;
left() = Surface In BoundingBox{-e, -e, -e, e, 1+e, h+e};              // x = 0
bot1() = Surface In BoundingBox{-e, -e, -e, 1+e, 1+e, e};              // z = 0, x in [0,1]
bot2() = Surface In BoundingBox{1-e, -e, -e, 2+e, 1+e, e};             // z = 0, x in [1,2]
top() = Surface In BoundingBox{-e, -e, h-e, 2+e, 1+e, h+e};            // z = height
right() = Surface In BoundingBox{2-e, -e, -e, 2+e, 1+e, h+e};          // x = 2
sides() = {Surface In BoundingBox{-e, -e, -e, 2+e, e, h+e},            // y = 0
           Surface In BoundingBox{-e, 1-e, -e, 2+e, 1+e, h+e}};        // y = 1
If (#left() != 1 || #bot1() != 1 || #bot2() != 1 || #top() != 2 || #right() != 1 ||
    #sides() != 4)
  Error("block.geo: a boundary face was not found by its bounding box");
  Abort;
EndIf

Physical Surface("Γ1", 1) = {left()};
Physical Surface("Γ2", 2) = {top(), right(), sides()};
Physical Surface("Γ3,1", 3) = {bot1()};
Physical Surface("Γ3,2", 4) = {bot2()};
Physical Surface("top", 5) = {top()};
Physical Surface("right", 6) = {right()};
Physical Surface("sides", 7) = {sides()};
Physical Volume("Ω", 10) = Volume{:};
