#!/usr/bin/env bash
# The FMU tests and a fuzz batch against an AddressSanitizer + UndefinedBehaviorSanitizer
# build of fmu_src/ (gcc or clang).  Fails on any sanitizer report (and on a failing test).
#
#   tests/tools/sanitizer_run.sh [BUILD_DIR]      (default: a temporary folder, removed)
#   FUZZ_CALLS=2000 to change the fuzz batch (calls per FMU; 0: none)
#
# The build is -O1 -g with -fsanitize=address,undefined -fno-omit-frame-pointer, warnings
# not errors (FULLPOSE_WERROR off: -O1 with the sanitizers gives warnings the normal build
# does not; they are counted and printed).  Python loads the instrumented FMUs and host
# libraries through FULLPOSE_BUILD_DIR, with the compiler's libasan and libubsan preloaded.
set -euo pipefail
cd "$(dirname "$0")/../.."
start=$SECONDS
cc=${CC:-gcc}
build=${1:-}
if [[ -z "$build" ]]; then
  build=$(mktemp -d "${TMPDIR:-/tmp}/fullpose-sanitize-XXXXXX")
  trap 'rm -rf "$build"' EXIT
fi
reports="$build/sanitizer-reports"
rm -rf "$reports" && mkdir -p "$reports"
flags="-fsanitize=address,undefined -fno-omit-frame-pointer -O1 -g"

echo "sanitizer build in $build ($cc: $flags)"
# build type "Sanitize" has no flags of its own, so -O1 is not overridden by Release's -O3
env -u FULLPOSE_WERROR cmake -S fmu_src -B "$build" -DCMAKE_C_COMPILER="$cc" \
  -DCMAKE_BUILD_TYPE=Sanitize -DFULLPOSE_WERROR=OFF -DCMAKE_C_FLAGS="$flags" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
  -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
  -DPython_EXECUTABLE="$(command -v python)" >"$build/configure.log"
ASAN_OPTIONS=detect_leaks=0 cmake --build "$build" -j1 >"$build/build.log" 2>&1 || {
  cat "$build/build.log" >&2; echo "sanitizer build failed" >&2; exit 1; }
n_warn=$(grep -c 'warning:' "$build/build.log" || true)
echo "build: $n_warn compiler warnings under $flags"
grep 'warning:' "$build/build.log" | sort -u | sed 's/^/  /' || true

asan=$("$cc" -print-file-name=libasan.so)
ubsan=$("$cc" -print-file-name=libubsan.so)
export FULLPOSE_BUILD_DIR="$build"
export LD_PRELOAD="$asan $ubsan"
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:log_path=$reports/asan"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:log_path=$reports/ubsan"
export MPLBACKEND=Agg

status=0
echo "+ pytest (FMU tests on the sanitizer build)"
python -m pytest -q -p no:cacheprovider tests/test_plant/test_plant_fmu.py tests/test_controller/test_controller_fmu.py \
  tests/test_controller/test_wls_piqp.py tests/test_fmus/test_closed_loop.py tests/test_fmus/test_host_api.py \
  tests/test_fmus/test_state_format.py tests/test_fmus/test_fmi_discipline.py tests/test_fmus/test_robustness.py \
  tests/test_fmus/test_fmi3.py || status=1
# the ScenarioSignals FMU's table reader on good and broken tables, and one replay through it
python -m pytest -q -p no:cacheprovider tests/test_orchestrator/test_ssp_scenario.py \
  -k "player or bad_table or fmpy_replays or validates" || status=1
fuzz_calls=${FUZZ_CALLS:-2000}
if [[ "$fuzz_calls" != 0 ]]; then
  echo "+ fuzz batch ($fuzz_calls calls per FMU: its findings and any sanitizer report fail)"
  python tests/helpers/fuzz_fmi.py --calls "$fuzz_calls" --seed 11 --fmu both --hang-timeout 20 \
    --max-lines 15 || status=1
fi
unset LD_PRELOAD

shopt -s nullglob
found=("$reports"/*)
if (( ${#found[@]} )); then
  echo "SANITIZER REPORTS: ${#found[@]}" >&2
  for f in "${found[@]}"; do
    echo "--- $f" >&2
    head -40 "$f" >&2
  done
  status=1
else
  echo "no sanitizer reports"
fi
echo "sanitizer run: $((SECONDS - start)) s, status $status"
exit $status
