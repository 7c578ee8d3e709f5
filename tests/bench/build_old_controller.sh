#!/usr/bin/env bash
# Build the FullPoseController FMU of another commit, for the old-against-new comparison of
# tests/bench/bench_controller.py (--old-fmu):
#
#     bash tests/bench/build_old_controller.sh COMMIT OUTDIR
#     python tests/bench/bench_controller.py --old-fmu OUTDIR/FullPoseController.fmu
#
# The commit's fmu_src/ is exported with `git archive` (the checkout and its worktrees are
# left alone) and built with CMake as the package build does (Release, warnings not errors:
# an old tree need not be clean under a newer compiler).  Needs git, cmake, a C compiler and
# a Python with fmpy (for the FMI headers), e.g. the project's virtual environment.
set -euo pipefail
if [ $# -ne 2 ]; then
  echo "usage: $0 COMMIT OUTDIR" >&2
  exit 2
fi
commit=$1
out=$2
repo=$(git -C "$(dirname "$0")" rev-parse --show-toplevel)
python=${PYTHON:-python3}
fmi_include=$("$python" -c 'import fmpy, os; print(os.path.join(os.path.dirname(fmpy.__file__), "c-code"))')
work=$(mktemp -d "${TMPDIR:-/tmp}/fullpose-old-XXXXXX")
trap 'rm -rf "$work"' EXIT
git -C "$repo" archive "$commit" fmu_src | tar -x -C "$work"
FULLPOSE_WERROR= cmake -S "$work/fmu_src" -B "$work/build" -DCMAKE_BUILD_TYPE=Release \
  -DFMI_INCLUDE_DIR="$fmi_include" -DFULLPOSE_WERROR=OFF >/dev/null
cmake --build "$work/build" --target FullPoseController_fmu -j 1 >/dev/null
mkdir -p "$out"
cp "$work/build/FullPoseController.fmu" "$out/"
echo "$out/FullPoseController.fmu ($(git -C "$repo" rev-parse --short "$commit"))"
