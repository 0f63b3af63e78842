#!/usr/bin/env bash
# The contact solvers on the plate lying on its foundation (issue 29), back to back in one
# run: for each plate size, a linear-only run and the same scene with each of the solvers
# named, the first STEPS steps of 20 (the block's span in larger steps), no output, no
# checkpoints. Prints a Markdown table: setup and steps (summary.json), peak resident memory
# (GNU time's "Maximum resident set size"), iterations (dual iterations; Krylov iterations
# of a linear PETSc run; Newton systems of the active set, with their Krylov iterations).
# The plates are meshes/3d/block.geo at height 1/4 with gmsh's unstructured tetrahedra of
# the given size, made into out/meshes/ when missing.
#
#   examples/bench_duals.sh [STEPS [SIZE...]]          # default: 2 0.06 0.03
#   SOLVERS="dense sparse" examples/bench_duals.sh 3 0.03
#
# With a build that has the `petsc` feature (BIN names its binary), `linear_petsc` is the
# linear-only run through PETSc and `active_set` the active-set solver:
#   BIN=target/release/viscontact SOLVERS="dense active_set linear_petsc" \
#       examples/bench_duals.sh 20 0.03
#
# docs/performance.md ("The sparse dual") quotes its rows for 0.03 and 0.015.
set -euo pipefail
cd "$(dirname "$0")/.."
steps=${1:-2}
shift || true
if [ $# -gt 0 ]; then sizes=("$@"); else sizes=(0.06 0.03); fi
read -r -a solvers <<<"${SOLVERS:-matrix_free sparse}"
bin=${BIN:-target/release/viscontact}
[ -x "$bin" ] || cargo build --release --bin viscontact
command -v /usr/bin/time >/dev/null || { echo "needs GNU time (/usr/bin/time)" >&2; exit 2; }
mkdir -p out/meshes
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

echo "| plate | solver | setup s | steps s | peak | iterations | Krylov (a system: mean / max) |"
echo "|---|---|---|---|---|---|---|"
for size in "${sizes[@]}"; do
    mesh=out/meshes/plate_$size.msh
    [ -f "$mesh" ] || gmsh -3 meshes/3d/block.geo -setnumber height 0.25 \
        -setnumber unstructured 1 -setnumber Mesh.MeshSizeMax "$size" \
        -format msh41 -bin -o "$mesh" >/dev/null
    end=$(python3 -c "print($steps / 20)")
    for solver in linear "${solvers[@]}"; do
        case $solver in
            linear) set=(--set contact.enabled=false --set friction.enabled=false) ;;
            linear_petsc) set=(--set contact.enabled=false --set friction.enabled=false
                               --set solver.linear=petsc) ;;
            *) set=(--set "solver.contact=$solver") ;;
        esac
        out=$tmp/$size-$solver
        /usr/bin/time -f "%M" -o "$tmp/peak" "$bin" run examples/block.toml \
            --set "mesh.file=../$mesh" --set "time.end=$end" --set "time.steps=$steps" \
            --set output.every=100000 --set checkpoint.enabled=false "${set[@]}" \
            --quiet --out "$out" >/dev/null
        python3 - "$out/summary.json" "$(cat "$tmp/peak")" "$size" "$solver" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))
t = s["timing"]
peak = int(sys.argv[2]) * 1024
newton = s.get("petsc", {}).get("newton")
krylov = "—" if newton is None else (f"{newton['krylov_total']} ({newton['krylov_mean']:.1f} / "
                                     f"{newton['krylov_max']})")
print(f"| {sys.argv[3]} | {sys.argv[4]} | {t['setup_s']:.2f} | {t['steps_s']:.2f} | "
      f"{peak / 1e9:.2f} GB | {s['iterations']['total']} | {krylov} |")
EOF
    done
done
