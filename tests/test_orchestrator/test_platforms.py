"""The FMUs of every platform (``fullpose build-fmus``): each binary well-formed, exporting
the FMI 2 co-simulation functions, and flying where this machine can run it.

* Linux (x86_64, aarch64): ELF shared objects needing no glibc symbol version newer than 2.17;
* Windows: PE DLLs exporting exactly the FMI functions, importing only system DLLs;
* macOS: Mach-O dylibs (``darwin64`` universal x86_64 + arm64, ``aarch64-darwin`` arm64) whose
  export tries hold the FMI functions; not run (no macOS here);
* flown: our C master (``fmu_src/tools/hover_master.c``, cross-compiled by Zig like the FMUs)
  loads both FMUs of a platform and flies 10 s back to hover; on win64 under Wine and on
  aarch64-linux under qemu-user the trajectory matches the native x86_64 run to 1e-9 m.

Oracles: LLVM's object tools (Debian's llvm, not the Zig that built the files), the FMI 2
header's list of functions, Wine, qemu-user, the native run.  The tools come from
``tests/tools/install_platform_tools.sh`` and ``pip install -e ".[test]"`` (ziglang); without
them these tests skip saying what is missing.  The whole module is marked ``platforms``
(``-m "not platforms"`` leaves it out): the build of all platforms takes about 35 s once
Zig's cache holds its C runtimes (about 3.5 min the first time on a machine), the Wine and
qemu runs about 15 s more.
"""

import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from orchestrator.export.platforms import PLATFORMS, platform_named
from orchestrator.master import run
from orchestrator.runner import prepare

pytest.importorskip("ziglang", reason="the Zig cross compiler (pip install -e '.[test]')")
pytestmark = pytest.mark.platforms

ROOT = Path(__file__).resolve().parents[2]
MASTER = ROOT / "fmu_src" / "tools" / "hover_master.c"
MODELS = ("MultirotorPlant", "FullPoseController")
INSTALL = "tests/tools/install_platform_tools.sh"
GLIBC_FLOOR = (2, 17)
STEP, STEPS, EVERY = 0.002, 5000, 50  # 10 s at 2 ms, printed every 0.1 s
POS0, EULER0 = (0.3, -0.2, -2.8), (0.05, -0.04, 0.1)  # off the hover reference
POS_REF = (0.0, 0.0, -3.0)
TOL = 1e-9  # m (and rad): an emulated platform's trajectory against the native one
# Linker-made symbols every dylib of Zig's linker exports (the image's Mach-O header); no code
MACHO_HEADER_SYMBOLS = {"_mh_dylib_header", "__dso_handle"}


def llvm(tool):
    """An LLVM tool: on PATH, or Debian's versioned copy (llvm-lipo is only llvm-lipo-14)."""
    versioned = sorted(Path("/usr/lib").glob(f"llvm-*/bin/{tool}"),
                       key=lambda p: int(re.sub(r"\D", "", p.parts[3]) or 0))
    path = shutil.which(tool) or (str(versioned[-1]) if versioned else None)
    if path is None:
        pytest.skip(f"{tool} (Debian's llvm) is missing: run {INSTALL}")
    return path


def out(cmd, **kw):
    res = subprocess.run(cmd, capture_output=True, text=True, check=False, **kw)
    assert res.returncode == 0, f"{' '.join(map(str, cmd))}: {res.stderr or res.stdout}"
    return res.stdout


def fmi2_cs_functions():
    """The co-simulation API as fmi2Functions.h declares it: every FMI2_Export but the
    Model Exchange sections."""
    text = (Path(fmpy.__file__).parent / "c-code" / "fmi2Functions.h").read_text()
    text = text[text.index("FMI2_Export fmi2GetTypesPlatformTYPE"):]
    sections = re.split(r"Functions for FMI2 for (Model Exchange|Co-Simulation)", text)
    kept = sections[0] + "".join(sections[i + 1] for i in range(1, len(sections), 2)
                                 if sections[i] == "Co-Simulation")
    return set(re.findall(r"FMI2_Export\s+\w+TYPE\s+(\w+);", kept))


FMI2_CS = fmi2_cs_functions()
# the plant is a Model Exchange FMU too (one archive, both interfaces)
FMI2_ME = {"fmi2EnterEventMode", "fmi2NewDiscreteStates", "fmi2EnterContinuousTimeMode",
           "fmi2CompletedIntegratorStep", "fmi2SetTime", "fmi2SetContinuousStates",
           "fmi2GetDerivatives", "fmi2GetEventIndicators", "fmi2GetContinuousStates",
           "fmi2GetNominalsOfContinuousStates"}


def fmi2_api(model: str) -> set[str]:
    """What the model's binary exports: the co-simulation API, and the plant's Model
    Exchange API."""
    return FMI2_CS | FMI2_ME if model == "MultirotorPlant" else FMI2_CS


@pytest.fixture(scope="module")
def built(dist, tmp_path_factory):
    """Both FMUs of every platform unzipped: {model: folder}."""
    dirs = {}
    for model in MODELS:
        dirs[model] = tmp_path_factory.mktemp(model)
        with zipfile.ZipFile(dist / f"{model}.fmu") as z:
            z.extractall(dirs[model])
    return dirs


def binaries(built, platform):
    p = platform_named(platform)
    return {m: built[m] / "binaries" / p.folder / f"{m}{p.suffix}" for m in MODELS}


def test_every_platform_folder_and_nothing_else(built, dist):
    for model in MODELS:
        assert validate_fmu(str(dist / f"{model}.fmu")) == []  # fmpy's checks
        found = sorted(p.relative_to(built[model] / "binaries").as_posix()
                       for p in (built[model] / "binaries").rglob("*") if p.is_file())
        assert found == sorted(f"{p.folder}/{model}{p.suffix}" for p in PLATFORMS)
        assert (built[model] / "sources" / "buildDescription.xml").is_file()


@pytest.mark.parametrize("platform,machine", [("x86_64-linux", "X86-64"),
                                              ("aarch64-linux", "AArch64")])
def test_linux_binaries_need_glibc_2_17_at_most_and_export_the_fmi_api(built, platform,
                                                                        machine):
    readelf, nm = llvm("llvm-readelf"), llvm("llvm-nm")
    for model, lib in binaries(built, platform).items():
        header = out([readelf, "--file-header", lib])
        assert re.search(r"Type:\s+DYN", header) and machine in header, header
        versions = out([readelf, "--version-info", lib])
        needed = {tuple(int(x) for x in v.split(".")) for v in
                  re.findall(r"Name: GLIBC_([0-9.]+)", versions)}
        assert needed and max(needed) <= GLIBC_FLOOR, f"{model}: needs GLIBC_{max(needed)}"
        exported = set(out([nm, "--dynamic", "--defined-only", "--format=just-symbols", lib])
                       .split())
        assert exported == fmi2_api(model), f"{model}: {sorted(exported ^ fmi2_api(model))}"
        libs = set(re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]",
                              out([readelf, "--dynamic", lib])))
        assert libs <= {"libc.so.6", "libm.so.6"}, libs


def test_windows_dlls_export_exactly_the_fmi_api_and_import_only_windows(built):
    objdump = llvm("llvm-objdump")
    for model, lib in binaries(built, "x86_64-windows").items():
        text = out([objdump, "--private-headers", lib])
        assert "file format coff-x86-64" in text
        table = text[text.index("Export Table:"):]
        exported = set(re.findall(r"^\s+\d+\s+0x[0-9a-f]+\s+(\w+)$", table, re.M))
        assert exported == fmi2_api(model), f"{model}: {sorted(exported ^ fmi2_api(model))}"
        dlls = {d.lower() for d in re.findall(r"DLL Name: (\S+)", text)}
        assert dlls and all(d == "kernel32.dll" or d.startswith("api-ms-win-crt-")
                            for d in dlls), dlls


def macho_exports(objdump, lib, arch):
    text = out([objdump, "--macho", "--exports-trie", f"--arch={arch}", lib])
    return {name[1:] for name in re.findall(r"^0x[0-9A-F]+\s+(\S+)$", text, re.M)}


@pytest.mark.parametrize("platform,arches", [("x86_64-darwin", ("x86_64", "arm64")),
                                             ("aarch64-darwin", ("arm64",))])
def test_darwin_binaries_are_dylibs_exporting_the_fmi_api(built, platform, arches):
    """Checked, not run: no macOS here."""
    objdump, lipo = llvm("llvm-objdump"), llvm("llvm-lipo")
    minos = {"x86_64": "10.15", "arm64": "11.0"}
    for model, lib in binaries(built, platform).items():
        assert out([lipo, "-archs", lib]).split() == list(arches)
        for arch in arches:
            head = out([objdump, "--macho", "--private-headers", f"--arch={arch}", lib])
            assert re.search(r"MH_MAGIC_64\s+\S+\s+\S+\s+\S+\s+DYLIB", head), head[:400]
            assert f"name @rpath/{model}.dylib" in head
            assert re.search(rf"minos {re.escape(minos[arch])}\n", head)
            used = out([objdump, "--macho", "--dylibs-used", f"--arch={arch}", lib])
            # its own name (LC_ID_DYLIB), then what it loads: the system library only
            assert re.findall(r"^\s+(\S+) \(", used, re.M) == [
                f"@rpath/{model}.dylib", "/usr/lib/libSystem.B.dylib"]
            exported = macho_exports(objdump, lib, arch) - MACHO_HEADER_SYMBOLS
            assert exported == fmi2_api(model), sorted(exported ^ fmi2_api(model))
    if platform == "aarch64-darwin":  # the same arm64 slice as in the universal darwin64
        for model, lib in binaries(built, platform).items():
            universal = binaries(built, "x86_64-darwin")[model]
            thin = lib.parent / "arm64-from-darwin64"
            out([lipo, universal, "-thin", "arm64", "-output", thin])
            assert thin.read_bytes() == lib.read_bytes()


@pytest.mark.skipif(fmpy.platform != "linux64", reason="the shipped binaries are x86_64 Linux")
def test_cross_built_linux64_flies_bit_identically_to_the_shipped_binaries(dist, monkeypatch):
    """The Zig build (clang, glibc 2.17 symbols) computes what the host's gcc build does:
    the first 3 s of a shipped scenario, every signal, to the bit."""
    monkeypatch.delenv("FULLPOSE_BUILD_DIR", raising=False)
    shipped = run(prepare("full_pose_with_disturbances", 3.0), progress=False)
    monkeypatch.setenv("FULLPOSE_BUILD_DIR", str(dist))
    cross = run(prepare("full_pose_with_disturbances", 3.0), progress=False)
    assert cross.columns == shipped.columns
    a, b = shipped.data, cross.data
    assert a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


# -- flying: our master, per platform ----------------------------------------------------


def compile_master(target, dest, include):
    exe = dest / ("hover_master.exe" if "windows" in target else f"hover_master-{target}")
    libs = () if "windows" in target else ("-ldl",)
    out([sys.executable, "-m", "ziglang", "cc", "-target", target, "-std=c99", "-O2",
         "-Wall", "-Wextra", "-Wpedantic", "-Wmissing-prototypes", "-Wstrict-prototypes",
         "-Werror", "-I", include, str(MASTER), *libs, "-o", exe])
    return exe


def hover_script(built, platform, path):
    """The master's script: both FMUs of ``platform``, connected by matching names (every
    controller measurement from the plant output of that name, every plant command from
    the controller output of that name), the plant started off the hover reference."""
    libs = binaries(built, platform)
    plant, ctrl = (read_model_description(str(built[m] / "modelDescription.xml"))
                   for m in MODELS)
    pv = {v.name: v for v in plant.modelVariables}
    cv = {v.name: v for v in ctrl.modelVariables}

    def fmu(fid, model, md):
        return (f"fmu {fid} {path(libs[model])} {md.guid} "
                f"{(built[model] / 'resources').as_uri()}")

    lines = [fmu("controller", "FullPoseController", ctrl), fmu("plant", "MultirotorPlant", plant)]
    lines += [f"real plant {pv[f'pos0[{i + 1}]'].valueReference} {POS0[i]!r}" for i in range(3)]
    lines += [f"real plant {pv[f'euler0[{i + 1}]'].valueReference} {EULER0[i]!r}"
              for i in range(3)]
    lines += [f"boolean plant {pv['init_trim'].valueReference} 1", "enter plant 0", "exit plant"]
    links = 0
    for name, v in cv.items():
        if v.causality == "input" and name in pv and pv[name].causality == "output":
            lines.append(f"link plant {pv[name].valueReference} controller {v.valueReference}")
            links += 1
    for name, v in pv.items():
        if v.causality == "input" and name in cv and cv[name].causality == "output":
            lines.append(f"link controller {cv[name].valueReference} plant {v.valueReference}")
            links += 1
    # pos vel acc euler rate, omega alpha beta[8], pose_age measured; omega/alpha/beta_cmd[8]
    # commanded
    assert links == 5 * 3 + 3 * 8 + 1 + 3 * 8, links
    lines += ["enter controller 0", "sync controller"]
    lines += [f"real controller {cv[f'pos_ref[{i + 1}]'].valueReference} {POS_REF[i]!r}"
              for i in range(3)]
    lines.append("exit controller")
    lines += [f"print plant {pv[f'{g}[{i + 1}]'].valueReference}"
              for g in ("pos", "euler") for i in range(3)]
    lines.append(f"run {STEP!r} {STEPS} {EVERY} controller plant")
    return "\n".join(lines) + "\n"


def fly(cmd, script_text, script_path, script_arg, env=None):
    script_path.write_text(script_text)
    res = subprocess.run([*cmd, script_arg], capture_output=True, text=True, check=False,
                         env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    rows = np.array([[float(x) for x in ln.split()] for ln in res.stdout.splitlines()
                     if ln.strip()])
    assert rows.shape == (STEPS // EVERY + 1, 7), rows.shape
    return rows


@pytest.fixture(scope="module")
def native_master(built, tmp_path_factory):
    if fmpy.platform != "linux64":
        pytest.skip("the native reference runs on x86_64 Linux")
    return compile_master("x86_64-linux-gnu.2.17", tmp_path_factory.mktemp("native"),
                          built["MultirotorPlant"] / "sources")


@pytest.fixture(scope="module")
def native_run(built, native_master):
    work = native_master.parent
    return fly([str(native_master)], hover_script(built, "x86_64-linux", str),
               work / "hover.txt", str(work / "hover.txt"))


@pytest.mark.parametrize("script,message", [
    ("# a comment\n\nfly away\n", "bad.txt:3: unknown command: fly"),
    ("fmu p /nowhere/lib.so {guid} file:///x\n", "bad.txt:1: cannot load library: /nowhere"),
    ("run 0.002 10\n", "bad.txt:1: usage: run STEP N EVERY ID..."),
])
def test_master_names_the_bad_line_of_its_script(native_master, tmp_path, script, message):
    (tmp_path / "bad.txt").write_text(script)
    res = subprocess.run([native_master, tmp_path / "bad.txt"], capture_output=True, text=True,
                         check=False)
    assert res.returncode == 1 and res.stderr.startswith(f"hover_master: {tmp_path}/{message}")


def test_native_master_flies_back_to_hover(native_run):
    """The reference itself: the vehicle, started 0.41 m and several degrees off, is back at
    the hover reference within a centimetre and a milliradian after 10 s."""
    t, pos, euler = native_run[:, 0], native_run[:, 1:4], native_run[:, 4:7]
    assert t[-1] == pytest.approx(STEPS * STEP)
    assert np.linalg.norm(pos[0] - POS0) < 1e-12
    assert np.linalg.norm(pos[-1] - POS_REF) < 0.01
    assert np.abs(euler[-1]).max() < 1e-3
    assert np.abs(pos - pos[0]).max() > 0.1, "it moved: the comparison has content"


def deviation(rows, native):
    assert np.array_equal(rows[:, 0], native[:, 0])
    return float(np.abs(rows[:, 1:4] - native[:, 1:4]).max()), float(
        np.abs(rows[:, 4:7] - native[:, 4:7]).max())


def test_win64_binaries_fly_under_wine_as_natively(built, native_run, tmp_path):
    wine = shutil.which("wine")
    if wine is None:
        pytest.skip(f"wine is missing: run {INSTALL}")
    exe = compile_master("x86_64-windows-gnu", tmp_path, built["MultirotorPlant"] / "sources")

    def winpath(p):
        return "Z:" + str(Path(p).resolve()).replace("/", "\\")

    env = {**os.environ, "WINEPREFIX": str(tmp_path / "wineprefix"), "WINEDEBUG": "-all",
           "WINEDLLOVERRIDES": "mscoree,mshtml="}  # no Mono/Gecko installer prompts
    rows = fly([wine, str(exe)], hover_script(built, "x86_64-windows", winpath),
               tmp_path / "hover.txt", winpath(tmp_path / "hover.txt"), env=env)
    dpos, deul = deviation(rows, native_run)
    print(f"win64 under Wine: max |pos - native| = {dpos:.3g} m, |euler| {deul:.3g} rad")
    assert dpos <= TOL and deul <= TOL


def test_aarch64_binaries_fly_under_qemu_as_natively(built, native_run, tmp_path):
    qemu = shutil.which("qemu-aarch64")
    sysroot = Path("/usr/aarch64-linux-gnu")
    if qemu is None or not (sysroot / "lib" / "ld-linux-aarch64.so.1").exists():
        pytest.skip(f"qemu-aarch64 or the arm64 C library is missing: run {INSTALL}")
    exe = compile_master("aarch64-linux-gnu.2.17", tmp_path,
                         built["MultirotorPlant"] / "sources")
    rows = fly([qemu, "-L", str(sysroot), str(exe)], hover_script(built, "aarch64-linux", str),
               tmp_path / "hover.txt", str(tmp_path / "hover.txt"))
    dpos, deul = deviation(rows, native_run)
    print(f"aarch64 under qemu: max |pos - native| = {dpos:.3g} m, |euler| {deul:.3g} rad")
    assert dpos <= TOL and deul <= TOL
