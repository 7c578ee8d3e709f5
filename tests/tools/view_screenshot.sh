#!/usr/bin/env bash
# A screenshot of the Rerun web viewer showing a recording, headless: how the 3-D view was
# looked at on a machine without a display (docs/orchestrator.md, "3-D view").
#
#     bash tests/tools/view_screenshot.sh RECORDING.rrd OUT.png
#
# Needs the view extra (rerun) and Chromium (Debian: apt-get install chromium).  Chromium
# renders the viewer's WebGL with SwiftShader; the recording streams from a local gRPC server
# into the page, so the screenshot waits 40 s of virtual time (shorter waits catch the page
# still loading).
set -euo pipefail
[ $# -eq 2 ] || { echo "usage: $0 RECORDING.rrd OUT.png" >&2; exit 2; }
rrd=$1
out=$2
rerun --serve-web --web-viewer-port 9090 --port 9877 "$rrd" >/dev/null 2>&1 &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
sleep 5
chromium --headless=new --no-sandbox --use-angle=swiftshader --enable-unsafe-swiftshader \
    --window-size=1600,1000 --virtual-time-budget=40000 --screenshot="$out" \
    "http://127.0.0.1:9090/?url=rerun%2Bhttp%3A%2F%2Flocalhost%3A9877%2Fproxy&renderer=webgl" \
    >/dev/null 2>&1
echo "$out"
