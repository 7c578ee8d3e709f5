"""Both FMUs rebuilt from their ``sources/`` by every documented route, without the project's
flags, and what each binary gives (docs/fmus.md, "Building from sources").

Routes: fmpy's ``build_platform_binary`` (with the documented option that links the maths
library), the documented one-line ``cc`` command, GCC and clang in their default (GNU) modes
with ``-march=native`` (fused multiply-add in hardware: the contraction case), Zig's ``cc``
natively and cross to aarch64 (run under qemu-user).  Each binary must

* export the FMI functions and nothing else (``nm -D --defined-only``): the one translation
  unit ``<model>_all.c`` hides and renames everything else;
* need the maths library itself (``DT_NEEDED libm.so.6``) and load outside Python: our C
  master (``fmu_src/tools/hover_master.c``, built without ``-lm``, ``dlopen`` with
  ``RTLD_LOCAL``) flies 1 s of closed loop, started off the hover reference, on the binaries
  of one route, and every printed position and attitude equals the orchestrator's run of the
  same start values on the installed FMUs, to the bit;
* hold no fused multiply-add instruction (``#pragma STDC FP_CONTRACT OFF`` / GCC's
  ``optimize("fp-contract=off")`` inside the sources);
* give the digests of the CMake build on the shipped scenarios ``hover`` and
  ``position_step`` (``tests/tools/scenario_digests.py``).

And one static image: both FMUs compiled with ``FMI2_FUNCTION_PREFIX`` (the standard
``fmi2Functions.h`` in ``sources/`` honours it) and linked with ``fmu_src/tools/
static_master.c`` into one executable, every symbol of each object carrying its prefix,
flying the same second to the bit.  Controls that show what the checks catch: fmpy's builder
without the option (no libm: the master cannot load it), the C files compiled one by one
without the project's flags (internals exported; loaded RTLD_GLOBAL, the controller binds to
the plant's and refuses its own GUID), the contraction pragma taken out (fused multiply-adds
on aarch64).  The Compliance Checker loads the rebuilt FMUs too, where the FMI tools are
(``tests/tools/fmi_tools.sh``).

Oracles: the compilers, binutils' and LLVM's object tools, qemu-user, the Compliance
Checker, the orchestrator's run and digests of the installed FMUs.  Marked ``platforms``
(opt-in, ``-m platforms``); a route whose compiler is absent skips saying so
(``tests/tools/install_platform_tools.sh`` installs clang, LLVM and qemu-user; ``ziglang``
comes with ``pip install -e ".[test]"``).
"""

from __future__ import annotations

import dataclasses
import importlib.util
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
from fmpy.build import build_platform_binary
from helpers import rezip

import controller
import plant
from orchestrator.master import CoSimulation, run
from orchestrator.runner import prepare
from plant.common.artifacts import library_path

pytestmark = [pytest.mark.platforms,
              pytest.mark.skipif(fmpy.platform != "linux64",
                                 reason="the source builds are checked on x86_64 Linux")]

ROOT = Path(__file__).resolve().parents[2]
TOOLS = ROOT / "fmu_src" / "tools"
DOC = ROOT / "docs" / "fmus.md"
INSTALL = "tests/tools/install_platform_tools.sh"
MODELS = ("MultirotorPlant", "FullPoseController")
WHERE = {"MultirotorPlant": plant.plant_fmu, "FullPoseController": controller.controller_fmu}
WARNINGS = ("-Wall", "-Wextra", "-Wpedantic", "-Wmissing-prototypes", "-Wstrict-prototypes",
            "-Werror")
DIGESTED = ("hover", "position_step")
SECONDS, STEP = 1.0, 0.002
POS0, EULER0 = (0.3, -0.2, -2.8), (0.05, -0.04, 0.1)  # started off the hover reference
# the documented fmpy call: its builder links no library an FMU names, this option the maths
# library (appended to every link line, so also with --as-needed)
FMPY_OPTIONS = {"CMAKE_C_STANDARD_LIBRARIES:STRING": "-lm"}
X86_FMA = re.compile(r"\svfn?m(add|sub)\w*\s")
ARM_FMA = re.compile(r"\s(fn?madd|fn?msub|fmla|fmls)\s")


def run_ok(cmd, **kw):
    res = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, check=False,
                         **kw)
    assert res.returncode == 0, f"{' '.join(map(str, cmd))}:\n{(res.stderr or res.stdout)[-3000:]}"
    return res.stdout


def tool(name):
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} is missing: run {INSTALL}")
    return path


def zig():
    if importlib.util.find_spec("ziglang") is None:
        pytest.skip("the Zig compiler is missing: pip install -e '.[test]'")
    return [sys.executable, "-m", "ziglang", "cc"]


def fmi2_functions(header: Path, model: str = "FullPoseController") -> set[str]:
    """The FMI 2 API the header declares for ``model``: co-simulation (Model Exchange sections
    left out), and Model Exchange too for the plant (one FMU, both interfaces)."""
    text = header.read_text()
    text = text[text.index("FMI2_Export fmi2GetTypesPlatformTYPE"):]
    sections = re.split(r"Functions for FMI2 for (Model Exchange|Co-Simulation)", text)
    wanted = {"Co-Simulation"} | ({"Model Exchange"} if model == "MultirotorPlant" else set())
    kept = sections[0] + "".join(sections[i + 1] for i in range(1, len(sections), 2)
                                 if sections[i] in wanted)
    return set(re.findall(r"FMI2_Export\s+\w+TYPE\s+(\w+);", kept))


# -- the FMUs' sources, unpacked once --------------------------------------------------------


@pytest.fixture(scope="module")
def unpacked(tmp_path_factory):
    """{model: folder} of each installed FMU, its binaries removed."""
    dirs = {}
    for model in MODELS:
        d = tmp_path_factory.mktemp(model)
        with zipfile.ZipFile(WHERE[model]()) as z:
            z.extractall(d)
        shutil.rmtree(d / "binaries")
        dirs[model] = d
    return dirs


def fresh_copy(unpacked, model, dest):
    shutil.copytree(unpacked[model], dest)
    return dest



def one_line_command(model):
    """The documented one-line build of the Linux binary (docs/fmus.md), for ``model``."""
    lines = [ln.strip() for ln in DOC.read_text().splitlines()
             if re.match(r"^\s*cc .* -o binaries/linux64/MultirotorPlant\.so$", ln)]
    assert len(lines) == 1, "docs/fmus.md shows the one-line cc command once"
    return lines[0].replace("MultirotorPlant", model)


# -- the routes ------------------------------------------------------------------------------


def build_fmpy(folder, model, work, options=FMPY_OPTIONS):
    build = work / f"{model}-cmake"
    build.mkdir()
    build_platform_binary(folder, build_dir=build, cmake_options=dict(options))
    return folder / "binaries" / "linux64" / f"{model}.so"


def build_cc(folder, model, work):
    (folder / "binaries" / "linux64").mkdir(parents=True)
    run_ok(["sh", "-c", one_line_command(model)], cwd=folder)
    return folder / "binaries" / "linux64" / f"{model}.so"


def build_with(compiler):
    """A build in the compiler's default (GNU) mode for this CPU: no -std, -march=native."""
    def build(folder, model, work):
        cmd = compiler() if callable(compiler) else [tool(compiler)]
        out = folder / "binaries" / "linux64" / f"{model}.so"
        out.parent.mkdir(parents=True)
        run_ok([*cmd, "-O2", "-march=native", "-shared", "-fPIC", "-I", folder / "sources",
                folder / "sources" / f"{model}_all.c", "-lm", "-o", out])
        return out
    return build


ROUTES = {
    "fmpy": build_fmpy,
    "cc": build_cc,
    "gcc-native": build_with("gcc"),
    "clang-native": build_with("clang"),
    "zig-native": build_with(zig),
}


@dataclasses.dataclass
class Built:
    """One route's rebuilt FMUs: the folder holding both archives, and each binary."""

    fmus: Path
    libs: dict[str, Path]


_built: dict[str, Built] = {}


def route_build(route, unpacked, tmp_path_factory) -> Built:
    """Both FMUs rebuilt by ``route`` (once per session), rezipped beside the host libraries."""
    if route not in _built:
        if route == "fmpy" and shutil.which("cmake") is None:
            pytest.fail("cmake is needed by fmpy's platform-binary builder")
        work = tmp_path_factory.mktemp(route)
        fmus = work / "fmus"
        fmus.mkdir()
        libs = {}
        for model in MODELS:
            folder = fresh_copy(unpacked, model, work / model)
            libs[model] = ROUTES[route](folder, model, work)
            assert libs[model].is_file()
            rezip(folder, fmus / f"{model}.fmu")
        for package, stem in (("plant", "fp_multirotor"), ("controller", "fp_controller"),
                              ("orchestrator", "fp_cosim")):  # the host libraries as installed
            lib = library_path(package, stem)
            shutil.copy(lib, fmus / lib.name)
        _built[route] = Built(fmus, libs)
    return _built[route]


@pytest.fixture(params=list(ROUTES))
def built(request, unpacked, tmp_path_factory):
    return request.param, route_build(request.param, unpacked, tmp_path_factory)


# -- what each binary gives ------------------------------------------------------------------


def exports(lib):
    return set(run_ok(["nm", "-D", "--defined-only", "--format=just-symbols", lib]).split())


def needed(lib):
    text = run_ok([tool("readelf"), "--dynamic", lib])
    return set(re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", text))


def test_route_exports_the_fmi_functions_only_and_needs_libm(built, unpacked):
    route, b = built
    for model, lib in b.libs.items():
        api = fmi2_functions(unpacked["MultirotorPlant"] / "sources" / "fmi2Functions.h", model)
        got = exports(lib)
        print(f"{route} {model}: {len(got)} exported symbols, {len(got - api)} beyond the "
              f"FMI functions; needs {sorted(needed(lib))}")
        assert got == api, f"{route} {model}: {sorted(got ^ api)}"
        assert "libm.so.6" in needed(lib), f"{route} {model} does not link the maths library"


def test_route_has_no_fused_multiply_add(built):
    route, b = built
    for model, lib in b.libs.items():
        fused = len(X86_FMA.findall(run_ok(["objdump", "-d", lib])))
        print(f"{route} {model}: {fused} fused multiply-add instructions")
        assert fused == 0


def _digests():
    spec = importlib.util.spec_from_file_location(
        "scenario_digests", ROOT / "tests" / "tools" / "scenario_digests.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {name: module.digest(name, "native")[0] for name in DIGESTED}


@pytest.fixture(scope="module")
def cmake_digests():
    """The digests of the FMUs installed (or FULLPOSE_BUILD_DIR's): the CMake build."""
    return _digests()


def test_route_gives_the_cmake_builds_digests(built, cmake_digests, monkeypatch):
    route, b = built
    monkeypatch.setenv("FULLPOSE_BUILD_DIR", str(b.fmus))
    assert plant.plant_fmu().parent == controller.controller_fmu().parent == b.fmus
    got = _digests()
    for name in DIGESTED:
        print(f"{route} {name}: {'equal' if got[name] == cmake_digests[name] else 'DIFFERS'}")
    assert got == cmake_digests


# -- flying outside Python: our C master -----------------------------------------------------


@pytest.fixture(scope="module")
def scenario():
    sc = prepare("hover", SECONDS)
    overrides = {f"{g}[{i + 1}]": v[i] for g, v in (("pos0", POS0), ("euler0", EULER0))
                 for i in range(3)}
    return dataclasses.replace(sc, plant_parameters={**sc.plant_parameters, **overrides})


@pytest.fixture(scope="module")
def orchestrator_run(scenario):
    """Position and attitude at every step of the orchestrator's run (installed FMUs)."""
    result = run(scenario, progress=False)
    cols = [result.columns.index(f"plant.{g}[{i}]") for g in ("pos", "euler") for i in (1, 2, 3)]
    rows = np.column_stack([result.data[:, result.columns.index("time")],
                            result.data[:, cols]])
    assert np.abs(rows[:, 1:4] - rows[0, 1:4]).max() > 0.01, "it moved: the comparison has content"
    return rows


def master_script(scenario, unpacked, libs):
    """The master's script for the scenario's closed loop at its start values: both FMUs,
    every parameter the orchestrator sets, the references and disturbances of t = 0 (the
    scenario holds them), the inputs connected by name, 1 s printed at every step."""
    md = {m: read_model_description(str(unpacked[m] / "modelDescription.xml")) for m in MODELS}
    var = {m: {v.name: v for v in md[m].modelVariables} for m in MODELS}
    ids = {"MultirotorPlant": "plant", "FullPoseController": "controller"}
    start = CoSimulation(scenario).start_values()
    t0 = np.zeros(1)
    refs = {**scenario.references(t0), "rotor_health": scenario.health(t0)}
    dist = scenario.disturbances(t0)

    def sets(model, values):
        out = []
        for name, value in values.items():
            v = var[model][name]
            kind = {"Real": "real", "Integer": "integer", "Boolean": "boolean"}[v.type]
            text = repr(float(value)) if kind == "real" else str(int(value))
            out.append(f"{kind} {ids[model]} {v.valueReference} {text}")
        return out

    def vector(model, group, values):
        flat = np.asarray(values, dtype=float).ravel()
        return sets(model, {f"{group}[{i + 1}]": x for i, x in enumerate(flat)})

    plant_v, ctrl_v = var["MultirotorPlant"], var["FullPoseController"]
    lines = [f"fmu {ids[m]} {libs[m]} {md[m].guid} {(unpacked[m] / 'resources').as_uri()}"
             for m in ("FullPoseController", "MultirotorPlant")]
    lines += [*sets("MultirotorPlant", start.plant), "enter plant 0", "exit plant"]
    for group, values in dist.items():
        lines += vector("MultirotorPlant", group, values)
    for name, v in ctrl_v.items():
        if v.causality == "input" and name in plant_v and plant_v[name].causality == "output":
            lines.append(f"link plant {plant_v[name].valueReference} controller "
                         f"{v.valueReference}")
    for name, v in plant_v.items():
        if v.causality == "input" and name in ctrl_v and ctrl_v[name].causality == "output":
            lines.append(f"link controller {ctrl_v[name].valueReference} plant "
                         f"{v.valueReference}")
    lines += sets("FullPoseController", start.controller)
    lines += ["enter controller 0", "sync controller"]
    for group, values in refs.items():
        lines += vector("FullPoseController", group, values)
    lines.append("exit controller")
    lines += [f"print plant {plant_v[f'{g}[{i}]'].valueReference}"
              for g in ("pos", "euler") for i in (1, 2, 3)]
    lines.append(f"run {STEP!r} {round(SECONDS / STEP)} 1 controller plant")
    return "\n".join(lines) + "\n"


def fly(cmd, script, work):
    path = work / "script.txt"
    path.write_text(script)
    res = subprocess.run([*map(str, cmd), str(path)], capture_output=True, text=True,
                         check=False, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    return np.array([[float(x) for x in ln.split()] for ln in res.stdout.splitlines()
                     if ln.strip()])


@pytest.fixture(scope="module")
def master(unpacked, tmp_path_factory):
    """hover_master built natively without the maths library: what it loads must bring it."""
    exe = tmp_path_factory.mktemp("master") / "hover_master"
    run_ok(["cc", "-std=c99", "-O2", *WARNINGS, "-I", unpacked["MultirotorPlant"] / "sources",
            TOOLS / "hover_master.c", "-ldl", "-o", exe])
    assert not any(n.startswith("libm.") for n in needed(exe))
    return exe


def assert_same_flight(rows, reference, label):
    assert rows.shape == reference.shape, (rows.shape, reference.shape)
    assert np.array_equal(rows[:, 0], reference[:, 0])
    dev = float(np.abs(rows[:, 1:] - reference[:, 1:]).max())
    print(f"{label}: max |position, attitude - orchestrator's run| = {dev:.3g}")
    assert dev == 0.0


def test_route_loads_outside_python_and_flies_as_the_orchestrator(built, master, scenario,
                                                                  unpacked, orchestrator_run,
                                                                  tmp_path):
    route, b = built
    rows = fly([master], master_script(scenario, unpacked, b.libs), tmp_path)
    assert_same_flight(rows, orchestrator_run, f"{route}, hover_master (dlopen RTLD_LOCAL)")


# -- aarch64: Zig's clang contracts by default there -----------------------------------------


def test_zig_aarch64_without_project_flags_has_no_fma_and_flies_under_qemu(
        unpacked, scenario, orchestrator_run, tmp_path):
    cc = zig()
    objdump = shutil.which("llvm-objdump")
    qemu = shutil.which("qemu-aarch64")
    sysroot = Path("/usr/aarch64-linux-gnu")
    if objdump is None or qemu is None or not (sysroot / "lib" / "ld-linux-aarch64.so.1").exists():
        pytest.skip(f"llvm-objdump, qemu-aarch64 or the arm64 C library is missing: run {INSTALL}")
    llvm_nm, llvm_readelf = shutil.which("llvm-nm"), shutil.which("llvm-readelf")
    if llvm_nm is None or llvm_readelf is None:
        pytest.skip(f"llvm-nm or llvm-readelf is missing: run {INSTALL}")
    target = ["-target", "aarch64-linux-gnu.2.17"]
    libs = {}
    for model in MODELS:
        api = fmi2_functions(unpacked[model] / "sources" / "fmi2Functions.h", model)
        src = unpacked[model] / "sources"
        libs[model] = tmp_path / f"{model}.so"
        run_ok([*cc, *target, "-O2", "-shared", "-fPIC", "-I", src, src / f"{model}_all.c",
                "-lm", "-o", libs[model]])
        fused = len(ARM_FMA.findall(run_ok([objdump, "-d", libs[model]])))
        got = set(run_ok([llvm_nm, "-D", "--defined-only", "--format=just-symbols",
                          libs[model]]).split())
        libm = "libm.so.6" in run_ok([llvm_readelf, "--dynamic", libs[model]])
        print(f"zig aarch64 {model}: {len(got)} exported symbols, {len(got - api)} beyond the "
              f"FMI functions, libm {'needed' if libm else 'NOT needed'}, {fused} fused "
              "multiply-add instructions")
        assert fused == 0 and got == api and libm
    # the control: without the pragma the same compile fuses
    control = tmp_path / "nopragma"
    shutil.copytree(unpacked["FullPoseController"] / "sources", control)
    begin = control / "fp_unity_begin.h"
    begin.write_text(begin.read_text().replace("#pragma STDC FP_CONTRACT OFF", ""))
    run_ok([*cc, *target, "-O2", "-c", "-I", control, control / "FullPoseController_all.c",
            "-o", tmp_path / "fused.o"])
    fused = len(ARM_FMA.findall(run_ok([objdump, "-d", tmp_path / "fused.o"])))
    print(f"zig aarch64 controller without the pragma: {fused} fused multiply-adds")
    assert fused > 100
    exe = tmp_path / "hover_master"
    run_ok([*cc, *target, "-std=c99", "-O2", *WARNINGS, "-I",
            unpacked["MultirotorPlant"] / "sources", TOOLS / "hover_master.c", "-ldl", "-o", exe])
    rows = fly([qemu, "-L", sysroot, exe], master_script(scenario, unpacked, libs), tmp_path)
    assert_same_flight(rows, orchestrator_run, "zig aarch64 under qemu")


# -- one static image ------------------------------------------------------------------------


def test_both_fmus_with_their_prefixes_in_one_static_image(unpacked, scenario, orchestrator_run,
                                                          tmp_path):
    objects = []
    for model in MODELS:
        src = unpacked[model] / "sources"
        obj = tmp_path / f"{model}.o"
        run_ok(["cc", "-std=c99", "-O2", *WARNINGS, f"-DFMI2_FUNCTION_PREFIX={model}_", "-c",
                "-I", src, src / f"{model}_all.c", "-o", obj])
        defined = run_ok(["nm", "--defined-only", "-g", "--format=just-symbols", obj]).split()
        foreign = [s for s in defined if not s.startswith(f"{model}_")]
        print(f"static {model}: {len(defined)} global symbols, {len(foreign)} without the prefix")
        assert defined and not foreign, foreign[:10]
        api = fmi2_functions(src / "fmi2Functions.h", model)
        assert {f"{model}_{f}" for f in api} <= set(defined)
        objects.append(obj)
    exe = tmp_path / "static_master"
    run_ok(["cc", "-std=c99", "-O2", *WARNINGS, "-I", unpacked["MultirotorPlant"] / "sources",
            "-I", TOOLS, TOOLS / "static_master.c", *objects, "-lm", "-o", exe])
    rows = fly([exe], master_script(scenario, unpacked, {m: m for m in MODELS}), tmp_path)
    assert_same_flight(rows, orchestrator_run, "one static image")


# -- controls: what the checks above catch ---------------------------------------------------


def test_control_fmpy_builder_without_the_option_links_no_libm(unpacked, master, scenario,
                                                             tmp_path):
    """fmpy's builder reads only the C files of an FMI 2 FMU: plainly called, its binary
    needs libm without naming it, loads in Python (which has libm) and nowhere else."""
    libs = {}
    for model in MODELS:
        folder = fresh_copy(unpacked, model, tmp_path / model)
        libs[model] = build_fmpy(folder, model, tmp_path, options={})
        assert "libm.so.6" not in needed(libs[model])
    path = tmp_path / "script.txt"
    path.write_text(master_script(scenario, unpacked, libs))
    res = subprocess.run([str(master), str(path)], capture_output=True, text=True, check=False)
    assert res.returncode == 1 and "undefined symbol" in res.stderr, res.stderr


def test_control_gcc_fuses_for_fma_hardware_without_the_vectorizer_guard(unpacked, tmp_path):
    """GCC 12's basic-block vectorizer pairs a*b+c with a*b-c into one vfmaddsub even under
    -ffp-contract=off; fp_unity_begin.h switches it off where the target has FMA.  Without
    that line, gcc -O2 -march=native fuses (and the hover and position_step digests differ)."""
    flags = Path("/proc/cpuinfo").read_text().split()
    if "fma" not in flags:
        pytest.skip("this CPU has no fused multiply-add: nothing to fuse")
    src = tmp_path / "sources"
    shutil.copytree(unpacked["MultirotorPlant"] / "sources", src)
    begin = src / "fp_unity_begin.h"
    guard = '#pragma GCC optimize("no-tree-slp-vectorize")'
    assert guard in begin.read_text()
    begin.write_text(begin.read_text().replace(guard, ""))
    out = tmp_path / "plant.so"
    run_ok([tool("gcc"), "-O2", "-march=native", "-shared", "-fPIC", "-I", src,
            src / "MultirotorPlant_all.c", "-lm", "-o", out])
    fused = len(X86_FMA.findall(run_ok(["objdump", "-d", out])))
    print(f"gcc -march=native without the guard: {fused} fused multiply-adds in the plant")
    if fused == 0:
        pytest.skip("this GCC does not fuse here without the guard (GCC 12.2 does)")


RTLD_GLOBAL_PAIR = r"""
import ctypes, sys
plant, ctrl, guid = sys.argv[1:4]
ctypes.CDLL(plant, mode=ctypes.RTLD_GLOBAL)
lib = ctypes.CDLL(ctrl, mode=ctypes.RTLD_GLOBAL)
LOGGER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                          ctypes.c_char_p)
class Callbacks(ctypes.Structure):
    _fields_ = [("logger", LOGGER), ("allocate", ctypes.c_void_p), ("free", ctypes.c_void_p),
                ("step_finished", ctypes.c_void_p), ("env", ctypes.c_void_p)]
libc = ctypes.CDLL(None)
messages = []
logger = LOGGER(lambda env, name, status, cat, msg: messages.append(msg.decode()))
cb = Callbacks(logger, ctypes.cast(libc.calloc, ctypes.c_void_p).value,
               ctypes.cast(libc.free, ctypes.c_void_p).value, None, None)
lib.fmi2Instantiate.restype = ctypes.c_void_p
c = lib.fmi2Instantiate(b"controller", 1, guid.encode(), b"", ctypes.byref(cb), 0, 0)
print("instantiated" if c else "refused: " + " | ".join(messages))
"""


def test_control_separate_files_without_flags_export_internals_and_rtld_global_breaks(
        unpacked, tmp_path):
    """The C files compiled one by one (not the one translation unit) without
    -fvisibility=hidden export the internals under the same names in both FMUs; loaded with
    RTLD_GLOBAL, the controller then calls the plant's fp_model_info and refuses its own GUID.
    The one translation unit's binaries, loaded the same way, instantiate."""
    guid = read_model_description(str(unpacked["FullPoseController"] / "modelDescription.xml")).guid
    separate, unity = {}, {}
    for model in MODELS:
        src = unpacked[model] / "sources"
        files = sorted(p for p in src.glob("*.c") if p.name != f"{model}_all.c")
        separate[model] = tmp_path / f"{model}-separate.so"
        run_ok(["cc", "-std=c99", "-O2", "-shared", "-fPIC", "-I", src, *files, "-lm", "-o",
                separate[model]])
        unity[model] = tmp_path / f"{model}-unity.so"
        run_ok(["cc", "-std=c99", "-O2", "-shared", "-fPIC", "-I", src, src / f"{model}_all.c",
                "-lm", "-o", unity[model]])
    leaked = exports(separate["MultirotorPlant"]) & exports(separate["FullPoseController"])
    leaked = {s for s in leaked if not s.startswith("fmi2")}
    print(f"separate files: {len(leaked)} internal symbols exported by both FMUs")
    assert {"fp_model_info", "fp_model_guid"} <= leaked

    def pair(libs):
        return run_ok([sys.executable, "-c", RTLD_GLOBAL_PAIR, libs["MultirotorPlant"],
                       libs["FullPoseController"], guid]).strip()

    assert pair(separate).startswith("refused"), pair(separate)
    assert pair(unity) == "instantiated"


# -- the Compliance Checker loads them too ---------------------------------------------------


def fmi_checker() -> Path:
    folder = os.environ.get("FULLPOSE_FMI_TOOLS")
    candidates = [Path(folder) / "bin" / "fmuCheck.linux64"] if folder else []
    found = shutil.which("fmuCheck.linux64")
    if found:
        candidates.append(Path(found))
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    pytest.skip("fmuCheck.linux64 not found (set FULLPOSE_FMI_TOOLS to the folder holding "
                "bin/fmuCheck.linux64; tests/tools/fmi_tools.sh builds it)")


@pytest.mark.parametrize("route", ["fmpy", "cc"])
def test_compliance_checker_loads_the_rebuilt_fmus(route, unpacked, tmp_path_factory, tmp_path):
    checker = fmi_checker()
    b = route_build(route, unpacked, tmp_path_factory)
    for model in MODELS:
        res = subprocess.run([str(checker), "-h", "0.002", "-s", "0.1", "-o",
                              str(tmp_path / f"{model}.csv"), str(b.fmus / f"{model}.fmu")],
                             capture_output=True, text=True, check=False, timeout=300)
        text = res.stdout + res.stderr
        print(f"{route} {model}: Compliance Checker exit {res.returncode}")
        assert res.returncode == 0 and "undefined symbol" not in text, text[-2000:]
        assert re.search(r"0 Error\(s\)", text), text[-2000:]
