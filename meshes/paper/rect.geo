// rect.geo -- the rectangle of the paper, Section 4:  Omega = (0,2) x (0,1)  (metres).
//
// Structured ("uniform") triangulation: with n = 1/h, the x-interval [0,2] and the
// y-interval [0,1] are EACH divided into n equal parts (cells 2/n x 1/n), and every cell
// is cut into two triangles with all diagonals in the same direction (transfinite
// "Right": from lower-left to upper-right).  Hence the mesh for 2n is a uniform refinement
// of the mesh for n (nested meshes: each coarse triangle is exactly the union of 4 fine
// ones).  (n+1)^2 nodes, 2 n^2 triangles.  n must be even (the bottom is split at x = 1).
//
//   gmsh -2 rect.geo -setnumber n 32 -format msh41 -o rect_032.msh      (default n = 8)
//
//     P5 (0,1) +----------- top: C4 ------------+ P4 (2,1)
//              |                                |
//    left: C5  |                Ω               | right: C3
//              |                                |
//     P1 (0,0) +---- C1 ---- + ------ C2 -------+ P3 (2,0)
//                         P2 (1,0)
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"    = 1  : left edge x = 0 (C5)            clamped
//   "Γ2"    = 2  : top edge + right edge (C4, C3)  traction
//   "Γ3,1"  = 3  : bottom, x in [0,1] (C1)         contact
//   "Γ3,2"  = 4  : bottom, x in [1,2] (C2)         friction
//   "top"   = 5  : top edge (C4)     load group inside Γ2
//   "right" = 6  : right edge (C3)   load group inside Γ2
//   "Ω"     = 10 : the domain (surface S1)
// Only physical entities are saved (Mesh.SaveAll = 0): the elements of the file are the
// 2 n^2 triangles and the 2-node lines on the boundary.
//
// The OpenCASCADE kernel is used on purpose: with the built-in kernel gmsh places the
// transfinite nodes by numerically integrating the curve length, which gives coordinates
// like 0.4999999999986921; with OpenCASCADE the nodes are (2i/n, j/n) to rounding, so
// nested meshes share their nodes exactly.

If (!Exists(n))
  n = 8;
EndIf
If (n < 2 || n % 2 != 0)
  Error("rect.geo: n must be even and >= 2 (got %g)", n);
  Abort;
EndIf

SetFactory("OpenCASCADE");
Mesh.SaveAll = 0;

Point(1) = {0, 0, 0};
Point(2) = {1, 0, 0};
Point(3) = {2, 0, 0};
Point(4) = {2, 1, 0};
Point(5) = {0, 1, 0};

Line(1) = {1, 2};   // bottom, x in [0,1]
Line(2) = {2, 3};   // bottom, x in [1,2]
Line(3) = {3, 4};   // right
Line(4) = {4, 5};   // top
Line(5) = {5, 1};   // left

Curve Loop(1) = {1, 2, 3, 4, 5};   // counter-clockwise: triangles come out counter-clockwise
Plane Surface(1) = {1};

// -setnumber unstructured 1: gmsh's own triangles of size about h = 1/n instead (not
// nested, no common diagonals), for timings and checks on a mesh that is not structured:
// `-setnumber n 8 -setnumber unstructured 1 -setnumber Mesh.Algorithm 6
// -setnumber Mesh.MeshSizeMax 0.0085` gives 32 491 nodes (the structured n = 128 has 16 641).
If (!Exists(unstructured))
  unstructured = 0;
EndIf
If (unstructured)
  If (Mesh.MeshSizeMax > 2)
    Mesh.MeshSizeMax = 1 / n;
  EndIf
Else
  Transfinite Curve{1, 2} = n/2 + 1;   // number of nodes on the curve
  Transfinite Curve{3, 4, 5} = n + 1;
  Transfinite Surface{1} = {1, 3, 4, 5} Right;   // the 4 corners; P2 lies on the bottom side
EndIf

Physical Curve("Γ1", 1) = {5};
Physical Curve("Γ2", 2) = {4, 3};
Physical Curve("Γ3,1", 3) = {1};
Physical Curve("Γ3,2", 4) = {2};
Physical Curve("top", 5) = {4};
Physical Curve("right", 6) = {3};
Physical Surface("Ω", 10) = {1};
