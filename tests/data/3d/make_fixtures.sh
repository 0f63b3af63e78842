#!/usr/bin/env bash
# Regenerates the gmsh-made 3D fixtures of tests/data/3d/ from patch_box.geo with the gmsh
# CLI (4.15.2, pip install gmsh); the other .msh files here are hand-written (README.md).
# Deterministic; run from any directory.
#
#   patch_box.msh       unstructured box, lc = 0.2, all groups          (valid; patch tests)
#   quadratic_tets.msh  the same box, lc = 2, -order 2: 10-node tetrahedra, 6-node triangles
#                                                                        (unsupported elements)
#   slab_t0008.msh      meshes/3d/slab.geo, n = 16, t = 0.008 (1/250 of the width): flat
#                       tetrahedra that once stalled the dual solver (tests/robustness.rs)
#   slab_t0004.msh      the same, t = 0.004 (1/500 of the width): steps that needed up to
#                       2 811 dual iterations, more than the limit then (tests/robustness.rs)
#   block_unstructured.msh  meshes/3d/block.geo, n = 4, unstructured: gmsh's own tetrahedra
#                       for the block scene (tests/contact.rs: fast solver against clarabel)
#   plate_005.msh       meshes/3d/block.geo at height 1/4, unstructured, size 0.05, binary:
#                       the plate on its foundation, m >= 1 024 contact rows and a root
#                       supernode of 1.7 M values (tests/regression/threads.rs)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
GMSH=${GMSH:-gmsh}

mesh() {
    local log
    log=$("$GMSH" -3 -format msh41 -v 2 "$@" 2>&1) || { echo "$log" >&2; exit 1; }
    if grep -q '^Error' <<<"$log"; then echo "$log" >&2; exit 1; fi
}

mesh patch_box.geo -o patch_box.msh
mesh patch_box.geo -setnumber lc 2 -order 2 -o quadratic_tets.msh
mesh ../../../meshes/3d/slab.geo -setnumber n 16 -setnumber t 0.008 -o slab_t0008.msh
mesh ../../../meshes/3d/slab.geo -setnumber n 16 -setnumber t 0.004 -o slab_t0004.msh
mesh ../../../meshes/3d/block.geo -setnumber n 4 -setnumber unstructured 1 -o block_unstructured.msh
mesh ../../../meshes/3d/block.geo -setnumber height 0.25 -setnumber unstructured 1 \
    -setnumber Mesh.MeshSizeMax 0.05 -bin -o plate_005.msh
