"""The built binaries keep the C rules: FMI entry points only, no mutable globals.

Oracles are binutils (nm, objdump) reading the shipped FMU binary itself.
"""

import re
import shutil
import subprocess
import zipfile

import pytest

import plant
from plant.common.artifacts import library_path

FMI2_CS_FUNCTIONS = {
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate",
    "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset", "fmi2GetReal", "fmi2GetInteger",
    "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean",
    "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives",
    "fmi2GetRealOutputDerivatives", "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus",
    "fmi2GetRealStatus", "fmi2GetIntegerStatus", "fmi2GetBooleanStatus", "fmi2GetStringStatus",
}
# The plant is a Model Exchange FMU too (one archive, both interfaces): it exports these as well.
FMI2_ME_FUNCTIONS = {
    "fmi2EnterEventMode", "fmi2NewDiscreteStates", "fmi2EnterContinuousTimeMode",
    "fmi2CompletedIntegratorStep", "fmi2SetTime", "fmi2SetContinuousStates",
    "fmi2GetDerivatives", "fmi2GetEventIndicators", "fmi2GetContinuousStates",
    "fmi2GetNominalsOfContinuousStates",
}
# Objects the C runtime itself places in writable sections of every shared library.
CRT_OBJECTS = {"completed.0", "__dso_handle", "__TMC_END__"}


def tool(name):
    path = shutil.which(name)
    if path is None:
        pytest.fail(f"{name} (binutils) is needed to inspect the binaries")
    return path


@pytest.fixture(scope="module")
def plant_binary(tmp_path_factory):
    out = tmp_path_factory.mktemp("plantbin")
    with zipfile.ZipFile(plant.plant_fmu()) as z:
        name = next(n for n in z.namelist() if n.startswith("binaries/") and n.endswith(".so"))
        return z.extract(name, out)


def writable_objects(binary):
    out = subprocess.run([tool("objdump"), "-t", binary], capture_output=True, text=True,
                         check=True).stdout
    found = set()
    for line in out.splitlines():
        m = re.match(r"^[0-9a-f]+ .{7} (\.data|\.bss)\s+[0-9a-f]+\s+(\S+)$", line)
        if m:
            found.add(m.group(2))
    return found - CRT_OBJECTS


def test_fmu_exports_exactly_the_fmi2_cs_and_me_api(plant_binary):
    out = subprocess.run([tool("nm"), "-D", "--defined-only", plant_binary], capture_output=True,
                         text=True, check=True).stdout
    exported = {line.split()[-1] for line in out.splitlines() if line.strip()}
    assert exported == FMI2_CS_FUNCTIONS | FMI2_ME_FUNCTIONS


# The host-API libraries, each in the package that calls it.
HOST_LIBRARIES = [("plant", "fp_multirotor"), ("controller", "fp_controller"),
                  ("orchestrator", "fp_cosim")]


def test_no_mutable_globals(plant_binary):
    assert writable_objects(plant_binary) == set()
    for package, stem in HOST_LIBRARIES:
        assert writable_objects(str(library_path(package, stem))) == set(), stem
