#!/usr/bin/env bash
# The README's quick start, run verbatim, as a newcomer on a fresh Debian/Ubuntu machine
# would: the indented command lines of README.md's "Quick start" section, which must be
# three, in this order: the install line, the paper example, the test command.
#
#   scripts/readme_quickstart.sh [install] [example] [test]    (no argument: all three)
#
# Each line runs as README.md writes it (through bash -c), with one exception: as root
# where `sudo` is not installed (a bare container, like CI's), its `sudo ` words are removed.
# A line whose comment names a file (`# → out/paper/solution.pvd`) must have written it.
# Nothing else is installed or updated here: a README line that fails on a fresh machine
# fails this script. `.ci/run` runs it.
set -euo pipefail
cd "$(dirname "$0")/.."

mapfile -t LINES < <(awk '/^## / { inside = ($0 == "## Quick start") }
    inside && /^    [^ ]/ { sub(/^    /, ""); print }' README.md)
ROLES=(install example test)
PATTERNS=("apt-get install" "cargo run" "cargo test")
if [ ${#LINES[@]} -ne 3 ]; then
    echo "README.md's Quick start has ${#LINES[@]} indented command lines, not 3" \
        "(install, example, test): update $0 with it" >&2
    exit 1
fi
for i in 0 1 2; do
    if [[ ${LINES[i]} != *"${PATTERNS[i]}"* ]]; then
        echo "README.md's Quick start line $((i + 1)) should be the ${ROLES[i]} line" \
            "(with '${PATTERNS[i]}'), but is: ${LINES[i]}" >&2
        exit 1
    fi
done

# Runs one README line and checks the file its comment promises.
run_line() {
    local line=$1 promised marker
    if [ "$(id -u)" = 0 ] && ! command -v sudo >/dev/null; then
        line=${line//sudo /}
    fi
    promised=$(sed -n 's/.*# → *\([^ ]*\).*/\1/p' <<<"$line")
    marker=$(mktemp)
    echo "+ $line" >&2
    DEBIAN_FRONTEND=noninteractive bash -c "$line"
    if [ -n "$promised" ] && [ ! "$promised" -nt "$marker" ]; then
        echo "README.md promises $promised, but the line did not write it: $line" >&2
        rm -f "$marker"
        exit 1
    fi
    rm -f "$marker"
}

[ $# -gt 0 ] || set -- "${ROLES[@]}"
for role in "$@"; do
    case $role in
    install) run_line "${LINES[0]}" ;;
    example) run_line "${LINES[1]}" ;;
    test) run_line "${LINES[2]}" ;;
    *)
        echo "unknown step '$role': choose from ${ROLES[*]}" >&2
        exit 2
        ;;
    esac
done
