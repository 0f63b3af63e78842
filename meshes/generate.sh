#!/usr/bin/env bash
# Regenerates every .msh file under meshes/ from the .geo sources with the gmsh CLI
# (gmsh 4.15.2 from PyPI: `pip install gmsh`).  Output is MSH 4.1, 2D, first order,
# only physical entities saved.  Deterministic: re-running gives byte-identical files
# (MSH 4.1 carries no version or date header).  Can be run from any directory.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")"

GMSH=${GMSH:-gmsh}
command -v "$GMSH" >/dev/null || { echo "generate.sh: gmsh not found (pip install gmsh, or set GMSH=...)" >&2; exit 1; }

# run gmsh quietly; fail on gmsh errors (gmsh itself exits 0 after a script Error())
mesh() {
    local log
    log=$("$GMSH" -2 -format msh41 -v 2 "$@" 2>&1) || { echo "$log" >&2; exit 1; }
    if grep -q '^Error' <<<"$log"; then echo "$log" >&2; exit 1; fi
    if [[ -n "$log" ]]; then echo "$log" >&2; fi
}

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
