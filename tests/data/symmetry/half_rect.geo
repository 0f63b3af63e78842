// half_rect.geo -- half of a rectangle on a foundation, for the 2D symmetry test of
// tests/solutions/dirichlet.rs: Omega = (0,1) x (0,0.5), the half x > 0 of (-1,1) x (0,0.5).
// mirror.py reflects this mesh in the line x = 0 to make whole_rect.msh.
//
// Physical groups (name = tag), names are UTF-8:
//   "Γ1"   = 1  : right x = 1                      clamped
//   "Γ2"   = 2  : top y = 0.5                      traction
//   "Γ3,1" = 3  : bottom y = 0, x in [0.5,1]       contact
//   "Γ3,2" = 4  : bottom y = 0, x in [0,0.5]       friction (meets the line x = 0)
//   "sym"  = 7  : x = 0, the symmetry line (half model only)
//   "Ω"    = 10 : the surface
//
//   gmsh -2 half_rect.geo -format msh41 -o half_rect.msh

SetFactory("Built-in");
lc = 0.1;
Point(1) = {0, 0, 0, lc};
Point(2) = {0.5, 0, 0, lc};
Point(3) = {1, 0, 0, lc};
Point(4) = {1, 0.5, 0, lc};
Point(5) = {0, 0.5, 0, lc};
Line(1) = {1, 2};
Line(2) = {2, 3};
Line(3) = {3, 4};
Line(4) = {4, 5};
Line(5) = {5, 1};
Curve Loop(1) = {1, 2, 3, 4, 5};
Plane Surface(1) = {1};
Physical Curve("Γ1", 1) = {3};
Physical Curve("Γ2", 2) = {4};
Physical Curve("Γ3,1", 3) = {2};
Physical Curve("Γ3,2", 4) = {1};
Physical Curve("sym", 7) = {5};
Physical Surface("Ω", 10) = {1};
Mesh.Algorithm = 6;
