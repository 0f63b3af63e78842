// punch.geo -- a pad pressed onto its foundation by a punch, for examples/punch.toml:
// Omega = (0,2) x (0,0.5) (metres), unstructured triangles.
//
//   P8 (0,0.5) +---- C7 ----+== C6 "punch" ==+---- C5 ----+ P5 (2,0.5)
//              |          P7 (0.75)       P6 (1.25)       |
//          C8  |                    Ω                     | C4
//              |                                          |
//   P1 (0,0)   +--- C1 ---+---------- C2 ---------+- C3 --+ P4 (2,0)
//                       P2 (0.5,0)             P3 (1.5,0)
//
// The punch (a rigid tool bonded to the pad's top, x in [0.75,1.25]) is where the
// displacement is prescribed; the bottom rests on the foundation: unilateral contact under
// the punch (x in [0.5,1.5]), given normal stress and Coulomb friction at the two ends.
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"    = 1  : the punch (C6), the part of the boundary where u is given   prescribed u
//   "Γ2"    = 2  : the rest of the top and the sides (C4, C5, C7, C8)   traction free
//   "Γ3,1"  = 3  : bottom, x in [0.5,1.5] (C2)                           contact
//   "Γ3,2"  = 4  : bottom, x in [0,0.5] and [1.5,2] (C1, C3)             friction
//   "punch" = 5  : the same curve by its name
//   "Ω"     = 10 : the domain (surface S1)
// No group is clamped (the scene's mesh.groups.fixed = []): the punch holds the pad.  Frontal-Delaunay, size lc = 0.05, finer
// (lc/2) at the punch's edges; only physical entities are saved.
//
//   gmsh -2 punch.geo -format msh41 -o punch.msh

If (!Exists(lc))
  lc = 0.05;
EndIf

Mesh.SaveAll = 0;
Mesh.Algorithm = 6;            // Frontal-Delaunay
General.NumThreads = 1;        // deterministic output

Point(1) = {0,    0,   0, lc};
Point(2) = {0.5,  0,   0, lc};
Point(3) = {1.5,  0,   0, lc};
Point(4) = {2,    0,   0, lc};
Point(5) = {2,    0.5, 0, lc};
Point(6) = {1.25, 0.5, 0, lc/2};
Point(7) = {0.75, 0.5, 0, lc/2};
Point(8) = {0,    0.5, 0, lc};

Line(1) = {1, 2};   // bottom, x in [0,0.5]
Line(2) = {2, 3};   // bottom, x in [0.5,1.5]
Line(3) = {3, 4};   // bottom, x in [1.5,2]
Line(4) = {4, 5};   // right
Line(5) = {5, 6};   // top, x in [1.25,2]
Line(6) = {6, 7};   // the punch
Line(7) = {7, 8};   // top, x in [0,0.75]
Line(8) = {8, 1};   // left

Curve Loop(1) = {1, 2, 3, 4, 5, 6, 7, 8};   // counter-clockwise
Plane Surface(1) = {1};

Physical Curve("Γ1", 1) = {6};
Physical Curve("Γ2", 2) = {4, 5, 7, 8};
Physical Curve("Γ3,1", 3) = {2};
Physical Curve("Γ3,2", 4) = {1, 3};
Physical Curve("punch", 5) = {6};
Physical Surface("Ω", 10) = {1};
