// sliver.geo -- the paper's rectangle (0,2) x (0,1), unstructured, with sliver elements.
//
// Three points are embedded in the surface so that the Delaunay mesher (mesh size
// h = 0.25) must make needle and cap triangles:
//   P10 = (0.5, 2.5e-5)                 hovers 1e-4·h above Γ3,1 (contact boundary)
//   P11 = (1.4, 0.5), P12 = P11 + 5e-5  two interior points 2e-4·h apart
//   P13 = (1.9, 0.75), P14 = P13 + 5e-5 (y) the same near Γ2 (right)
// P10 and P13/P14 give needle triangles with smallest angles of 0.008° to 0.2° and aspect
// ratios up to 4·10^3, two of them at the Γ3,1 node (0.5, 0); around P11/P12 gmsh grades
// the mesh down to the pair's distance (tiny, well-shaped triangles next to coarse ones).
// tests/cli/hard_meshes.rs checks min angle < 1° and aspect ratio >= 10^3 with
// `viscontact mesh-info --json`.
//
//   gmsh -2 sliver.geo -format msh41 -o sliver.msh        (gmsh 4.15.2)
//
// Physical groups as in meshes/paper/rect.geo: "Γ1" = 1 (left), "Γ2" = 2 (top + right),
// "Γ3,1" = 3 (bottom, x <= 1), "Γ3,2" = 4 (bottom, x >= 1), "top" = 5, "right" = 6,
// "Ω" = 10.

SetFactory("OpenCASCADE");
Mesh.SaveAll = 0;
Mesh.Algorithm = 5;   // Delaunay: keeps the embedded points where they are

h = 0.25;
d = 1e-4 * h;

Point(1) = {0, 0, 0, h};
Point(2) = {1, 0, 0, h};
Point(3) = {2, 0, 0, h};
Point(4) = {2, 1, 0, h};
Point(5) = {0, 1, 0, h};

Line(1) = {1, 2};   // bottom, x in [0,1]
Line(2) = {2, 3};   // bottom, x in [1,2]
Line(3) = {3, 4};   // right
Line(4) = {4, 5};   // top
Line(5) = {5, 1};   // left

Curve Loop(1) = {1, 2, 3, 4, 5};
Plane Surface(1) = {1};

Point(10) = {0.5, d, 0, h};
Point(11) = {1.4, 0.5, 0, h};
Point(12) = {1.4 + 2 * d, 0.5, 0, h};
Point(13) = {1.9, 0.75, 0, h};
Point(14) = {1.9, 0.75 + 2 * d, 0, h};
Point{10, 11, 12, 13, 14} In Surface{1};

Physical Curve("Γ1", 1) = {5};
Physical Curve("Γ2", 2) = {4, 3};
Physical Curve("Γ3,1", 3) = {1};
Physical Curve("Γ3,2", 4) = {2};
Physical Curve("top", 5) = {4};
Physical Curve("right", 6) = {3};
Physical Surface("Ω", 10) = {1};
