// slider.geo -- a flat box for friction tests, unstructured tetrahedra:
// Omega = (0,1) x (0,1) x (0,0.25)  (metres), clamped on top, sliding on its bottom.
//
//                z
//                |   (0,1,0.25) +--------------------------+ (1,1,0.25)
//                |             /        Γ1: z = 0.25      /|
//                | (0,0,0.25) +--------------------------+ |
//                |            |   sides: x = 0, x = 1,   | + (1,1,0)
//                |            |          y = 0, y = 1    |/
//                |   (0,0,0)  +--------------------------+ (1,0,0)
//                |                Γ3,2: z = 0 (below)
//                +---------------------------------------------- x   (y into the page)
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"    = 1  : top face z = 0.25                        (area 1)   clamped
//   "Γ2"    = 2  : side faces x = 0, x = 1, y = 0, y = 1    (area 1)   traction
//   "Γ3,2"  = 4  : bottom face z = 0                        (area 1)   friction
//   "sides" = 7  : the four side faces (= Γ2)               load group inside Γ2
//   "Ω"     = 10 : the domain (volume V1)
// There is no "Γ3,1" (no frictionless contact): the paper allows either part of Γ3 to be
// empty.  Tags follow block.geo ("Γ3,2" = 4, "sides" = 7).
//
// Mesh: unstructured, so that no direction is preferred (frictional sliding in any
// direction of the plane z = 0 meets the same kind of mesh): Frontal-Delaunay on the
// faces (Mesh.Algorithm = 6), Delaunay in the volume (Mesh.Algorithm3D = 1), target size
// lc = 0.07 (~3.6 elements through the thickness, ~1100 nodes, ~4200 tetrahedra).  One
// thread, so the output is deterministic.  Only physical entities are saved
// (Mesh.SaveAll = 0): 4-node tetrahedra (gmsh type 4) and 3-node triangles (type 2).
//
//   gmsh -3 slider.geo -format msh41 -o slider.msh          (-setnumber lc 0.05: finer)

If (!Exists(lc))
  lc = 0.07;
EndIf
If (lc <= 0 || lc > 0.25)
  Error("slider.geo: lc must be in (0, 0.25] (got %g)", lc);
  Abort;
EndIf

SetFactory("OpenCASCADE");
Mesh.SaveAll = 0;
Mesh.Algorithm = 6;            // Frontal-Delaunay (faces)
Mesh.Algorithm3D = 1;          // Delaunay (volume)
General.NumThreads = 1;        // deterministic output

Box(1) = {0, 0, 0, 1, 1, 0.25};
MeshSize{PointsOf{Volume{1};}} = lc;

// Faces are picked by bounding box: a surface is taken if it lies inside the box.
e = 1e-6;
topf() = Surface In BoundingBox{-e, -e, 0.25-e, 1+e, 1+e, 0.25+e};   // z = 0.25
botf() = Surface In BoundingBox{-e, -e, -e, 1+e, 1+e, e};            // z = 0
sides() = {Surface In BoundingBox{-e, -e, -e, e, 1+e, 0.25+e},       // x = 0
           Surface In BoundingBox{1-e, -e, -e, 1+e, 1+e, 0.25+e},    // x = 1
           Surface In BoundingBox{-e, -e, -e, 1+e, e, 0.25+e},       // y = 0
           Surface In BoundingBox{-e, 1-e, -e, 1+e, 1+e, 0.25+e}};   // y = 1
If (#topf() != 1 || #botf() != 1 || #sides() != 4)
  Error("slider.geo: a boundary face was not found by its bounding box");
  Abort;
EndIf

Physical Surface("Γ1", 1) = {topf()};
Physical Surface("Γ2", 2) = {sides()};
Physical Surface("Γ3,2", 4) = {botf()};
Physical Surface("sides", 7) = {sides()};
Physical Volume("Ω", 10) = {1};
