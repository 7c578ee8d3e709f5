#!/usr/bin/env bash
# OpenModelica's OMSimulator, the importer tests/test_orchestrator/test_omsimulator.py plays the
# exported SSP with (its command line, its C API and its Python API).  Its PyPI package
# downloads a prebuilt binary while it installs, which fails without internet access, so the
# tests use a build from its public sources: the workplace's shared/omsimulator (bin/OMSimulator,
# lib/x86_64-linux-gnu/libOMSimulator.so and the Python API beside it).
#
# Prints the folder holding bin/OMSimulator and exits 0, or says on stderr why there is none
# and exits 1 (the tests then skip and say so).  Location: FULLPOSE_OMSIMULATOR, else the
# workplace beside the repository (its parent folder; for a clone of a local checkout, as CI
# makes, also the parent of that checkout).
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
roots=("$repo/..")
origin=$(git -C "$repo" remote get-url origin 2>/dev/null || true)
if [ -n "$origin" ] && [ -d "$origin" ]; then roots+=("$origin/.."); fi

have() { [ -x "$1/bin/OMSimulator" ] && [ -f "$1/lib/x86_64-linux-gnu/libOMSimulator.so" ]; }
if [ -n "${FULLPOSE_OMSIMULATOR:-}" ]; then
    if have "$FULLPOSE_OMSIMULATOR"; then (cd "$FULLPOSE_OMSIMULATOR" && pwd); exit 0; fi
    echo "FULLPOSE_OMSIMULATOR=$FULLPOSE_OMSIMULATOR holds no bin/OMSimulator and libOMSimulator.so" >&2
    exit 1
fi
for root in "${roots[@]}"; do
    if have "$root/shared/omsimulator"; then (cd "$root/shared/omsimulator" && pwd); exit 0; fi
done
echo "no OMSimulator build: set FULLPOSE_OMSIMULATOR to a folder with bin/OMSimulator and" \
     "lib/x86_64-linux-gnu/libOMSimulator.so (a build from its sources; its PyPI package needs" \
     "internet access while it installs)" >&2
exit 1
