"""Reflects half_block.msh in the plane y = 0.5 into whole_block.msh: the whole block meshed
symmetrically (tests/solutions/symmetry.rs).  The half's nodes keep their tags and come first;
each node off the plane gets a mirror image; every tetrahedron and boundary triangle gets one,
with two nodes swapped to keep its orientation.  Every group but "sym" (the plane, now
inside) keeps its name and tag, holding both halves.

    python3 mirror.py          (needs the gmsh Python module: pip install gmsh)
"""
import gmsh

gmsh.initialize()
gmsh.option.setNumber("General.Verbosity", 2)
gmsh.open("half_block.msh")
tags, coords, _ = gmsh.model.mesh.getNodes()
xyz = {int(t): coords[3 * i:3 * i + 3] for i, t in enumerate(tags)}
top = max(xyz)
image = {t: t if abs(p[1] - 0.5) < 1e-12 else t + top for t, p in xyz.items()}

groups = []  # (dim, tag, name, element type, [node lists])
for dim, ptag in gmsh.model.getPhysicalGroups():
    name = gmsh.model.getPhysicalName(dim, ptag)
    cells = []
    for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, ptag):
        types, _, nodes = gmsh.model.mesh.getElements(dim, ent)
        for ty, ns in zip(types, nodes):
            k = 4 if dim == 3 else 3
            cells += [[int(n) for n in ns[i:i + k]] for i in range(0, len(ns), k)]
    groups.append((dim, ptag, name, cells))

gmsh.model.add("whole")
vol = gmsh.model.addDiscreteEntity(3)
node_tags, node_xyz = [], []
for t in sorted(xyz):
    node_tags.append(t)
    node_xyz += list(xyz[t])
for t in sorted(xyz):
    if image[t] != t:
        x, y, z = xyz[t]
        node_tags.append(image[t])
        node_xyz += [x, 1.0 - y, z]
gmsh.model.mesh.addNodes(3, vol, node_tags, node_xyz)
next_element = 1
for dim, ptag, name, cells in groups:
    if name == "sym":
        continue
    mirrored = [[image[n] for n in c] for c in cells]
    for c in mirrored:
        c[0], c[1] = c[1], c[0]
    both = cells + mirrored
    ent = vol if dim == 3 else gmsh.model.addDiscreteEntity(2)
    etype = 4 if dim == 3 else 2
    flat = [n for c in both for n in c]
    etags = list(range(next_element, next_element + len(both)))
    next_element += len(both)
    gmsh.model.mesh.addElementsByType(ent, etype, etags, flat)
    gmsh.model.addPhysicalGroup(dim, [ent], ptag, name)
gmsh.option.setNumber("Mesh.SaveAll", 0)
gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
gmsh.write("whole_block.msh")
gmsh.finalize()
