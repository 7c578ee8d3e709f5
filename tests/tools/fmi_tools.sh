#!/usr/bin/env bash
# The two native FMI tools the tests check our FMUs with (tests/test_fmi_tools.py): the
# Modelica FMU Compliance Checker and fmusim.  Neither is on a package registry; they are
# built offline from snapshots of their public repositories by the workplace's
# build_fmi_tools.sh (about 10 minutes on 2 cores, once: later runs reuse the folder).
#
# Prints the folder holding bin/fmuCheck.linux64 and bin/fmusim and exits 0, or says on
# stderr why there is none and exits 1 (the tests then skip and say so).
#   FULLPOSE_FMI_TOOLS      the folder (default: the workplace's prebuilt tools,
#                           /work/shared/fmi-tools, when present; else /opt/fmi-tools)
#   FMI_TOOLS_BUILD_SCRIPT  the build script (default /work/shared/tools/build_fmi_tools.sh)
#   MIRROR_ROOT             the repository snapshots it builds from (default /work/.mirror)
set -euo pipefail
have() { [ -x "$dest/bin/fmuCheck.linux64" ] && [ -x "$dest/bin/fmusim" ]; }
if [ -z "${FULLPOSE_FMI_TOOLS:-}" ]; then  # prebuilt for this machine kind: no 10-minute build
    dest=/work/shared/fmi-tools
    if have; then echo "$dest"; exit 0; fi
fi
dest=${FULLPOSE_FMI_TOOLS:-/opt/fmi-tools}
if have; then echo "$dest"; exit 0; fi
script=${FMI_TOOLS_BUILD_SCRIPT:-/work/shared/tools/build_fmi_tools.sh}
export MIRROR_ROOT=${MIRROR_ROOT:-/work/.mirror}
if [ ! -f "$script" ] || [ ! -d "$MIRROR_ROOT" ]; then
    echo "fmi tools: no $dest/bin/{fmuCheck.linux64,fmusim} and nothing to build them from" \
         "($script, $MIRROR_ROOT)" >&2
    exit 1
fi
mkdir -p "$dest"
log="$dest/build.log"
echo "fmi tools: building into $dest (log: $log)" >&2
if ! bash "$script" "$dest" >"$log" 2>&1 || ! have; then
    tail -30 "$log" >&2
    echo "fmi tools: build failed" >&2
    exit 1
fi
echo "$dest"
