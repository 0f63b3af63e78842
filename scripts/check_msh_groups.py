#!/usr/bin/env python3
"""Prints the physical groups of a gmsh file as meshio sees them, as JSON.

    python3 scripts/check_msh_groups.py FILE.msh [--nodes]

Output (UTF-8, keys sorted): {name: {"tag": t, "dim": d, "elements": count}}, with
"nodes": count (distinct nodes of the group's elements) added under --nodes. Tests compare
it with `viscontact mesh-info`.

Element counts come from meshio's `cell_sets` (one index array per cell block for each
physical name), not from `cell_data["gmsh:physical"]`: the latter keeps only the first
physical tag of an entity, so an edge in both "Γ2" and "top" would be missed by "top".
(For MSH 2.2 files, where meshio makes no cell sets, that tag is all there is.)
Exits 1 with a message if meshio cannot read the file.
"""

import argparse
import json
import sys


def fail(msg):
    print(f"check_msh_groups: error: {msg}", file=sys.stderr)
    sys.exit(1)


def main():
    ap = argparse.ArgumentParser(description="Physical groups of a gmsh file, via meshio.")
    ap.add_argument("msh", help="gmsh .msh file")
    ap.add_argument("--nodes", action="store_true", help="also count each group's nodes")
    args = ap.parse_args()

    try:
        import meshio
        import numpy as np
    except ImportError:
        fail("meshio is not installed (pip install meshio)")
    try:
        mesh = meshio.read(args.msh, file_format="gmsh")
    except Exception as e:  # meshio raises many kinds
        fail(f"meshio cannot read {args.msh}: {type(e).__name__}: {e}")

    groups = {}
    for name, (tag, dim) in mesh.field_data.items():
        sets = mesh.cell_sets.get(name)
        if sets is None and not any(n in mesh.cell_sets for n in mesh.field_data):
            # No cell sets at all (MSH 2.2): fall back on the per-element physical tag.
            tags = mesh.cell_data.get("gmsh:physical") or [None] * len(mesh.cells)
            sets = [
                None if t is None or block.dim != dim else np.nonzero(t == tag)[0]
                for block, t in zip(mesh.cells, tags)
            ]
        if sets is None:  # no element carries this group
            sets = [None] * len(mesh.cells)
        count = 0
        nodes = set()
        for block, idx in zip(mesh.cells, sets):
            if idx is None or len(idx) == 0:
                continue
            count += len(idx)
            if args.nodes:
                nodes.update(np.unique(block.data[idx]).tolist())
        entry = {"tag": int(tag), "dim": int(dim), "elements": count}
        if args.nodes:
            entry["nodes"] = len(nodes)
        groups[name] = entry

    json.dump(groups, sys.stdout, ensure_ascii=False, sort_keys=True)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
