// slab.geo -- a thin slab whose mid-plane is the rectangle of the paper (rect.geo):
// Omega = (0,2) x (0,1) x (-t/2, t/2)  (metres), the 3D counterpart of the paper's
// plane-stress model (Section 4).
//
// The mid-plane z = 0 is rect.geo's surface, drawn with exactly rect.geo's points, curves
// and transfinite "Right" triangulation (n parts in x and in y, cells 2/n x 1/n); it is
// extruded up to z = t/2 and down to z = -t/2 in layers/2 equal layers each.  Every layer
// is a copy of the 2D triangulation and every prism is split into 3 tetrahedra (no
// Recombine).  Hence every node's (x, y) is bit-for-bit a node of rect.geo's mesh for the
// same n, the nodes on z = 0 and the tetrahedron faces there ARE that mesh, and a 3D run
// compares with a 2D run on meshes/paper/rect_0nn.msh.  The nodes' z are exact (0 and
// ±t/2 for layers = 2).  (n+1)^2 (layers+1) nodes, 6 n^2 layers tetrahedra.
//
// layers (even, >= 2) = 2 by default, one layer on each side of the mid-plane.  Under
// in-plane loads the state is close to plane stress (u_x, u_y nearly constant through the
// thickness, u_z linear), which one linear layer already represents, so more layers buy
// little and make the tetrahedra of a thin slab flatter (t = 0.04, n = 16: layers 0.02
// thick against cells 0.125 x 0.0625).  A single layer is not offered: it would leave no
// nodes on the mid-plane, where 2D and 3D nodal values compare node for node.
//
//   gmsh -3 slab.geo -setnumber n 16 -setnumber t 0.04 -format msh41 -o slab_016_t0040.msh
//   (defaults n = 16, t = 0.2, layers = 2)
//
//     y
//     |  P5 (0,1) +------------- top: y = 1 --------------+ P4 (2,1)
//     |           |                                       |
//     |  Γ1:      |   Ω: mid-plane z = 0 (this drawing);  | right: x = 2
//     |  x = 0    |   faces z = ±t/2 above and below      |
//     |           |                                       |
//     |  P1 (0,0) +------ Γ3,1 ------+------ Γ3,2 --------+ P3 (2,0)
//     |                           P2 (1,0)
//     +-------------------------------------------------------- x   (z out of the page)
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"    = 1  : face x = 0                  (area t)             clamped
//   "Γ2"    = 2  : faces y = 1, x = 2, z = ±t/2 (area 4 + 3 t)      traction
//   "Γ3,1"  = 3  : face y = 0, x in [0,1]      (area t)             contact
//   "Γ3,2"  = 4  : face y = 0, x in [1,2]      (area t)             friction
//   "top"   = 5  : face y = 1                  (area 2 t)   load group inside Γ2
//   "right" = 6  : face x = 2                  (area t)     load group inside Γ2
//   "faces" = 7  : faces z = -t/2 and z = t/2  (area 4)     load group inside Γ2
//   "Ω"     = 10 : the domain (the two extruded volumes, z < 0 and z > 0)
// Only physical entities are saved (Mesh.SaveAll = 0): the elements of the file are the
// tetrahedra (gmsh type 4) and the 3-node boundary triangles (type 2); the mid-plane
// surface is inside Ω and in no group.
//
// The OpenCASCADE kernel is used as in rect.geo: the in-plane node coordinates are then
// the same doubles as in rect.geo's meshes.

If (!Exists(n))
  n = 16;
EndIf
If (!Exists(t))
  t = 0.2;
EndIf
If (!Exists(layers))
  layers = 2;
EndIf
If (n < 2 || n % 2 != 0)
  Error("slab.geo: n must be even and >= 2 (got %g)", n);
  Abort;
EndIf
If (t < 1e-5)
  Error("slab.geo: the thickness t must be >= 1e-5 (got %g)", t);
  Abort;
EndIf
If (layers < 2 || layers % 2 != 0)
  Error("slab.geo: layers must be even and >= 2 (got %g)", layers);
  Abort;
EndIf

SetFactory("OpenCASCADE");
Mesh.SaveAll = 0;

// the mid-plane: rect.geo's surface
Point(1) = {0, 0, 0};
Point(2) = {1, 0, 0};
Point(3) = {2, 0, 0};
Point(4) = {2, 1, 0};
Point(5) = {0, 1, 0};

Line(1) = {1, 2};   // y = 0, x in [0,1]
Line(2) = {2, 3};   // y = 0, x in [1,2]
Line(3) = {3, 4};   // right
Line(4) = {4, 5};   // top
Line(5) = {5, 1};   // left

Curve Loop(1) = {1, 2, 3, 4, 5};
Plane Surface(1) = {1};

Transfinite Curve{1, 2} = n/2 + 1;
Transfinite Curve{3, 4, 5} = n + 1;
Transfinite Surface{1} = {1, 3, 4, 5} Right;

// up[0], dn[0] = the faces z = t/2, z = -t/2; up[1], dn[1] = the volumes z > 0, z < 0
up[] = Extrude {0, 0, t/2} { Surface{1}; Layers{layers/2}; };
dn[] = Extrude {0, 0, -t/2} { Surface{1}; Layers{layers/2}; };

// Faces are picked by bounding box: a surface is taken if it lies inside the box.  OCC
// pads bounding boxes by 1e-7, hence the tolerance e and the lower bound on t.
e = 1e-6;
zl = -t/2 - e; zh = t/2 + e;
left() = Surface In BoundingBox{-e, -e, zl, e, 1+e, zh};             // x = 0
bot1() = Surface In BoundingBox{-e, -e, zl, 1+e, e, zh};             // y = 0, x in [0,1]
bot2() = Surface In BoundingBox{1-e, -e, zl, 2+e, e, zh};            // y = 0, x in [1,2]
top() = Surface In BoundingBox{-e, 1-e, zl, 2+e, 1+e, zh};           // y = 1
right() = Surface In BoundingBox{2-e, -e, zl, 2+e, 1+e, zh};         // x = 2
faces() = {Surface In BoundingBox{-e, -e, zl, 2+e, 1+e, e-t/2},      // z = -t/2
           Surface In BoundingBox{-e, -e, t/2-e, 2+e, 1+e, zh}};     // z = t/2
If (#left() != 2 || #bot1() != 2 || #bot2() != 2 || #top() != 2 || #right() != 2 ||
    #faces() != 2)
  Error("slab.geo: a boundary face was not found by its bounding box");
  Abort;
EndIf

Physical Surface("Γ1", 1) = {left()};
Physical Surface("Γ2", 2) = {top(), right(), faces()};
Physical Surface("Γ3,1", 3) = {bot1()};
Physical Surface("Γ3,2", 4) = {bot2()};
Physical Surface("top", 5) = {top()};
Physical Surface("right", 6) = {right()};
Physical Surface("faces", 7) = {faces()};
Physical Volume("Ω", 10) = {up[1], dn[1]};
