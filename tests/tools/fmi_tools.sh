#!/usr/bin/env bash
# The two native FMI tools the tests check our FMUs with (tests/test_fmus/test_fmi_tools.py): the
# Modelica FMU Compliance Checker and fmusim.  Neither is on a package registry; they are
# built offline from snapshots of their public repositories by the workplace's
# build_fmi_tools.sh (about 10 minutes on 2 cores, once: later runs reuse the folder).
#
# Prints the folder holding bin/fmuCheck.linux64 and bin/fmusim and exits 0, or says on
# stderr why there is none and exits 1 (the tests then skip and say so).  Locations come
# from the environment, else from the workplace beside the repository (its parent folder;
# for a clone of a local checkout, as CI makes, also the parent of that checkout):
#   FULLPOSE_FMI_TOOLS      the folder; default: the workplace's prebuilt shared/fmi-tools,
#                           else a build into the user cache (fullpose/fmi-tools)
#   FMI_TOOLS_BUILD_SCRIPT  the build script (default: the workplace's
#                           shared/tools/build_fmi_tools.sh)
#   MIRROR_ROOT             the repository snapshots it builds from (default: the
#                           workplace's .mirror)
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
roots=("$repo/..")
origin=$(git -C "$repo" remote get-url origin 2>/dev/null || true)
if [ -n "$origin" ] && [ -d "$origin" ]; then roots+=("$origin/.."); fi

have() { [ -x "$1/bin/fmuCheck.linux64" ] && [ -x "$1/bin/fmusim" ]; }
if [ -n "${FULLPOSE_FMI_TOOLS:-}" ]; then
    dest=$FULLPOSE_FMI_TOOLS
else
    for root in "${roots[@]}"; do  # prebuilt for this machine kind: no 10-minute build
        if have "$root/shared/fmi-tools"; then (cd "$root/shared/fmi-tools" && pwd); exit 0; fi
    done
    dest=${XDG_CACHE_HOME:-$HOME/.cache}/fullpose/fmi-tools
fi
if have "$dest"; then echo "$dest"; exit 0; fi
script=${FMI_TOOLS_BUILD_SCRIPT:-}
mirror=${MIRROR_ROOT:-}
for root in "${roots[@]}"; do
    if [ -z "$script" ] && [ -f "$root/shared/tools/build_fmi_tools.sh" ]; then
        script=$root/shared/tools/build_fmi_tools.sh
    fi
    if [ -z "$mirror" ] && [ -d "$root/.mirror" ]; then mirror=$root/.mirror; fi
done
if [ -z "$script" ] || [ -z "$mirror" ]; then
    echo "fmi tools: no $dest/bin/{fmuCheck.linux64,fmusim} and nothing to build them from" \
         "(set FMI_TOOLS_BUILD_SCRIPT and MIRROR_ROOT, or FULLPOSE_FMI_TOOLS)" >&2
    exit 1
fi
export MIRROR_ROOT=$mirror
mkdir -p "$dest"
log="$dest/build.log"
echo "fmi tools: building into $dest (log: $log)" >&2
if ! bash "$script" "$dest" >"$log" 2>&1 || ! have "$dest"; then
    tail -30 "$log" >&2
    echo "fmi tools: build failed" >&2
    exit 1
fi
echo "$dest"
