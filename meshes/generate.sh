#!/usr/bin/env bash
# Regenerates every .msh file under meshes/ from the .geo sources with the gmsh CLI
# (gmsh 4.15.2 from PyPI: `pip install gmsh`).  Output is MSH 4.1, first order (2D
# triangles; tetrahedra under 3d/), only physical entities saved.  Deterministic:
# re-running gives byte-identical files (MSH 4.1 carries no version or date header).
# Can be run from any directory.
#
#   meshes/generate.sh              all the committed meshes
#   meshes/generate.sh block N      only meshes/3d/block_NNN.msh (N even >= 2, zero-padded
#                                   to 3 digits), for meshes too big to commit: N = 24 is
#                                   the benchmark mesh (30625 nodes, 91875 dofs, 6.8 MB),
#                                   N = 16 has 9537 nodes (28611 dofs, 1.6 MB)
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")"

GMSH=${GMSH:-gmsh}
command -v "$GMSH" >/dev/null || { echo "generate.sh: gmsh not found (pip install gmsh, or set GMSH=...)" >&2; exit 1; }

# run gmsh quietly; fail on gmsh errors (gmsh itself exits 0 after a script Error())
# mesh [-3] FILE.geo [gmsh options...]: a 2D mesh, or with -3 first a 3D one
mesh() {
    local dim=-2 log
    if [[ $1 == -3 ]]; then dim=-3; shift; fi
    log=$("$GMSH" "$dim" -format msh41 -v 2 "$@" 2>&1) || { echo "$log" >&2; exit 1; }
    if grep -q '^Error' <<<"$log"; then echo "$log" >&2; exit 1; fi
    if [[ -n "$log" ]]; then echo "$log" >&2; fi
}

# on demand: one block mesh (not committed)
if (( $# > 0 )); then
    if [[ $# -ne 2 || $1 != block || ! $2 =~ ^[0-9]+$ ]] || (( 10#$2 < 2 || 10#$2 % 2 != 0 )); then
        echo "usage: generate.sh [block N]   (N even >= 2; writes meshes/3d/block_NNN.msh)" >&2
        exit 2
    fi
    n=$((10#$2))
    out=$(printf '3d/block_%03d.msh' "$n")
    mesh -3 3d/block.geo -setnumber n "$n" -o "$out"
    echo "wrote $out"
    exit 0
fi

# the paper's rectangle, nested structured meshes h = 1/8 .. 1/128
for n in 8 16 32 64 128; do
    out=$(printf 'paper/rect_%03d.msh' "$n")
    mesh paper/rect.geo -setnumber n "$n" -o "$out"
    echo "wrote $out"
done
# the same as rect_016.msh, binary MSH 4.1 (tests the binary reader)
mesh paper/rect.geo -setnumber n 16 -bin -o paper/rect_016_binary.msh
echo "wrote paper/rect_016_binary.msh"

mesh bracket/bracket.geo -o bracket/bracket.msh
echo "wrote bracket/bracket.msh"

mesh plate_hole/plate_hole.geo -o plate_hole/plate_hole.msh
echo "wrote plate_hole/plate_hole.msh"

# the examples of issue 51: a punch on a pad (examples/punch.toml), a body with a soft layer
# (examples/bimaterial.toml)
mesh punch/punch.geo -o punch/punch.msh
echo "wrote punch/punch.msh"
mesh bimaterial/bimaterial.geo -o bimaterial/bimaterial.msh
echo "wrote bimaterial/bimaterial.msh"

# 3D, tetrahedra (4 nodes).  The block on its foundation, h = 1/2, 1/4, 1/8 (larger n:
# `generate.sh block N` above)
for n in 2 4 8; do
    out=$(printf '3d/block_%03d.msh' "$n")
    mesh -3 3d/block.geo -setnumber n "$n" -o "$out"
    echo "wrote $out"
done
# the slab on rect_016.msh's triangulation, thickness t = 0.2 and 0.04 (1/10 and 1/50 of
# the width 2); the file name gives t in millimetres
mesh -3 3d/slab.geo -setnumber n 16 -setnumber t 0.2 -o 3d/slab_016_t0200.msh
echo "wrote 3d/slab_016_t0200.msh"
mesh -3 3d/slab.geo -setnumber n 16 -setnumber t 0.04 -o 3d/slab_016_t0040.msh
echo "wrote 3d/slab_016_t0040.msh"

mesh -3 3d/slider.geo -o 3d/slider.msh
echo "wrote 3d/slider.msh"

# the half of the block cut by its plane of symmetry y = 0.5, h = 1/8 (examples/half_block.toml)
mesh -3 half_block/half_block.geo -o half_block/half_block.msh
echo "wrote half_block/half_block.msh"
