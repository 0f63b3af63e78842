// corner.geo -- a quadrilateral whose contact side (bottom, Γ3,1) meets its friction side
// (Γ3,2) at the corner P2 under the interior angle `angle` (degrees), the case where a node
// carries a contact row along one normal and a friction row whose tangent is (nearly)
// parallel to it. Issue 11: the condensed contact matrix is singular at a 90° corner.
//
//   gmsh -2 corner.geo -setnumber angle 90 -format msh41 -o corner_090.msh
//
//            P4 (0,1) +------- top (Γ1) ------+ P3 = P2 + (−cos a, sin a)
//                     |                        \
//          left (Γ2)  |          Ω              \  side (Γ3,2), friction
//                     |                          \
//            P1 (0,0) +------ bottom (Γ3,1) ------+ P2 (1,0)
//
// Unstructured triangles (Frontal-Delaunay), h = 0.1; deterministic.
If (!Exists(angle))
  angle = 90;
EndIf
a = angle * Pi / 180;
h = 0.1;
Point(1) = {0, 0, 0, h};
Point(2) = {1, 0, 0, h};
Point(3) = {1 - Cos(a), Sin(a), 0, h};
Point(4) = {0, 1, 0, h};
Line(1) = {1, 2};  // bottom: contact
Line(2) = {2, 3};  // side: friction
Line(3) = {3, 4};  // top: clamped
Line(4) = {4, 1};  // left: traction
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Physical Curve("Γ3,1", 3) = {1};
Physical Curve("Γ3,2", 4) = {2};
Physical Curve("Γ1", 1) = {3};
Physical Curve("Γ2", 2) = {4};
Physical Surface("Ω", 10) = {1};
