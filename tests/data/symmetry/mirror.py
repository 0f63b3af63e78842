"""Reflects a half mesh in a coordinate plane (3D) or line (2D) into the whole mesh, meshed
symmetrically (tests/solutions/dirichlet.rs): half_block.msh in y = 0.5 into
whole_block.msh, half_rect.msh in x = 0 into whole_rect.msh.  The half's nodes keep their
tags and come first; each node off the plane gets a mirror image; every cell and boundary
facet gets one, with two nodes swapped to keep its orientation.  Every group but "sym" (the
plane, now inside) keeps its name and tag, holding both halves.

    python3 mirror.py          (needs the gmsh Python module: pip install gmsh)
"""
import gmsh

gmsh.initialize()
gmsh.option.setNumber("General.Verbosity", 2)
for half, whole, axis, plane in [("half_block.msh", "whole_block.msh", 1, 0.5),
                                 ("half_rect.msh", "whole_rect.msh", 0, 0.0)]:
    gmsh.clear()
    gmsh.open(half)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    xyz = {int(t): coords[3 * i:3 * i + 3] for i, t in enumerate(tags)}
    top = max(xyz)
    image = {t: t if abs(p[axis] - plane) < 1e-12 else t + top for t, p in xyz.items()}

    groups = []  # (dim, tag, name, [node lists])
    for dim, ptag in gmsh.model.getPhysicalGroups():
        name = gmsh.model.getPhysicalName(dim, ptag)
        cells = []
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, ptag):
            types, _, nodes = gmsh.model.mesh.getElements(dim, ent)
            for ty, ns in zip(types, nodes):
                k = dim + 1  # simplices
                cells += [[int(n) for n in ns[i:i + k]] for i in range(0, len(ns), k)]
        groups.append((dim, ptag, name, cells))

    dim = gmsh.model.getDimension()
    gmsh.model.add("whole")
    vol = gmsh.model.addDiscreteEntity(dim)
    node_tags, node_xyz = [], []
    for t in sorted(xyz):
        node_tags.append(t)
        node_xyz += list(xyz[t])
    for t in sorted(xyz):
        if image[t] != t:
            p = list(xyz[t])
            p[axis] = 2 * plane - p[axis]
            node_tags.append(image[t])
            node_xyz += p
    gmsh.model.mesh.addNodes(dim, vol, node_tags, node_xyz)
    next_element = 1
    for gdim, ptag, name, cells in groups:
        if name == "sym":
            continue
        mirrored = [[image[n] for n in c] for c in cells]
        for c in mirrored:
            c[0], c[1] = c[1], c[0]
        both = cells + mirrored
        ent = vol if gdim == dim else gmsh.model.addDiscreteEntity(gdim)
        etype = {(3, 3): 4, (3, 2): 2, (2, 2): 2, (2, 1): 1}[(dim, gdim)]
        flat = [n for c in both for n in c]
        etags = list(range(next_element, next_element + len(both)))
        next_element += len(both)
        gmsh.model.mesh.addElementsByType(ent, etype, etags, flat)
        gmsh.model.addPhysicalGroup(gdim, [ent], ptag, name)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.write(whole)
gmsh.finalize()
