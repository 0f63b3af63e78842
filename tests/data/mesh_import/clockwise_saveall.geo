// Unit square whose curve loop runs clockwise, so gmsh writes every triangle clockwise;
// Mesh.SaveAll = 1 also saves point elements (type 15), an unused geometry point, the
// lines of curves without a physical group, and a physical point group.
//   gmsh -2 -format msh41 clockwise_saveall.geo -o clockwise_saveall.msh
Mesh.SaveAll = 1;
lc = 0.5;
Point(1) = {0, 0, 0, lc};
Point(2) = {1, 0, 0, lc};
Point(3) = {1, 1, 0, lc};
Point(4) = {0, 1, 0, lc};
Point(9) = {3, 3, 0, lc};   // not part of the surface
Line(1) = {1, 4};   // left, downwards-up (clockwise loop)
Line(2) = {4, 3};   // top
Line(3) = {3, 2};   // right
Line(4) = {2, 1};   // bottom
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Physical Curve("bottom", 11) = {4};
Physical Curve("left", 12) = {1};
Physical Point("corner", 13) = {1};
Physical Surface("square", 14) = {1};
