#!/usr/bin/env bash
# How wall time and peak memory grow with h and with N on the paper scene (full problem:
# contact + friction + memory), no .vtu output. Meshes 1/256 and 1/512 are made with gmsh
# into out/meshes/. Usage: scripts/scaling.sh [path/to/viscontact]
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${1:-target/release/viscontact}
mkdir -p out/meshes out/scaling
for n in 256 512; do
    [ -f out/meshes/rect_$n.msh ] || gmsh -2 meshes/paper/rect.geo -setnumber n $n -format msh41 -bin -o out/meshes/rect_$n.msh >/dev/null
done
mesh() { case $1 in 128) echo meshes/paper/rect_128.msh;; *) echo out/meshes/rect_$1.msh;; esac; }
run() { # level steps
    local out=out/scaling/h$1_n$2
    /usr/bin/time -f "%e %M" -o $out.time "$BIN" run examples/paper.toml --quiet --out $out \
        --set mesh.file=../$(mesh $1) --set time.steps=$2 --set output.every=$2 >/dev/null
    read -r wall kb < $out.time
    printf '| 1/%s | %s | %s | %.2f | %.0f |\n' $1 $2 "$(grep -o '"dofs": [0-9]*' $out/summary.json | grep -o '[0-9]*$')" $wall $((kb / 1024))
}
echo "| h | N | dofs | wall (s) | peak RSS (MB) |"
echo "|---|---|---|---|---|"
for N in 128 256 512; do run 128 $N; done
for L in 256 512; do run $L 128; done
run 256 256
run 512 512
