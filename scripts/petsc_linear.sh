#!/usr/bin/env bash
# The linear backends side by side (docs/performance.md, "PETSc"): the block's scene
# without contact and friction on gmsh's unstructured blocks, each mesh run with
# solver.linear = "cholesky" and "petsc" one after the other, 20 steps, no output but the
# last frame. Prints setup, steps and total seconds, the Krylov iterations and the peak
# memory of each run. Needs a build with the feature:
#   HDF5_DIR=/usr/lib/x86_64-linux-gnu/hdf5/serial cargo build --release --features petsc
#   scripts/petsc_linear.sh [SIZE ...]        (gmsh mesh sizes; default 0.042 0.035)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/viscontact
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
sizes=("${@:-0.042 0.035}")
printf '%-8s %-9s %8s %8s %8s %8s %10s %9s\n' size linear dofs setup_s steps_s total_s krylov peak_MB
for size in ${sizes[@]}; do
    gmsh -3 meshes/3d/block.geo -setnumber unstructured 1 -setnumber Mesh.MeshSizeMax "$size" \
        -format msh41 -o "$dir/block.msh" >/dev/null
    for linear in cholesky petsc; do
        /usr/bin/time -f '%M' -o "$dir/peak" "$bin" run examples/block.toml --quiet \
            --out "$dir/$linear" --set "mesh.file=\"$dir/block.msh\"" \
            --set contact.enabled=false --set friction.enabled=false \
            --set time.steps=20 --set output.every=1000 \
            --set "solver.linear=\"$linear\"" >/dev/null
        python3 - "$dir/$linear/summary.json" "$size" "$linear" "$(cat "$dir/peak")" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
t = s["timing"]
print(f'{sys.argv[2]:<8} {sys.argv[3]:<9} {s["dofs"]:>8} {t["setup_s"]:>8.2f} '
      f'{t["steps_s"]:>8.2f} {t["total_s"]:>8.2f} {s["iterations"]["total"]:>10} '
      f'{int(sys.argv[4]) / 1024:>9.0f}')
PY
    done
done
