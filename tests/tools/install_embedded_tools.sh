#!/usr/bin/env bash
# Installs what the controller's embedded build and its processor-in-the-loop runs need
# (tests/test_embedded/, fullpose build-embedded, fullpose run --pil): the GNU Arm Embedded
# toolchain with newlib, and QEMU's Arm system emulator (the Cortex-M7 board mps2-an500).
# Debian 12 packages; idempotent (nothing is downloaded when all are present); quiet.
set -euo pipefail

packages=(gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install_embedded_tools: all present (${packages[*]})"
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install_embedded_tools: installed ${missing[*]}"
