#!/usr/bin/env bash
# Issue 28's table: the same binary and the same runs restricted to two cores
# (`taskset -c 0,1`) against every core of the machine, alternating, median of REPEAT runs
# each (setup = mesh, discretization, ordering, factorization; steps = the time loop, both
# from summary.json). The thread count is the default, the cores the process may use, so
# `taskset` alone sets it. No frames are written but the last; no checkpoints.
#
#   scripts/threads.sh [path/to/viscontact] [REPEAT]
#
# With BASELINE=path/to/another/viscontact (an earlier build), each case also runs that
# binary on all cores, alternating with the others, and the table gains its steps and the
# ratio of the two builds' steps on all cores (how the table of docs/performance.md's
# "Wide supernodes shared out" was made).
# Cases: the 2D paper scene at h = k = 1/128 and 1/512 (full), the 3D block at h = 1/24
# (full and linear only) and 1/32 (full), and, if PLATE_MESH names a gmsh mesh of the plate
# on its foundation (meshes/3d/block.geo at height 1/4, gmsh tetrahedra of size 0.03),
# that plate with PLATE_STEPS steps (default 100; full and linear only). Meshes that are not in the repository
# are made with gmsh (out/meshes/, meshes/generate.sh). To run on another machine, copy the
# binary with the shared libraries `ldd` lists and point LD_LIBRARY_PATH at them.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${1:-target/release/viscontact}
REPEAT=${2:-3}
ALL=$(nproc --all)
mkdir -p out/meshes out/threads
[ -f out/meshes/rect_512.msh ] ||
    gmsh -2 meshes/paper/rect.geo -setnumber n 512 -format msh41 -bin -o out/meshes/rect_512.msh >/dev/null
for n in 24 32; do [ -f meshes/3d/block_0$n.msh ] || meshes/generate.sh block $n; done
LINEAR=(--set contact.enabled=false --set friction.enabled=false)

# one CPUS SCENE ARGS...: prints "setup_s steps_s" of one run on the cores CPUS (of the
# binary $RUN, default $BIN).
one() {
    local cpus=$1 scene=$2 out=out/threads/run
    shift 2
    rm -rf "$out"
    taskset -c "$cpus" "${RUN:-$BIN}" run "$scene" --quiet --out "$out" --set output.every=100000 \
        --set checkpoint.enabled=false "$@" >/dev/null
    for key in setup_s steps_s; do
        grep -o "\"$key\": [0-9.e+-]*" "$out/summary.json" | grep -o '[0-9.e+-]*$'
    done | paste -sd ' '
}

# median COLUMN LINES...: the median of column COLUMN (1 or 2) of the lines.
median() {
    local col=$1
    shift
    printf '%s\n' "$@" | awk -v c="$col" '{print $c}' | sort -g |
        awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'
}

# row NAME SCENE ARGS...: the table row of a case, two cores against all, alternating
# (and the baseline on all cores, with BASELINE).
row() {
    local name=$1 scene=$2 two=() all=() base=()
    shift 2
    for _ in $(seq "$REPEAT"); do
        two+=("$(one 0,1 "$scene" "$@")")
        all+=("$(one 0-$((ALL - 1)) "$scene" "$@")")
        if [ -n "${BASELINE:-}" ]; then
            base+=("$(RUN=$BASELINE one 0-$((ALL - 1)) "$scene" "$@")")
        fi
    done
    local s2 t2 sa ta tb=0
    s2=$(median 1 "${two[@]}") t2=$(median 2 "${two[@]}")
    sa=$(median 1 "${all[@]}") ta=$(median 2 "${all[@]}")
    [ -n "${BASELINE:-}" ] && tb=$(median 2 "${base[@]}")
    awk -v n="$name" -v s2="$s2" -v t2="$t2" -v sa="$sa" -v ta="$ta" -v tb="$tb" 'BEGIN {
        printf "| %s | %.2f / %.2f s | %.2f / %.2f s | %.2f× / %.2f× |", n, s2, t2, sa, ta, s2 / sa, t2 / ta
        if (tb > 0) printf " %.2f s | %.2f× |", tb, tb / ta
        printf "\n" }'
}

if [ -n "${BASELINE:-}" ]; then
    echo "| case (setup / steps) | 2 cores | $ALL cores | $ALL vs 2 | baseline steps, $ALL cores | baseline / this |"
    echo "|---|---|---|---|---|---|"
else
    echo "| case (setup / steps) | 2 cores | $ALL cores | $ALL vs 2 |"
    echo "|---|---|---|---|"
fi
row "2D paper h = k = 1/128, full" examples/paper.toml \
    --set mesh.file=../meshes/paper/rect_128.msh --set time.steps=128
row "2D h = k = 1/512, full" examples/paper.toml \
    --set mesh.file=../out/meshes/rect_512.msh --set time.steps=512
row "3D block 1/24, full" examples/block.toml --set mesh.file=../meshes/3d/block_024.msh
row "3D block 1/24, linear only" examples/block.toml \
    --set mesh.file=../meshes/3d/block_024.msh "${LINEAR[@]}"
row "3D block 1/32, full" examples/block.toml --set mesh.file=../meshes/3d/block_032.msh
if [ -n "${PLATE_MESH:-}" ]; then
    plate=$(realpath "$PLATE_MESH") steps=${PLATE_STEPS:-100}
    row "3D plate on its foundation, full" examples/block.toml \
        --set mesh.file="$plate" --set time.steps="$steps"
    row "3D plate on its foundation, linear only" examples/block.toml \
        --set mesh.file="$plate" --set time.steps="$steps" "${LINEAR[@]}"
fi
