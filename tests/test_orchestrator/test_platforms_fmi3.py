"""The FMI 3.0 FMUs of every platform (``fullpose build-fmus --fmi 3``): binaries under the FMI
3.0 platform tuples, each exporting exactly the functions ``fmi3Functions.h`` declares, and
the cross-built x86_64 Linux pair flying a shipped scenario as the FMI 2.0 host build does,
to the bit.

Oracles: fmpy's validator, LLVM's object tools (Debian's llvm), the FMI 3.0 header's list
of functions, the FMI 2.0 run of the same scenario.  Marked ``platforms`` with the FMI 2.0
platform tests (tests/test_orchestrator/test_platforms.py).
"""

import re
import shutil
import zipfile
from dataclasses import replace
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu

from orchestrator.export.platforms import PLATFORMS
from orchestrator.master import run
from orchestrator.runner import prepare

pytest.importorskip("ziglang", reason="the Zig cross compiler (pip install -e '.[test]')")
pytestmark = pytest.mark.platforms

MODELS = ("MultirotorPlant", "FullPoseController", "ScenarioSignals")
INSTALL = "tests/tools/install_platform_tools.sh"
MACHO_HEADER_SYMBOLS = {"_mh_dylib_header", "__dso_handle"}


def fmi3_functions() -> set[str]:
    """Every function fmi3Functions.h declares (FMI3_Export ...TYPE name;)."""
    text = (Path(fmpy.__file__).parent / "c-code" / "fmi3Functions.h").read_text()
    return set(re.findall(r"FMI3_Export\s+\w+TYPE\s+(\w+);", text))


FMI3 = fmi3_functions()


def llvm(tool):
    versioned = sorted(Path("/usr/lib").glob(f"llvm-*/bin/{tool}"),
                       key=lambda p: int(re.sub(r"\D", "", p.parts[3]) or 0))
    path = shutil.which(tool) or (str(versioned[-1]) if versioned else None)
    if path is None:
        pytest.skip(f"{tool} (Debian's llvm) is missing: run {INSTALL}")
    return path


def out(cmd):
    import subprocess

    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert res.returncode == 0, f"{' '.join(map(str, cmd))}: {res.stderr or res.stdout}"
    return res.stdout


@pytest.fixture(scope="module")
def dist3(tmp_path_factory):
    """The three FMI 3.0 FMUs built for every platform, in ``<folder>/fmi3/``."""
    from orchestrator.export.fmu_build import build_fmus

    folder = tmp_path_factory.mktemp("dist3")
    build_fmus(PLATFORMS, folder / "fmi3", fmi=3)
    return folder


@pytest.fixture(scope="module")
def unzipped(dist3, tmp_path_factory):
    dirs = {}
    for model in MODELS:
        dirs[model] = tmp_path_factory.mktemp(model)
        with zipfile.ZipFile(dist3 / "fmi3" / f"{model}.fmu") as z:
            z.extractall(dirs[model])
    return dirs


def test_fmi3_tuples_and_nothing_else(dist3, unzipped):
    assert len(FMI3) > 70
    for model in MODELS:
        assert validate_fmu(str(dist3 / "fmi3" / f"{model}.fmu")) == []
        found = sorted(p.relative_to(unzipped[model] / "binaries").as_posix()
                       for p in (unzipped[model] / "binaries").rglob("*") if p.is_file())
        assert found == sorted(f"{p.name}/{model}{p.suffix}" for p in PLATFORMS)


def test_every_binary_exports_exactly_the_fmi3_api(unzipped):
    nm, objdump, lipo = llvm("llvm-nm"), llvm("llvm-objdump"), llvm("llvm-lipo")
    for model in MODELS:
        root = unzipped[model] / "binaries"
        for tuple_ in ("x86_64-linux", "aarch64-linux"):
            lib = root / tuple_ / f"{model}.so"
            exported = set(out([nm, "--dynamic", "--defined-only", "--format=just-symbols",
                                lib]).split())
            assert exported == FMI3, f"{model} {tuple_}: {sorted(exported ^ FMI3)[:5]}"
        text = out([objdump, "--private-headers", root / "x86_64-windows" / f"{model}.dll"])
        table = text[text.index("Export Table:"):]
        exported = set(re.findall(r"^\s+\d+\s+0x[0-9a-f]+\s+(\w+)$", table, re.M))
        assert exported == FMI3, f"{model} windows: {sorted(exported ^ FMI3)[:5]}"
        for tuple_, arch in (("x86_64-darwin", "x86_64"), ("aarch64-darwin", "arm64")):
            lib = root / tuple_ / f"{model}.dylib"
            assert out([lipo, "-archs", lib]).split() == [arch]  # thin, as FMI 3.0 names it
            trie = out([objdump, "--macho", "--exports-trie", f"--arch={arch}", lib])
            exported = {n[1:] for n in re.findall(r"^0x[0-9A-F]+\s+(\S+)$", trie, re.M)}
            assert exported - MACHO_HEADER_SYMBOLS == FMI3, f"{model} {tuple_}"


@pytest.mark.skipif(fmpy.platform != "linux64", reason="the shipped binaries are x86_64 Linux")
def test_cross_built_fmi3_flies_the_fmi2_run_to_the_bit(dist3, monkeypatch):
    """The Zig-built FMI 3.0 pair against the host's FMI 2.0 build: the first 3 s of a shipped
    scenario, every signal, to the bit."""
    monkeypatch.delenv("FULLPOSE_BUILD_DIR", raising=False)
    shipped = run(prepare("full_pose_with_disturbances", 3.0), progress=False)
    monkeypatch.setenv("FULLPOSE_BUILD_DIR", str(dist3))
    cross = run(replace(prepare("full_pose_with_disturbances", 3.0), fmi=3), progress=False)
    assert cross.meta["fmi"] == 3
    assert cross.columns == shipped.columns
    a, b = shipped.data, cross.data
    assert a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))
