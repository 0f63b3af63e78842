// plate_hole.geo -- rectangular plate (0,2) x (0,1) (metres) with a circular hole,
// centre (1.0, 0.55), radius 0.2; unstructured triangles.
//
//   P4 (0,1) +------------- top: C3 --------------+ P3 (2,1)
//            |                 ___                |
//  left: C4  |               /     \  hole:       | right: C2
//            |              |   +   | C11..C14    |
//            |               \ ___ /              |
//   P1 (0,0) +------ C1 ------+-------- C5 -------+ P6 (2,0)
//                          P5 (1,0)
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"    = 1  : left edge x = 0 (C4)                        clamped
//   "Γ2"    = 2  : top + right + hole (C3, C2, C11..C14)      traction (hole: free)
//   "Γ3,1"  = 3  : bottom, x in [0,1] (C1)                     contact
//   "Γ3,2"  = 4  : bottom, x in [1,2] (C5)                     friction
//   "top"   = 5  : top edge (C3)       load group inside Γ2
//   "right" = 6  : right edge (C2)     load group inside Γ2
//   "hole"  = 7  : the hole's circle   load group inside Γ2
//   "Ω"     = 10 : the domain (surface S1)
// Mesh: Frontal-Delaunay, size lc = 0.05 away from the hole, graded down to lc/4 on the
// hole (distance-threshold field).  Only physical entities are saved (Mesh.SaveAll = 0).
//
//   gmsh -2 plate_hole.geo -format msh41 -o plate_hole.msh

If (!Exists(lc))
  lc = 0.05;
EndIf
xc = 1.0; yc = 0.55; r = 0.2;

Mesh.SaveAll = 0;
Mesh.Algorithm = 6;            // Frontal-Delaunay
General.NumThreads = 1;        // deterministic output
Mesh.MeshSizeFromPoints = 0;   // sizes come from the background field only
Mesh.MeshSizeFromCurvature = 0;
Mesh.MeshSizeExtendFromBoundary = 0;

Point(1) = {0, 0, 0};
Point(5) = {1, 0, 0};
Point(6) = {2, 0, 0};
Point(3) = {2, 1, 0};
Point(4) = {0, 1, 0};

Line(1) = {1, 5};   // bottom, x in [0,1]
Line(5) = {5, 6};   // bottom, x in [1,2]
Line(2) = {6, 3};   // right
Line(3) = {3, 4};   // top
Line(4) = {4, 1};   // left

// the hole: centre P10, four quarter arcs
Point(10) = {xc,     yc,     0};
Point(11) = {xc + r, yc,     0};
Point(12) = {xc,     yc + r, 0};
Point(13) = {xc - r, yc,     0};
Point(14) = {xc,     yc - r, 0};
Circle(11) = {11, 10, 12};
Circle(12) = {12, 10, 13};
Circle(13) = {13, 10, 14};
Circle(14) = {14, 10, 11};

Curve Loop(1) = {1, 5, 2, 3, 4};        // outer boundary, counter-clockwise
Curve Loop(2) = {11, 12, 13, 14};       // hole
Plane Surface(1) = {1, 2};

Field[1] = Distance;
Field[1].CurvesList = {11, 12, 13, 14};
Field[1].Sampling = 200;
Field[2] = Threshold;
Field[2].InField = 1;
Field[2].SizeMin = lc / 4;
Field[2].SizeMax = lc;
Field[2].DistMin = 0.02;
Field[2].DistMax = 0.3;
Background Field = 2;

Physical Curve("Γ1", 1) = {4};
Physical Curve("Γ2", 2) = {3, 2, 11, 12, 13, 14};
Physical Curve("Γ3,1", 3) = {1};
Physical Curve("Γ3,2", 4) = {5};
Physical Curve("top", 5) = {3};
Physical Curve("right", 6) = {2};
Physical Curve("hole", 7) = {11, 12, 13, 14};
Physical Surface("Ω", 10) = {1};
