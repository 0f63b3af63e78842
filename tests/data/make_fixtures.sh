#!/usr/bin/env bash
# Regenerates the mesh fixtures of tests/data/ (bad and edge-case inputs for the MSH reader)
# from meshes/paper/rect.geo with the gmsh CLI (4.15.2, pip install gmsh), plus two
# hand-written files.  Deterministic; run from any directory.
#
#   rect_004.msh          rect n=4, MSH 4.1 ASCII, all groups              (valid)
#   msh22.msh             rect n=2 in MSH 2.2 format                         (unsupported version)
#   quadratic.msh         rect n=4, -order 2: 6-node triangles, 3-node lines (unsupported elements)
#   truncated.msh         rect n=8 cut in the middle of the $Elements section (no $EndElements)
#   no_contact_group.msh  rect n=4 without the physical group "Γ3,1"         (missing group)
#   inverted.msh          rect n=2 with element 9 listed clockwise           (inverted element)
#   zero_area.msh         hand-written, (0,2)x(0,1), 6 triangles + 1 triangle with 3
#                         collinear nodes (element 10), all groups present; otherwise a
#                         conforming mesh                                     (degenerate element)
#   bimaterial_bar.msh    bimaterial_bar.geo meshed (two materials bonded along x = 1)
#   symmetry/*.msh        half_block.geo, half_rect.geo meshed, and their mirror images (mirror.py);
#                         all four turned by 30° (turn.py: *_turned.msh, inclined planes)
#   mesh_checks/*.msh     from the .geo files beside them (issue 26: two halves not
#                         fragmented in 2D and 3D, a Γ2 arc off the mesh, Γ3,1 overlapping
#                         Γ3,2, overlapping physical surfaces)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
GMSH=${GMSH:-gmsh}
GEO=../../meshes/paper/rect.geo
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT

mesh() {
    local log
    log=$("$GMSH" -2 -v 2 "$@" 2>&1) || { echo "$log" >&2; exit 1; }
    if grep -q '^Error' <<<"$log"; then echo "$log" >&2; exit 1; fi
}

mesh "$GEO" -setnumber n 4 -format msh41 -o rect_004.msh
mesh "$GEO" -setnumber n 2 -format msh22 -o msh22.msh
mesh "$GEO" -setnumber n 4 -order 2 -format msh41 -o quadratic.msh

# truncated: keep the first half of the triangle block of rect_008 (cut at a line end)
mesh "$GEO" -setnumber n 8 -format msh41 -o "$tmp/rect_008.msh"
awk '/^\$Elements/ { e = NR } e && NR == e + 100 { print; exit } { print }' "$tmp/rect_008.msh" > truncated.msh

# no_contact_group: the same geometry without Physical Curve("Γ3,1")
grep -v '^Physical Curve("Γ3,1"' "$GEO" > "$tmp/rect_no_contact.geo"
mesh "$tmp/rect_no_contact.geo" -setnumber n 4 -format msh41 -o no_contact_group.msh

# inverted: element 9 "1 2 9" -> "2 1 9" (clockwise)
mesh "$GEO" -setnumber n 2 -format msh41 -o "$tmp/rect_002.msh"
python3 - "$tmp/rect_002.msh" inverted.msh <<'PY'
import sys
lines = open(sys.argv[1], encoding="utf-8").read().split("\n")
hits = [i for i, l in enumerate(lines) if l.split() == ["9", "1", "2", "9"]]
assert len(hits) == 1, hits
lines[hits[0]] = "9 2 1 9 "
open(sys.argv[2], "w", encoding="utf-8").write("\n".join(lines))
PY

# zero_area: hand-written MSH 4.1.  Nodes 2 (1,0), 7 (1,0.5), 6 (1,1) are collinear;
# element 10 = (2,7,6) has zero area.  The other 6 triangles are counter-clockwise and
# cover the domain; every edge is shared by exactly 2 triangles or is a boundary line.
cat > zero_area.msh <<'MSH'
$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
7
1 1 "Γ1"
1 2 "Γ2"
1 3 "Γ3,1"
1 4 "Γ3,2"
1 5 "top"
1 6 "right"
2 10 "Ω"
$EndPhysicalNames
$Entities
5 5 1 0
1 0 0 0 0
2 1 0 0 0
3 2 0 0 0
4 2 1 0 0
5 0 1 0 0
1 0 0 0 1 0 0 1 3 2 1 -2
2 1 0 0 2 0 0 1 4 2 2 -3
3 2 0 0 2 1 0 2 2 6 2 3 -4
4 0 1 0 2 1 0 2 2 5 2 4 -5
5 0 0 0 0 1 0 1 1 2 5 -1
1 0 0 0 2 1 0 1 10 5 1 2 3 4 5
$EndEntities
$Nodes
7 7 1 7
0 1 0 1
1
0 0 0
0 2 0 1
2
1 0 0
0 3 0 1
3
2 0 0
0 4 0 1
4
2 1 0
0 5 0 1
5
0 1 0
1 4 0 1
6
1 1 0
2 1 0 1
7
1 0.5 0
$EndNodes
$Elements
6 12 1 12
1 1 1 1
1 1 2
1 2 1 1
2 2 3
1 3 1 1
3 3 4
1 4 1 2
4 4 6
5 6 5
1 5 1 1
6 5 1
2 1 2 6
7 1 2 5
8 2 6 5
9 2 3 7
10 2 7 6
11 3 4 7
12 4 6 7
$EndElements
MSH

# mesh_checks/: meshes that are not one body, a group off the mesh, overlapping Γ3,1/Γ3,2
for g in unfragmented fillet overlap regions; do
    mesh "mesh_checks/$g.geo" -format msh41 -o "mesh_checks/$g.msh"
done
mesh -3 mesh_checks/unfragmented_3d.geo -format msh41 -o mesh_checks/unfragmented_3d.msh

# bimaterial_bar: two surfaces bonded along x = 1, for [[material.region]]
mesh bimaterial_bar.geo -format msh41 -o bimaterial_bar.msh

# symmetry/: half of a block with its symmetry plane, and the whole block made by mirroring
# the half's mesh (so that the two meshes agree on the half; issue 51)
mesh -3 symmetry/half_block.geo -format msh41 -o symmetry/half_block.msh
mesh symmetry/half_rect.geo -format msh41 -o symmetry/half_rect.msh
(cd symmetry && python3 mirror.py && python3 turn.py)
