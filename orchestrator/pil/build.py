"""The embedded build of the controller (``fullpose build-embedded``): libfpc.a and the
processor-in-the-loop image fpc_pil.elf, cross-compiled with the GNU Arm Embedded toolchain
from the CMake project fmu_src/embedded (installed with the package as controller/embedded,
with the model sources it compiles: the FMU's).

    built = build_embedded(Path("build/m7"))
    print(built.elf, built.memory.flash, built.memory.ram)
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from orchestrator.pil.target import check_image
from plant.common.artifacts import NativeBuildMissing, find_artifact

TOOLS = ("arm-none-eabi-gcc", "arm-none-eabi-size", "cmake")
"""What the cross build runs (Debian: gcc-arm-none-eabi, libnewlib-arm-none-eabi, cmake)."""


class EmbeddedBuildError(RuntimeError):
    """The cross build cannot run or failed; the message says why."""


@dataclass(frozen=True)
class Memory:
    """An image's memory, from ``arm-none-eabi-size -A`` (bytes): flash = code, constants and
    the initial data; ram = data and bss (the controller, the image's buffers, the C library's
    heap pool); stack = the stack region reserved."""

    flash: int
    ram: int
    stack: int


@dataclass(frozen=True)
class EmbeddedBuild:
    """The products of a cross build and their sizes."""

    folder: Path
    library: Path
    elf: Path
    trace_elf: Path  # the same image recording its libm calls (fpc_pil_trace.elf)
    memory: Memory
    library_flash: int  # code and constants of libfpc.a's objects (size -t)
    library_ram: int  # data and bss of libfpc.a's objects (0: nothing static)


def project_dir() -> Path:
    """The CMake project: the checkout's fmu_src/embedded when running from one, else the
    installed copy."""
    here = Path(__file__).resolve().parents[2] / "fmu_src" / "embedded"
    if (here / "CMakeLists.txt").is_file():
        return here
    try:
        return find_artifact("controller", "embedded/embedded", "CMakeLists.txt").parent
    except NativeBuildMissing as e:
        raise EmbeddedBuildError(f"the embedded project is not installed: {e}") from None


def missing_tools() -> list[str]:
    """The tools of :data:`TOOLS` not on PATH, plus qemu-system-arm for the PIL runs."""
    return [t for t in (*TOOLS, "qemu-system-arm") if shutil.which(t) is None]


def default_folder() -> Path:
    """Where ``fullpose build-embedded`` and ``fullpose run --pil`` build by default."""
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return cache / "fullpose" / "embedded-m7"


def _run(cmd: list[str], what: str) -> str:
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-15:])
        raise EmbeddedBuildError(f"{what} failed:\n{tail}")
    return done.stdout


def _sizes(elf: Path) -> Memory:
    table: dict[str, int] = {}
    for line in _run(["arm-none-eabi-size", "-A", str(elf)], "arm-none-eabi-size").splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0].startswith(".") and parts[1].isdigit():
            table[parts[0]] = int(parts[1])
    flash = table.get(".text", 0) + table.get(".ARM.exidx", 0) + table.get(".data", 0)
    return Memory(flash, table.get(".data", 0) + table.get(".bss", 0), table.get(".stack", 0))


def _library_sizes(lib: Path) -> tuple[int, int]:
    out = _run(["arm-none-eabi-size", "-t", str(lib)], "arm-none-eabi-size")
    total = out.strip().splitlines()[-1].split()  # text data bss dec hex (TOTALS)
    return int(total[0]), int(total[1]) + int(total[2])


def build_embedded(folder: Path | None = None, werror: bool = False) -> EmbeddedBuild:
    """Configure (once) and build the cross project into folder (default
    :func:`default_folder`); incremental, like any CMake build."""
    missing = [t for t in TOOLS if shutil.which(t) is None]
    if missing:
        raise EmbeddedBuildError(
            f"{', '.join(missing)} not found: install the GNU Arm Embedded toolchain and "
            "CMake (Debian: apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi cmake)")
    folder = Path(folder) if folder is not None else default_folder()
    src = project_dir()
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []
    if not (folder / "CMakeCache.txt").is_file():
        _run(["cmake", "-S", str(src), "-B", str(folder), *generator,
              f"--toolchain={src / 'arm-none-eabi.cmake'}",
              f"-DFULLPOSE_WERROR={'ON' if werror else 'OFF'}"], "configuring the cross build")
    _run(["cmake", "--build", str(folder)], "the cross build")
    elf, lib = folder / "fpc_pil.elf", folder / "libfpc.a"
    flash, ram = _library_sizes(lib)
    return EmbeddedBuild(folder, lib, elf, folder / "fpc_pil_trace.elf", _sizes(elf), flash, ram)


def image_of(option: str, say: bool = True) -> Path:
    """The controller image a ``--pil [IMAGE]`` option names: IMAGE itself, or for
    ``"build"`` (the option without a value) the image built (incrementally) into
    :func:`default_folder`.  ValueError for an image that does not exist."""
    if option != "build":
        if not Path(option).is_file():
            raise ValueError(f"--pil {option}: no such controller image (fpc_pil.elf, from "
                             "`fullpose build-embedded`)")
        check_image(Path(option))
        return Path(option)
    if say:
        print("building the controller image for the Cortex-M7 (fullpose build-embedded) ...",
              flush=True)
    return build_embedded().elf
