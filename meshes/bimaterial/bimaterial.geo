// bimaterial.geo -- the paper's rectangle (0,2) x (0,1) (metres) made of two materials, for
// examples/bimaterial.toml: a soft layer (0,2) x (0,0.2) bonded under a stiffer core
// (0,2) x (0.2,1).  The two surfaces share the line y = 0.2, so the mesh is conforming and
// every triangle lies in one of them.  Unstructured triangles.
//
//   P6 (0,1)   +---------------- top: C6 -----------------+ P5 (2,1)
//              |                 "core"                   | C5
//   P7 (0,0.2) +--------------- C8 (interface) -----------+ P4 (2,0.2)
//              |                 "layer"                  | C4
//   P1 (0,0)   +------- C1 -------+-------- C2 -----------+ P3 (2,0)
//                               P2 (1,0)
//
// Physical groups (name = tag), names are UTF-8 (as meshes/paper/rect.geo, plus the parts):
//   "Γ1"    = 1  : left edge x = 0 (C7, C9)                clamped
//   "Γ2"    = 2  : top edge + right edge (C6, C4, C5)      traction
//   "Γ3,1"  = 3  : bottom, x in [0,1] (C1)                 contact
//   "Γ3,2"  = 4  : bottom, x in [1,2] (C2)                 friction
//   "top"   = 5  : top edge (C6)         "right" = 6 : right edge (C4, C5)
//   "Ω"     = 10 : the domain (S1, S2)
//   "layer" = 11 : the soft layer (S1)   "core" = 12 : the core (S2)
// Frontal-Delaunay, size lc = 1/16 (1/32 in the layer); only physical entities are saved.
//
//   gmsh -2 bimaterial.geo -format msh41 -o bimaterial.msh

If (!Exists(lc))
  lc = 1/16;
EndIf

Mesh.SaveAll = 0;
Mesh.Algorithm = 6;            // Frontal-Delaunay
General.NumThreads = 1;        // deterministic output

Point(1) = {0, 0,   0, lc/2};
Point(2) = {1, 0,   0, lc/2};
Point(3) = {2, 0,   0, lc/2};
Point(4) = {2, 0.2, 0, lc/2};
Point(5) = {2, 1,   0, lc};
Point(6) = {0, 1,   0, lc};
Point(7) = {0, 0.2, 0, lc/2};

Line(1) = {1, 2};   // bottom, x in [0,1]
Line(2) = {2, 3};   // bottom, x in [1,2]
Line(4) = {3, 4};   // right, in the layer
Line(5) = {4, 5};   // right, in the core
Line(6) = {5, 6};   // top
Line(7) = {6, 7};   // left, in the core
Line(8) = {7, 4};   // the interface y = 0.2
Line(9) = {7, 1};   // left, in the layer

Curve Loop(1) = {1, 2, 4, -8, 9};   // the layer, counter-clockwise
Plane Surface(1) = {1};
Curve Loop(2) = {8, 5, 6, 7};       // the core, counter-clockwise
Plane Surface(2) = {2};

Physical Curve("Γ1", 1) = {7, 9};
Physical Curve("Γ2", 2) = {6, 4, 5};
Physical Curve("Γ3,1", 3) = {1};
Physical Curve("Γ3,2", 4) = {2};
Physical Curve("top", 5) = {6};
Physical Curve("right", 6) = {4, 5};
Physical Surface("Ω", 10) = {1, 2};
Physical Surface("layer", 11) = {1};
Physical Surface("core", 12) = {2};
