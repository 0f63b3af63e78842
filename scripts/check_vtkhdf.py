#!/usr/bin/env python3
"""Checks a viscontact solution.vtkhdf with independent readers: VTK's vtkHDFReader and h5py.

    python3 scripts/check_vtkhdf.py FILE [--expect-steps S] [--compare K VTU]... [--digest]

Reads FILE with vtkHDFReader (the reader ParaView uses): its number of steps and their times.
--expect-steps S: the file has S steps. --compare K VTU: step K (0-based) read by vtkHDFReader
equals VTU read by vtkXMLUnstructuredGridReader bit for bit: points, cells, and every point
and cell array (names, components, type, values); field data (the run id) is not compared.
--digest: also reads every dataset with h5py and reports a SHA-256 of its bytes, shape and
type (FieldData/run_id left out: two runs of one scene differ only there).

Prints one JSON object {"steps", "times", "points", "cells", "point_fields", "cell_fields",
"compared", "digest"} and exits 0; otherwise prints `check_vtkhdf: error: ...` on stderr and
exits 1 (2 for bad arguments).
"""

import argparse
import hashlib
import json
import sys


def fail(msg):
    print(f"check_vtkhdf: error: {msg}", file=sys.stderr)
    sys.exit(1)


def arrays(data):
    from vtk.util.numpy_support import vtk_to_numpy

    out = {}
    for i in range(data.GetNumberOfArrays()):
        a = data.GetArray(i)
        out[a.GetName()] = vtk_to_numpy(a)
    return out


def cells_of(grid):
    from vtk.util.numpy_support import vtk_to_numpy

    cells = grid.GetCells()
    return vtk_to_numpy(cells.GetConnectivityArray()), vtk_to_numpy(cells.GetOffsetsArray())


def same(what, a, b):
    if a.dtype != b.dtype or a.shape != b.shape:
        fail(f"{what}: {a.dtype}{a.shape} in the .vtkhdf, {b.dtype}{b.shape} in the .vtu")
    if a.tobytes() != b.tobytes():
        fail(f"{what}: values differ")


def main():
    ap = argparse.ArgumentParser(description="Check a viscontact .vtkhdf series.")
    ap.add_argument("file")
    ap.add_argument("--expect-steps", type=int, metavar="S")
    ap.add_argument("--compare", nargs=2, action="append", default=[], metavar=("K", "VTU"))
    ap.add_argument("--digest", action="store_true")
    args = ap.parse_args()
    try:
        import vtk
        from vtk.util.numpy_support import vtk_to_numpy
    except ImportError:
        fail("the vtk Python package is not installed (pip install vtk)")

    r = vtk.vtkHDFReader()
    if not r.CanReadFile(args.file):
        fail(f"vtkHDFReader cannot read {args.file}")
    r.SetFileName(args.file)
    r.UpdateInformation()
    steps = r.GetNumberOfSteps()
    info = r.GetOutputInformation(0)
    key = vtk.vtkStreamingDemandDrivenPipeline.TIME_STEPS()
    times = list(info.Get(key)) if info.Has(key) else []
    if len(times) != steps:
        fail(f"{steps} steps but {len(times)} times")
    if args.expect_steps is not None and steps != args.expect_steps:
        fail(f"{steps} steps, expected {args.expect_steps}")

    r.SetStep(0)
    r.Update()
    g = r.GetOutput()
    result = {
        "steps": steps,
        "times": times,
        "points": g.GetNumberOfPoints(),
        "cells": g.GetNumberOfCells(),
        "point_fields": sorted(arrays(g.GetPointData())),
        "cell_fields": sorted(arrays(g.GetCellData())),
        "compared": 0,
    }
    for k, vtu in args.compare:
        k = int(k)
        if not 0 <= k < steps:
            fail(f"--compare {k}: the file has steps 0 .. {steps - 1}")
        r.SetStep(k)
        r.Update()
        h = r.GetOutput()
        x = vtk.vtkXMLUnstructuredGridReader()
        x.SetFileName(vtu)
        x.Update()
        v = x.GetOutput()
        if v.GetNumberOfPoints() == 0:
            fail(f"vtkXMLUnstructuredGridReader read no points from {vtu}")
        what = f"step {k} vs {vtu}"
        same(f"{what}: points", vtk_to_numpy(h.GetPoints().GetData()),
             vtk_to_numpy(v.GetPoints().GetData()))
        for part, a, b in zip(("connectivity", "offsets"), cells_of(h), cells_of(v)):
            same(f"{what}: {part}", a.astype("int64"), b.astype("int64"))
        for kind, hd, vd in (("point", h.GetPointData(), v.GetPointData()),
                             ("cell", h.GetCellData(), v.GetCellData())):
            ha, va = arrays(hd), arrays(vd)
            if sorted(ha) != sorted(va):
                fail(f"{what}: {kind} fields {sorted(ha)} vs {sorted(va)}")
            for name in ha:
                same(f"{what}: {kind} field {name}", ha[name], va[name])
        result["compared"] += 1

    if args.digest:
        import h5py

        digest = {}

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and name != "VTKHDF/FieldData/run_id":
                a = obj[...]
                h = hashlib.sha256(a.tobytes()).hexdigest()
                digest[name] = f"{a.dtype}{list(a.shape)} {h}"

        with h5py.File(args.file, "r") as f:
            f.visititems(visit)
            digest["NSteps"] = int(f["VTKHDF/Steps"].attrs["NSteps"])
        result["digest"] = digest
    print(json.dumps(result))


if __name__ == "__main__":
    main()
