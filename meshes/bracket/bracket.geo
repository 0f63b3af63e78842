// bracket.geo -- an L-shaped bracket (metres), unstructured triangles.
//
//   P7 (0,2) +--C6--+ P6 (0.5,2)           Γ1 (clamped): the top edge of the vertical arm
//            |      |
//            |      |
//        C7  |      | C5
//            |      |
//            |      +-------- C4 --------+ P4 (2,0.5)
//            |        P5 (0.5,0.5)       |  C3 = "tip"
//   P1 (0,0) +------- C1 ------+---- C2 -+ P3 (2,0)
//                            P2 (1,0)
//
// The bottom y = 0 (split at x = 1) rests on the foundation.
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"   = 1  : top edge of the vertical arm, y = 2 (C6)                 clamped
//   "Γ2"   = 2  : all other free edges: tip, top of the horizontal arm,
//                 inner vertical edge, outer left edge (C3, C4, C5, C7)    traction
//   "Γ3,1" = 3  : bottom, x in [0,1] (C1)                                   contact
//   "Γ3,2" = 4  : bottom, x in [1,2] (C2)                                   friction
//   "tip"  = 5  : right end edge x = 2 (C3)     load group inside Γ2
//   "Ω"    = 10 : the domain (surface S1)
// Mesh: Frontal-Delaunay (Mesh.Algorithm = 6), target size lc = 0.06 (~1200 triangles).
// Only physical entities are saved (Mesh.SaveAll = 0).
//
//   gmsh -2 bracket.geo -format msh41 -o bracket.msh

If (!Exists(lc))
  lc = 0.06;
EndIf

Mesh.SaveAll = 0;
Mesh.Algorithm = 6;            // Frontal-Delaunay
General.NumThreads = 1;        // deterministic output

Point(1) = {0,   0,   0, lc};
Point(2) = {1,   0,   0, lc};
Point(3) = {2,   0,   0, lc};
Point(4) = {2,   0.5, 0, lc};
Point(5) = {0.5, 0.5, 0, lc};
Point(6) = {0.5, 2,   0, lc};
Point(7) = {0,   2,   0, lc};

Line(1) = {1, 2};   // bottom, x in [0,1]
Line(2) = {2, 3};   // bottom, x in [1,2]
Line(3) = {3, 4};   // tip, x = 2
Line(4) = {4, 5};   // top of the horizontal arm, y = 0.5
Line(5) = {5, 6};   // inner edge of the vertical arm, x = 0.5
Line(6) = {6, 7};   // top of the vertical arm, y = 2
Line(7) = {7, 1};   // outer left edge, x = 0

Curve Loop(1) = {1, 2, 3, 4, 5, 6, 7};   // counter-clockwise
Plane Surface(1) = {1};

Physical Curve("Γ1", 1) = {6};
Physical Curve("Γ2", 2) = {3, 4, 5, 7};
Physical Curve("Γ3,1", 3) = {1};
Physical Curve("Γ3,2", 4) = {2};
Physical Curve("tip", 5) = {3};
Physical Surface("Ω", 10) = {1};
