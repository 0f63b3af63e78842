"""Turns the symmetry fixtures so that their symmetry planes are inclined
(tests/solutions/dirichlet.rs): the blocks by 30° about the x axis (the plane y = 0.5 and
the foundation z = 0 turn with them), the rectangles by 30° about the origin (the line
x = 0 turns).  Node tags, their order, the cells and the groups are kept; only the
coordinates change, by the rotation R with y' = R y.

    python3 turn.py            (after mirror.py; needs the gmsh Python module)
"""
import math

import gmsh

c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
ABOUT_X = [1, 0, 0, 0, 0, c, -s, 0, 0, s, c, 0]
ABOUT_Z = [c, -s, 0, 0, s, c, 0, 0, 0, 0, 1, 0]

gmsh.initialize()
gmsh.option.setNumber("General.Verbosity", 2)
for name, rotation in [("half_block", ABOUT_X), ("whole_block", ABOUT_X),
                       ("half_rect", ABOUT_Z), ("whole_rect", ABOUT_Z)]:
    gmsh.clear()
    gmsh.open(name + ".msh")
    gmsh.model.mesh.affineTransform(rotation)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.write(name + "_turned.msh")
gmsh.finalize()
