"""Every FMU carries the C sources of its binary, and those alone rebuild it.

``sources/`` holds exactly the files the binary is compiled from, flat (``-I sources`` is the
only include path), with the FMI 2 headers; the modelDescription's ``<SourceFiles>`` and
``sources/buildDescription.xml`` list its one translation unit, ``<model>_all.c``, which
includes every other C file once.  An FMU whose binaries are deleted and rebuilt from
``sources/`` alone, with fmpy's platform-binary builder (its own CMakeLists: fmpy 0.3.32
reads the FMI 2 ``<SourceFiles>``) and with the one-line ``cc`` command of docs/fmus.md,
flies a shipped scenario bit-identically to the shipped binaries (every route, without the
project's flags, outside Python and in one static image: test_source_builds.py).

Oracles: fmpy's builder and its FMI 3.0 build-description schema, the system C compiler,
fmpy's FMI headers and the FMI 2.0.1 standard's ``fmi2Functions.h`` (its SHA-256), the run
of the shipped binaries.
"""

import hashlib
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.build import build_platform_binary
from fmpy.model_description import read_build_description
from helpers import rezip

import controller
import plant
from orchestrator.master import run
from orchestrator.runner import prepare

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "fmus.md"
FMUS = {"MultirotorPlant": plant.plant_fmu, "FullPoseController": controller.controller_fmu}
FMI_HEADERS = {"fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"}
# SHA-256 of the FMI 2.0.1 standard's headers/fmi2Functions.h with LF line ends (the
# modelica/fmi-standard repository, tag v2.0.1): what the build makes of fmpy's edited copy
FMI2_FUNCTIONS_H_2_0_1 = "5315e320046c976b3977bc14eb7e2cb58711fa296e4bdf88ddd2c9c82e2a9958"
SCENARIO, SECONDS = "full_pose_with_disturbances", 3.0  # disturbances, attitude and position
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def sources_of(fmu):
    """{file name: bytes} of the FMU's sources/ folder."""
    with zipfile.ZipFile(fmu) as z:
        return {n.split("/", 1)[1]: z.read(n) for n in z.namelist()
                if n.startswith("sources/") and not n.endswith("/")}


@pytest.mark.parametrize("model", FMUS)
def test_sources_list_the_c_files_once_and_hold_nothing_else(model):
    fmu = FMUS[model]()
    files = sources_of(fmu)
    c_files = sorted(n for n in files if n.endswith(".c"))
    md = read_model_description(str(fmu))
    listed = md.buildConfigurations[0].sourceFileSets[0].sourceFiles  # FMI 2 <SourceFiles>
    assert listed == [f"{model}_all.c"]  # the one translation unit
    included = _INCLUDE.findall(files[listed[0]].decode())
    # every other C file, once each (and so: none compiled beside it)
    assert sorted(n for n in included if n.endswith(".c")) == sorted(set(c_files) - set(listed))
    assert len(set(included)) == len(included)
    # the FMI 2.0.4 / 3.0 build description, validated against fmpy's FMI 3 schema
    configs = read_build_description(str(fmu), validate=True)
    assert len(configs) == 1 and configs[0].modelIdentifier == md.coSimulation.modelIdentifier
    (file_set,) = configs[0].sourceFileSets
    assert file_set.language == "C99" and file_set.sourceFiles == listed
    with zipfile.ZipFile(fmu) as z:  # the one library to link: the system's maths library
        root = ET.fromstring(z.read("sources/buildDescription.xml"))
    assert [(lib.get("name"), lib.get("external")) for lib in root.iter("Library")] == [
        ("m", "true")]
    assert all("/" not in n for n in files), "sources/ is flat"
    assert {n for n in files if not n.endswith((".c", ".h"))} == {"buildDescription.xml"}
    # neither the build tools nor the Python host API
    assert not {"mdgen.c", "hover_master.c", "static_master.c", "fp_cosim.c", "fp_api.h"} & set(
        files)


@pytest.mark.parametrize("model", FMUS)
def test_every_header_is_included_and_every_include_is_there(model):
    """The C files' quoted includes, followed transitively, reach every header in sources/
    and only headers in sources/; the FMI headers are fmpy's own, byte for byte, but for
    fmi2Functions.h: the FMI 2.0.1 standard's, which honours FMI2_FUNCTION_PREFIX (fmpy's
    copy ignores it), made from fmpy's by putting back the two blocks it marks as changed."""
    files = sources_of(FMUS[model]())
    seen, todo = set(), [n for n in files if n.endswith(".c")]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for inc in _INCLUDE.findall(files[name].decode()):
            assert inc in files, f"{name} includes {inc}, which sources/ lacks"
            todo.append(inc)
    headers = {n for n in files if n.endswith(".h")}
    assert headers <= seen, f"headers no C file includes: {sorted(headers - seen)}"
    assert FMI_HEADERS <= headers
    c_code = Path(fmpy.__file__).parent / "c-code"
    for h in FMI_HEADERS - {"fmi2Functions.h"}:
        assert files[h] == (c_code / h).read_bytes()
    ours, fmpys = files["fmi2Functions.h"].decode(), (c_code / "fmi2Functions.h").read_text()
    assert hashlib.sha256(ours.encode()).hexdigest() == FMI2_FUNCTIONS_H_2_0_1
    assert "fmi2FullName(name) fmi2PasteB(FMI2_FUNCTION_PREFIX, name)" in ours
    # outside the two blocks fmpy marks, fmpy's text: the declarations are the same
    assert ours[ours.index("/* Version number */"):] == fmpys[fmpys.index("/* Version number */"):]


def one_line_command(model):
    """The documented one-line build of the Linux binary (docs/fmus.md), for ``model``."""
    lines = [ln.strip() for ln in DOC.read_text().splitlines()
             if re.match(r"^\s*cc .* -o binaries/linux64/MultirotorPlant\.so$", ln)]
    assert len(lines) == 1, "docs/fmus.md shows the one-line cc command once"
    return lines[0].replace("MultirotorPlant", model)


def unpack_without_binaries(fmu, dest):
    with zipfile.ZipFile(fmu) as z:
        z.extractall(dest)
    shutil.rmtree(dest / "binaries")
    return dest



def fly(monkeypatch, fmu_dir=None):
    """Every row of the first seconds of a shipped scenario, with the FMUs in ``fmu_dir``
    (None: the installed ones)."""
    if fmu_dir is not None:
        monkeypatch.setenv("FULLPOSE_BUILD_DIR", str(fmu_dir))
        assert plant.plant_fmu().parent == controller.controller_fmu().parent == fmu_dir
    result = run(prepare(SCENARIO, SECONDS), progress=False)
    monkeypatch.delenv("FULLPOSE_BUILD_DIR", raising=False)
    return result.columns, result.data


@pytest.fixture(scope="module")
def shipped_run():
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv("FULLPOSE_BUILD_DIR", raising=False)
        return fly(mp)


def assert_bit_identical(shipped, rebuilt):
    (cols_a, a), (cols_b, b) = shipped, rebuilt
    assert cols_a == cols_b and a.shape == b.shape
    assert a.shape[0] == round(SECONDS / 0.002) + 1
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    bad = [cols_a[j] for j in np.flatnonzero(~same.all(axis=0))]
    assert not bad, f"columns that differ from the shipped binaries' run: {bad[:8]}"


@pytest.mark.skipif(fmpy.platform != "linux64", reason="the rebuild runs on x86_64 Linux")
@pytest.mark.platforms
def test_fmpy_builder_rebuilds_both_fmus_bit_identically(tmp_path, monkeypatch, shipped_run):
    if shutil.which("cmake") is None:
        pytest.fail("cmake is needed by fmpy's platform-binary builder")
    out = tmp_path / "fmus"
    out.mkdir()
    for model, where in FMUS.items():
        unzipped = unpack_without_binaries(where(), tmp_path / model)
        build_dir = tmp_path / f"{model}-build"
        build_dir.mkdir()
        build_platform_binary(unzipped, build_dir=build_dir)
        assert (unzipped / "binaries" / "linux64" / f"{model}.so").is_file()
        rezip(unzipped, out / f"{model}.fmu")
    assert_bit_identical(shipped_run, fly(monkeypatch, out))


@pytest.mark.skipif(fmpy.platform != "linux64", reason="the one-line command is for Linux")
@pytest.mark.platforms
def test_documented_one_line_command_rebuilds_both_fmus_bit_identically(tmp_path, monkeypatch,
                                                                         shipped_run):
    out = tmp_path / "fmus"
    out.mkdir()
    for model, where in FMUS.items():
        unzipped = unpack_without_binaries(where(), tmp_path / model)
        (unzipped / "binaries" / "linux64").mkdir(parents=True)
        res = subprocess.run(one_line_command(model), shell=True, cwd=unzipped,
                             capture_output=True, text=True, check=False)
        assert res.returncode == 0, res.stderr
        rezip(unzipped, out / f"{model}.fmu")
    assert_bit_identical(shipped_run, fly(monkeypatch, out))
