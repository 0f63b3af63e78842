#!/usr/bin/env bash
# One PETSc run over MPI ranks (docs/cluster.md): the plate lying on its foundation
# (meshes/3d/block.geo at height 1/4, gmsh's unstructured tetrahedra of size SIZE, made
# into out/meshes/ when missing) under the block's scene without contact and friction
# (KIND=linear, the default) or with them through the active set (KIND=contact), STEPS
# steps, no output but the last frame (EVERY=K: a frame every K steps; over several ranks a
# frame is a .pvtu with a piece per rank), no checkpoints; each rank count one after the other
# in one call (0: one process, without mpirun). Prints setup, steps and total seconds (rank
# 0's summary.json), the Newton systems (with contact) and Krylov iterations, and the peak
# memory of the largest rank.
#   HDF5_DIR=/usr/lib/x86_64-linux-gnu/hdf5/serial cargo build --release --features petsc
#   BIN=target/release/viscontact scripts/ranks.sh [SIZE [STEPS [RANKS...]]]
# default: 0.015 20 1 2. As root, Open MPI needs OMPI_ALLOW_RUN_AS_ROOT=1 and
# OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1; more ranks than cores, MPIRUN="mpirun --oversubscribe".
# On a machine without PETSc and MPI: scripts/carry.sh packs this script with what it runs.
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-0.015}
steps=${2:-20}
shift 2 || true
ranks=("${@:-1 2}")
case "${KIND:-linear}" in
    linear) physics=(--set contact.enabled=false --set friction.enabled=false) ;;
    contact) physics=(--set solver.contact=active_set) ;;
    *) echo "KIND is linear or contact" >&2; exit 2 ;;
esac
bin=$(realpath "${BIN:-target/release/viscontact}")
read -ra mpirun <<<"${MPIRUN:-mpirun}" # a command with its options
mesh=out/meshes/plate_$size.msh
mkdir -p out/meshes
[ -f "$mesh" ] || gmsh -3 meshes/3d/block.geo -setnumber height 0.25 \
    -setnumber unstructured 1 -setnumber Mesh.MeshSizeMax "$size" \
    -format msh41 -bin -o "$mesh" >/dev/null
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
end=$(python3 -c "print($steps / 20)")
printf '%-6s %8s %8s %8s %8s %8s %8s %9s\n' ranks dofs setup_s steps_s total_s systems krylov \
    peak_MB
for n in ${ranks[@]}; do
    # Each rank's peak, by GNU time around it (the rank from Open MPI's or PMI's variable).
    cat >"$dir/one.sh" <<SH
#!/bin/sh
exec ${TIME_BIN:-/usr/bin/time} -f %M -o "$dir/peak.\${OMPI_COMM_WORLD_RANK:-\${PMI_RANK:-0}}" "\$@"
SH
    chmod +x "$dir/one.sh"
    rm -f "$dir"/peak.*
    launch=("${mpirun[@]}" -n "$n")
    [ "$n" = 0 ] && launch=()
    "${launch[@]}" "$dir/one.sh" "$bin" run examples/block.toml --quiet --out "$dir/o$n" \
        --set "mesh.file=../$mesh" --set "time.end=$end" --set "time.steps=$steps" \
        "${physics[@]}" --set solver.linear=petsc --set "output.every=${EVERY:-100000}" \
        --set checkpoint.enabled=false >/dev/null
    peak=$(cat "$dir"/peak.* | sort -n | tail -1)
    python3 - "$dir/o$n/summary.json" "$n" "$peak" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
t = s["timing"]
# With contact, the iterations are the active set's Newton systems and PETSc's record
# counts their Krylov iterations; without, the iterations are the Krylov iterations.
newton = (s.get("petsc") or {}).get("newton")
systems, krylov = (newton["systems"], newton["krylov_total"]) if newton else ("-", s["iterations"]["total"])
print(f'{sys.argv[2]:<6} {s["dofs"]:>8} {t["setup_s"]:>8.2f} {t["steps_s"]:>8.2f} '
      f'{t["total_s"]:>8.2f} {systems:>8} {krylov:>8} {int(sys.argv[3]) / 1024:>9.0f}')
PY
done
