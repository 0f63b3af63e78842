#!/usr/bin/env python3
"""Checks a viscontact output series with an independent reader (meshio).

    python3 scripts/check_vtu.py DIR [--expect-points P] [--expect-fields a,b,c]

Reads DIR/solution.pvd (xml.etree), checks that it lists at least one frame, that the
times are finite and increasing, that every listed .vtu exists and meshio reads it, and that
all frames have the same number of points and the same point and cell field names (each
field of the right length). --expect-points P: every frame has P points. --expect-fields:
the point and cell field names, together, are exactly these (in any order).

Prints one line `ok: N files, P points, C cells, t = T0 .. T1, fields: ...` and exits 0;
otherwise prints `check_vtu: error: ...` on stderr and exits 1 (2 for bad arguments).
"""

import argparse
import math
import os
import sys
import xml.etree.ElementTree as ET


def fail(msg):
    print(f"check_vtu: error: {msg}", file=sys.stderr)
    sys.exit(1)


def read_pvd(path):
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        fail(f"{path}: no such file")
    except ET.ParseError as e:
        fail(f"{path}: not valid XML: {e}")
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        fail(f'{path}: not a VTK collection (expected <VTKFile type="Collection">)')
    entries = []
    for ds in root.iter("DataSet"):
        file, timestep = ds.get("file"), ds.get("timestep")
        if file is None or timestep is None:
            fail(f"{path}: a <DataSet> lacks its file or timestep attribute")
        try:
            t = float(timestep)
        except ValueError:
            fail(f'{path}: timestep="{timestep}" of {file} is not a number')
        if not math.isfinite(t):
            fail(f'{path}: timestep="{timestep}" of {file} is not finite')
        entries.append((t, file))
    if not entries:
        fail(f"{path}: lists no frames")
    for (t0, f0), (t1, f1) in zip(entries, entries[1:]):
        if not t1 > t0:
            fail(f"{path}: times not increasing: {f0} at {t0!r}, then {f1} at {t1!r}")
    return entries


def main():
    ap = argparse.ArgumentParser(description="Check a viscontact .pvd/.vtu series with meshio.")
    ap.add_argument("dir", help="output directory holding solution.pvd")
    ap.add_argument("--expect-points", type=int, metavar="P")
    ap.add_argument("--expect-fields", metavar="a,b,c")
    args = ap.parse_args()

    try:
        import meshio
    except ImportError:
        fail("meshio is not installed (pip install meshio)")

    pvd = os.path.join(args.dir, "solution.pvd")
    entries = read_pvd(pvd)

    first = None  # (file, points, cells, point field names, cell field names)
    for t, file in entries:
        path = os.path.join(args.dir, file)
        if not os.path.isfile(path):
            fail(f"{pvd} lists {file} (t = {t!r}), but {path} does not exist")
        try:
            mesh = meshio.read(path, file_format="vtu")
        except Exception as e:  # meshio raises many kinds
            fail(f"meshio cannot read {path}: {type(e).__name__}: {e}")
        npts = len(mesh.points)
        ncells = sum(len(block.data) for block in mesh.cells)
        pnames = sorted(mesh.point_data)
        cnames = sorted(mesh.cell_data)
        for name, a in mesh.point_data.items():
            if len(a) != npts:
                fail(f"{path}: point field {name} has {len(a)} values for {npts} points")
        for name, blocks in mesh.cell_data.items():
            n = sum(len(b) for b in blocks)
            if n != ncells:
                fail(f"{path}: cell field {name} has {n} values for {ncells} cells")
        if first is None:
            first = (file, npts, ncells, pnames, cnames)
            continue
        f0, p0, c0, pn0, cn0 = first
        if npts != p0 or ncells != c0:
            fail(f"{path}: {npts} points, {ncells} cells, but {f0} has {p0} points, {c0} cells")
        if pnames != pn0:
            fail(f"{path}: point fields {pnames}, but {f0} has {pn0}")
        if cnames != cn0:
            fail(f"{path}: cell fields {cnames}, but {f0} has {cn0}")

    _, npts, ncells, pnames, cnames = first
    if args.expect_points is not None and npts != args.expect_points:
        fail(f"{npts} points, expected {args.expect_points}")
    if args.expect_fields is not None:
        want = {f.strip() for f in args.expect_fields.split(",") if f.strip()}
        have = set(pnames) | set(cnames)
        if have != want:
            missing = ", ".join(sorted(want - have)) or "none"
            extra = ", ".join(sorted(have - want)) or "none"
            fail(f"fields differ from --expect-fields: missing {missing}; unexpected {extra}")

    fields = ", ".join(pnames) + " (point); " + ", ".join(cnames) + " (cell)"
    print(
        f"ok: {len(entries)} files, {npts} points, {ncells} cells, "
        f"t = {entries[0][0]!r} .. {entries[-1][0]!r}, fields: {fields}"
    )


if __name__ == "__main__":
    main()
