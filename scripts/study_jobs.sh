#!/usr/bin/env bash
# Issue 28's study target: the paper's Tables 1–3 (`study examples/paper.toml --vary both,h,k
# --levels 8,16,32,64 --reference 128 --repeat 1`) with `--jobs 1` against `--jobs 2`,
# alternating, REPEAT times each; prints every wall time (the whole command), the medians
# and their ratio, and checks that the numbers of the two are the same (study.json without
# its times and the line that says how they were measured).
#
#   scripts/study_jobs.sh [path/to/viscontact] [REPEAT]
#
# With BASELINE=path/to/another/viscontact (an earlier build), that binary runs both too,
# alternating with the others, and its numbers must be the same as well.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${1:-target/release/viscontact}
REPEAT=${2:-3}
OUT=out/study_jobs
mkdir -p "$OUT"
ARGS=(examples/paper.toml --vary both,h,k --levels 8,16,32,64 --reference 128 --repeat 1)

# one BIN JOBS TAG: runs the study, prints its wall time in seconds, keeps its untimed
# numbers in numbers_TAG_JOBS.json.
one() {
    local bin=$1 jobs=$2 tag=$3 dir=$OUT/run start end
    rm -rf "$dir"
    start=$(date +%s.%N)
    "$bin" study "${ARGS[@]}" --jobs "$jobs" --out "$dir" >/dev/null
    end=$(date +%s.%N)
    python3 - "$dir/study.json" "$OUT/numbers_${tag}_$jobs.json" <<'EOF'
import json, sys
def untimed(v):
    if isinstance(v, dict):
        return {k: untimed(x) for k, x in v.items()
                if k not in ("wall_s", "steps_s", "per_step_s", "runs", "timed")}
    if isinstance(v, list):
        return [untimed(x) for x in v]
    return v
json.dump(untimed(json.load(open(sys.argv[1]))), open(sys.argv[2], "w"), sort_keys=True)
EOF
    awk "BEGIN {print $end - $start}"
}

median() {
    printf '%s\n' "$@" | sort -g |
        awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'
}

declare -A times
rm -f "$OUT"/numbers_*.json
for _ in $(seq "$REPEAT"); do
    tag=0
    for bin in "$BIN" ${BASELINE:+"$BASELINE"}; do
        for jobs in 1 2; do
            times[$bin,$jobs]+="$(one "$bin" "$jobs" "$tag") "
        done
        tag=$((tag + 1))
    done
done
for bin in "$BIN" ${BASELINE:+"$BASELINE"}; do
    # shellcheck disable=SC2086
    m1=$(median ${times[$bin,1]})
    # shellcheck disable=SC2086
    m2=$(median ${times[$bin,2]})
    echo "$bin: --jobs 1: ${times[$bin,1]}(median $m1 s); --jobs 2: ${times[$bin,2]}(median $m2 s); ratio $(awk "BEGIN {printf \"%.3f\", $m2 / $m1}")"
done
first=""
for f in "$OUT"/numbers_*.json; do
    if [ -z "$first" ]; then first=$f; elif ! cmp -s "$first" "$f"; then
        echo "the numbers differ: $first against $f" >&2
        exit 1
    fi
done
echo "the numbers are the same in every run"
