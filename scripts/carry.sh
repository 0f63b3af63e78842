#!/usr/bin/env bash
# Carries scripts/ranks.sh to a machine that has neither PETSc nor MPI (a rented 16-core node,
# say): packs the PETSc build, the shared libraries it and Open MPI's launcher load (ldd),
# Open MPI's launcher with its components and help texts, GNU time, the plate's mesh and the
# files ranks.sh reads into one archive (~50 MB, xz). On the other machine:
#   tar xJf viscontact-carried.tar.xz && cd viscontact-carried && . ./env.sh
#   KIND=contact scripts/ranks.sh 0.015 20 16 2 8 4     # the 16-core table of docs/cluster.md
# The other machine needs a glibc at least as new as this one's (glibc is not carried: its
# loader must match it), python3 for ranks.sh's table, and nothing else. env.sh points Open MPI
# at the carried copy (OPAL_PREFIX), starts the ranks without ssh (plm=isolated: one machine),
# over shared memory (btl self,vader, without the kernel's single-copy, which containers
# forbid), allows root and more ranks than cores.
#   BIN=target/release/viscontact scripts/carry.sh [SIZE [OUT.tar.xz]]   (default 0.015)
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-0.015}
archive=$(realpath -m "${2:-viscontact-carried.tar.xz}")
bin=$(realpath "${BIN:-target/release/viscontact}")
mesh=out/meshes/plate_$size.msh
[ -f "$mesh" ] || { echo "no $mesh: make it with scripts/ranks.sh $size 1 0 first" >&2; exit 2; }
mpi=/usr/lib/x86_64-linux-gnu/openmpi
pmix=/usr/lib/x86_64-linux-gnu/pmix2/lib/pmix
orterun=$(readlink -f "$(command -v mpirun)")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
top=$work/viscontact-carried
mkdir -p "$top"/{bin,lib,usr/bin,scripts,examples,out/meshes}

install -m 755 "$bin" "$top/bin/viscontact"
strip "$top/bin/viscontact"
cp "$orterun" "$top/usr/bin/orterun"
cp /usr/bin/orted /usr/bin/time "$top/usr/bin/"
# Open MPI finds its components and help texts under OPAL_PREFIX, at the paths of its build.
for dir in "$mpi/lib/openmpi3" "$pmix" /usr/share/openmpi; do
    mkdir -p "$top$(dirname "$dir")"
    cp -r "$dir" "$top$dir"
done
# Every shared library that the programs and the components load, but glibc's own.
loaded=("$bin" "$orterun" /usr/bin/orted "$mpi"/lib/openmpi3/*.so "$pmix"/*.so)
ldd "${loaded[@]}" 2>/dev/null | awk '/=> \// {print $3}' | sort -u |
    grep -Ev '/(ld-linux[^/]*|libc|libm|libdl|libpthread|librt|libresolv|libutil)\.so' |
    while read -r lib; do cp -L "$lib" "$top/lib/"; done

cp scripts/ranks.sh "$top/scripts/"
cp examples/block.toml "$top/examples/"
cp "$mesh" "$top/out/meshes/"
cat >"$top/env.sh" <<'SH'
# Sourced: the carried build and Open MPI for scripts/ranks.sh (scripts/carry.sh).
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
export LD_LIBRARY_PATH=$here/lib OPAL_PREFIX=$here/usr
export PMIX_MCA_mca_base_component_path=$here/usr/lib/x86_64-linux-gnu/pmix2/lib/pmix
export OMPI_MCA_plm=isolated OMPI_MCA_pml=ob1 OMPI_MCA_btl=self,vader
export OMPI_MCA_btl_vader_single_copy_mechanism=none OMPI_MCA_rmaps_base_oversubscribe=1
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 HWLOC_HIDE_ERRORS=1
export BIN=$here/bin/viscontact MPIRUN=$here/usr/bin/orterun TIME_BIN=$here/usr/bin/time
"$BIN" --version
SH
tar -C "$work" -cJf "$archive" viscontact-carried
ls -l "$archive"
