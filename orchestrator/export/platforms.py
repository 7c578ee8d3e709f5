"""The platforms ``fullpose build-fmus`` builds FMU binaries for, and the Zig cross compiler
that builds them (``ziglang`` on PyPI: ``pip install "fullpose[platforms]"``).

Folder names (FMI 2.0.4, section 2.3: ``win64``, ``linux64`` and ``darwin64`` mean 64-bit
x86; "for any other platforms the platform tuples of FMI 3.0 should be used"):

* ``x86_64-linux`` -> ``binaries/linux64``, glibc 2.17 or newer;
* ``aarch64-linux`` -> ``binaries/aarch64-linux`` (FMI 3.0 tuple), glibc 2.17 or newer;
* ``x86_64-windows`` -> ``binaries/win64`` (the Universal C Runtime of Windows 10 and later);
* ``x86_64-darwin`` -> ``binaries/darwin64``, a universal Mach-O with an x86_64 and an arm64
  slice: importers that know only the FMI 2 names (fmpy, for one, loads ``darwin64`` on
  every Mac) find a binary that runs natively on Intel and on Apple silicon, and x86_64
  importers find the x86_64 slice they expect (macOS 10.15 or newer);
* ``aarch64-darwin`` -> ``binaries/aarch64-darwin`` (FMI 3.0 tuple), the arm64 slice alone
  (macOS 11 or newer), for importers that follow FMI 2.0.4 literally.

One Zig target is compiled once however many platforms use it (the arm64 Mach-O serves both
darwin folders).
"""

from __future__ import annotations

import importlib.util
import os
import platform as _host
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

from orchestrator.export.macho import universal_binary

# Every compiler warning flag of the project's own build (fmu_src/CMakeLists.txt).
WARNINGS = ("-Wall", "-Wextra", "-Wpedantic", "-Wmissing-prototypes", "-Wstrict-prototypes")
# Flags of every binary: the FMI functions are the only exports (fmi2Functions.h marks them),
# no debug information, and no fused multiply-add (clang contracts a*b+c by default on
# aarch64, which would change the arithmetic from one platform to another).
FLAGS = ("-std=c99", "-O2", "-shared", "-fPIC", "-fvisibility=hidden", "-ffp-contract=off",
         "-s")


class PlatformBuildError(RuntimeError):
    """A platform cannot be built: unknown name, no compiler, or a failed compile."""


@dataclass(frozen=True)
class Target:
    """One Zig compile: ``zig cc -target TRIPLE``; ``macho_arch`` names a Mach-O slice."""

    triple: str
    suffix: str
    libs: tuple[str, ...] = ()
    macho_arch: str = ""


@dataclass(frozen=True)
class Platform:
    """A platform of the FMU: its FMI 2 ``binaries/`` folder and the compiles behind it (two:
    a universal Mach-O of both slices)."""

    name: str
    folder: str
    targets: tuple[Target, ...]
    aliases: tuple[str, ...] = ()

    @property
    def suffix(self) -> str:
        """The binary's file suffix (.so, .dll, .dylib)."""
        return self.targets[0].suffix


LINUX_X86_64 = Target("x86_64-linux-gnu.2.17", ".so", ("-lm",))
LINUX_AARCH64 = Target("aarch64-linux-gnu.2.17", ".so", ("-lm",))
WINDOWS_X86_64 = Target("x86_64-windows-gnu", ".dll")
MACOS_X86_64 = Target("x86_64-macos.10.15", ".dylib", macho_arch="x86_64")
MACOS_ARM64 = Target("aarch64-macos.11.0", ".dylib", macho_arch="arm64")

PLATFORMS: tuple[Platform, ...] = (
    Platform("x86_64-linux", "linux64", (LINUX_X86_64,), ("linux64",)),
    Platform("aarch64-linux", "aarch64-linux", (LINUX_AARCH64,)),
    Platform("x86_64-windows", "win64", (WINDOWS_X86_64,), ("win64",)),
    Platform("x86_64-darwin", "darwin64", (MACOS_X86_64, MACOS_ARM64), ("darwin64",)),
    Platform("aarch64-darwin", "aarch64-darwin", (MACOS_ARM64,)),
)


def host_platform() -> Platform:
    """The platform of this machine."""
    machine = _host.machine().lower()
    arch = "aarch64" if machine in ("aarch64", "arm64") else "x86_64"
    system = {"win32": "windows", "darwin": "darwin"}.get(sys.platform, "linux")
    return platform_named(f"{arch}-{system}")


def platform_named(name: str) -> Platform:
    """The platform called name (or an alias), or PlatformBuildError naming the known ones."""
    for p in PLATFORMS:
        if name in (p.name, *p.aliases):
            return p
    known = ", ".join(p.name for p in PLATFORMS)
    raise PlatformBuildError(f"unknown platform {name!r} (known: {known}, all, host)")


def parse_platforms(spec: str) -> list[Platform]:
    """``all``, ``host`` or a comma list of platform names (FMI 3 tuples or FMI 2 folders),
    in the order of :data:`PLATFORMS`, each once."""
    names = [s.strip() for s in spec.split(",") if s.strip()]
    if not names:
        raise PlatformBuildError("--platforms is empty: give all, host or a comma list")
    chosen: set[str] = set()
    for name in names:
        if name == "all":
            chosen |= {p.name for p in PLATFORMS}
        elif name == "host":
            chosen.add(host_platform().name)
        else:
            chosen.add(platform_named(name).name)
    return [p for p in PLATFORMS if p.name in chosen]


def zig_command() -> list[str]:
    """The command that runs Zig's C compiler (``python -m ziglang``), or a clear error."""
    if importlib.util.find_spec("ziglang") is None:
        raise PlatformBuildError(
            "the Zig cross compiler is not installed: pip install 'fullpose[platforms]' "
            "(or pip install ziglang)")
    return [sys.executable, "-m", "ziglang"]


def werror() -> bool:
    """Warnings are errors as in the CMake build: FULLPOSE_WERROR set and not 0."""
    return os.environ.get("FULLPOSE_WERROR", "") not in ("", "0")


def source_files(sources: Path) -> list[Path]:
    """The C files an FMU's ``sources`` folder is compiled from: those its
    ``buildDescription.xml`` lists (our FMUs': one, ``<model>_all.c``, which includes the
    others), else every C file in it."""
    described = sources / "buildDescription.xml"
    if described.is_file():
        root = ElementTree.parse(described).getroot()
        names = [f.get("name", "") for f in root.iter("SourceFile")]
        if names:
            return [sources / n for n in names]
    return sorted(sources.glob("*.c"))


def compile_target(target: Target, sources: Path, out: Path, label: str) -> None:
    """The C files of ``sources`` (:func:`source_files`) into the shared library ``out``, for
    ``target``, with ``-I sources`` as the only include path."""
    files = [str(p) for p in source_files(sources)]
    if not files:
        raise PlatformBuildError(f"{label}: no C sources in {sources}")
    # a Mach-O names itself (its install name): not after the temporary path it is built at
    name = (f"-Wl,-install_name,@rpath/{out.name}",) if target.macho_arch else ()
    cmd = [*zig_command(), "cc", "-target", target.triple, *FLAGS, *WARNINGS,
           *(("-Werror",) if werror() else ()), "-I", str(sources), *files, *target.libs,
           *name, "-o", str(out)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode != 0 or not out.is_file():
        tail = "\n".join((res.stderr or res.stdout).strip().splitlines()[-15:])
        raise PlatformBuildError(f"{label}: zig cc -target {target.triple} failed:\n{tail}")


def binary_folder(platform: Platform, fmi: int = 2) -> str:
    """The ``binaries/`` folder of ``platform`` in an FMU of FMI version ``fmi``: FMI 2.0's
    (``linux64``, ``win64``, ``darwin64``, else the FMI 3.0 tuple), FMI 3.0's tuple."""
    return platform.folder if fmi == 2 else platform.name


def build_platform(platform: Platform, sources: Path, binaries: Path, work: Path, model: str,
                   built: dict[str, Path], fmi: int = 2) -> tuple[Path, float]:
    """The binary of ``model`` for ``platform``, ``binaries/<folder>/<model><suffix>``
    (:func:`binary_folder`), from ``sources``; each target compiled into ``work`` unless already
    in ``built`` (triple -> library, updated); returns the binary and the seconds spent.  In
    FMI 3.0, ``x86_64-darwin`` holds the x86_64 slice alone (``aarch64-darwin`` the arm64
    one), not FMI 2.0's universal ``darwin64`` file."""
    start = time.perf_counter()
    slices = []
    targets = platform.targets if fmi == 2 else platform.targets[:1]
    for target in targets:
        if target.triple not in built:
            lib = work / target.triple / f"{model}{target.suffix}"
            lib.parent.mkdir(parents=True, exist_ok=True)
            compile_target(target, sources, lib, f"{model} for {platform.name}")
            built[target.triple] = lib
        slices.append(built[target.triple])
    out = binaries / binary_folder(platform, fmi) / f"{model}{platform.suffix}"
    out.parent.mkdir(parents=True, exist_ok=True)
    if len(slices) == 1:
        shutil.copyfile(slices[0], out)
    else:
        out.write_bytes(universal_binary([p.read_bytes() for p in slices]))
    return out, time.perf_counter() - start

