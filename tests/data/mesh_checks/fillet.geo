// fillet.geo -- a rectangle (0,2)x(0,1) whose upper right corner was meant to be rounded:
// the fillet arc was drawn, but the surface is still bounded by the sharp corner, so the
// arc is meshed as a curve of its own whose line elements are edges of no triangle.  The
// traction group "Γ2" holds the top side and the arc; "arc" holds the arc alone; the load
// group "top" (the top side) lies inside Γ2.  Issue 26, finding 8: a load on "top" was
// refused with "mesh has no group 'Γ2'".
//
//   gmsh -2 fillet.geo -format msh41 -o fillet.msh
h = 0.125;
r = 0.25;
Point(1) = {0, 0, 0, h};
Point(2) = {2, 0, 0, h};
Point(3) = {2, 1, 0, h};
Point(4) = {0, 1, 0, h};
Point(5) = {2 - r, 1, 0, h};      // fillet start on the top side
Point(6) = {2, 1 - r, 0, h};      // fillet end on the right side
Point(7) = {2 - r, 1 - r, 0, h};  // fillet centre
Line(1) = {1, 2};  // bottom
Line(2) = {2, 3};  // right (sharp corner)
Line(3) = {3, 4};  // top (sharp corner)
Line(4) = {4, 1};  // left
Circle(5) = {6, 7, 5};  // the fillet, outside the surface's boundary
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Physical Curve("Γ1", 1) = {4};
Physical Curve("Γ2", 2) = {3, 5};
Physical Curve("Γ3,1", 3) = {1};
Physical Curve("arc", 5) = {5};
Physical Curve("top", 6) = {3};
Physical Surface("Ω", 10) = {1};
