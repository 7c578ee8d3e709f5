#!/usr/bin/env bash
# Installs what the cross-platform FMU checks (tests/test_orchestrator/test_platforms.py) run the binaries on:
# Wine (win64 DLLs), qemu-user with the arm64 C library (aarch64-linux .so files) and LLVM's
# object-file tools (llvm-objdump, llvm-nm, llvm-readelf: ELF, PE and Mach-O alike), and
# clang, one of the compilers FMUs are rebuilt from their sources/ with
# (tests/test_fmus/test_source_builds.py).
# Debian 12 packages; idempotent (nothing is downloaded when all are present); quiet.
# The Zig cross compiler comes from PyPI instead: pip install -e ".[platforms]" (or [test]).
set -euo pipefail

packages=(wine wine64 qemu-user libc6-arm64-cross llvm clang)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install_platform_tools: all present (${packages[*]})"
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install_platform_tools: installed ${missing[*]}"
