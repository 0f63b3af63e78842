#!/usr/bin/env bash
# Regenerates the hard-case mesh fixtures of tests/data/hard/ with the gmsh CLI
# (gmsh 4.15.2 from PyPI: `pip install gmsh`). Deterministic; run from any directory.
#
#   sliver.msh   sliver.geo: the paper's rectangle, unstructured (Delaunay, h = 0.25), with
#                embedded points 1e-4·h from Γ3,1 and from Γ2 and 2e-4·h from each other:
#                min angle < 1°, aspect ratio > 10³ (used by tests/hard_meshes.rs)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
GMSH=${GMSH:-gmsh}
log=$("$GMSH" -2 -v 2 sliver.geo -format msh41 -o sliver.msh 2>&1) || { echo "$log" >&2; exit 1; }
if grep -q '^Error' <<<"$log"; then echo "$log" >&2; exit 1; fi
echo "wrote sliver.msh"
