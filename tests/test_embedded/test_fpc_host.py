"""fpc.h's typed API (FpcInputs in, FpcOutputs out: what a firmware calls) built for this host
from the embedded project and replayed on a closed loop the controller FMU flew: every
sample's commands equal the FMU's to the bit (the same sources, compiler family and libm,
so nothing may differ), the structs' layout equal to fpc.h's.  Needs cmake and a C compiler
only (no Arm tools)."""

from __future__ import annotations

import ctypes
import shutil
import subprocess

import numpy as np
import pytest
from fmpy import read_model_description

from controller import controller_fmu
from orchestrator.master import CoSimulation
from orchestrator.pil.build import project_dir
from orchestrator.runner import prepare

pytestmark = [pytest.mark.heavy, pytest.mark.skipif(
    shutil.which("cmake") is None or shutil.which("cc") is None,
    reason="cmake and a C compiler build the host library")]

R = 8  # FPC_MAX_ROTORS
_IN = [("pos_ref", 3), ("euler_ref", 3), ("vel_ref", 3), ("acc_ref", 3), ("euler_rate_ref", 3),
       ("rotor_health", R), ("pos", 3), ("vel", 3), ("acc", 3), ("euler", 3), ("rate", 3),
       ("omega", R), ("alpha", R), ("beta", R)]


class FpcInputs(ctypes.Structure):
    _fields_ = [(n, ctypes.c_double * k) for n, k in _IN] + [
        ("pose_age", ctypes.c_double), ("armed", ctypes.c_int32)]


class FpcOutputs(ctypes.Structure):
    _fields_ = [(n, ctypes.c_double * k) for n, k in (
        ("omega_cmd", R), ("alpha_cmd", R), ("beta_cmd", R), ("mu_c", 3), ("f_b_ref", 3))] + [
        (n, ctypes.c_int32) for n in ("feasible", "guid_status", "alloc_status", "rotors_lost",
                                      "landed", "idle")]


SHIM = """
#include "fpc.h"
double fp_clock_seconds(void) { return 0.0; }
size_t fpc_host_sizes(size_t *in, size_t *out) {
    *in = sizeof(FpcInputs); *out = sizeof(FpcOutputs); return sizeof(FpcController);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    work = tmp_path_factory.mktemp("fpc_host")
    build = work / "build"
    subprocess.run(["cmake", "-S", str(project_dir()), "-B", str(build), "-DFPC_PIL=OFF",
                    "-DFPC_CPU_FLAGS=-fPIC", "-DFULLPOSE_WERROR=ON"], check=True,
                   capture_output=True)
    subprocess.run(["cmake", "--build", str(build)], check=True, capture_output=True)
    (work / "shim.c").write_text(SHIM)
    so = work / "libfpc_host.so"
    subprocess.run(["cc", "-shared", "-fPIC", "-O2", f"-I{project_dir()}",
                    f"-I{project_dir().parent / 'common'}",
                    f"-I{project_dir().parent / 'controller'}", str(work / "shim.c"),
                    "-Wl,--whole-archive", str(build / "libfpc.a"), "-Wl,--no-whole-archive",
                    "-lm", "-o", str(so)], check=True, capture_output=True)
    return ctypes.CDLL(str(so))


def _controller(lib: ctypes.CDLL) -> ctypes.Array[ctypes.c_char]:
    size_in, size_out = ctypes.c_size_t(), ctypes.c_size_t()
    lib.fpc_host_sizes.restype = ctypes.c_size_t
    size = lib.fpc_host_sizes(ctypes.byref(size_in), ctypes.byref(size_out))
    assert (size_in.value, size_out.value) == (ctypes.sizeof(FpcInputs),
                                               ctypes.sizeof(FpcOutputs))
    buf = ctypes.create_string_buffer(size + 16)
    return buf


@pytest.mark.parametrize("name, airframe", [("hover_varying_orientation", None),
                                            ("rotor_failure_hover", "x8_coaxial")])
def test_the_typed_api_commands_what_the_fmu_commands(lib: ctypes.CDLL, name: str,
                                                      airframe: str | None) -> None:
    sc = prepare(name, 3.0, airframe=airframe)
    sim = CoSimulation(sc)
    run = sim.run()
    cols = list(run.columns)
    data = np.asarray(run.data)
    n = sc.airframe.n_rotors
    md = read_model_description(str(controller_fmu()))
    var = {v.name: v for v in md.modelVariables}

    ctrl = _controller(lib)
    ok = 0
    assert lib.fpc_defaults(ctrl, None, None) == ok
    start = sim.start_values().controller
    for kind, setter, conv in (("Real", lib.fpc_set_reals_vr, ctypes.c_double),
                               ("int", lib.fpc_set_ints_vr, ctypes.c_int32)):
        names = [k for k in start if (var[k].type == "Real") == (kind == "Real")]
        refs = (ctypes.c_uint32 * len(names))(*[var[k].valueReference for k in names])
        vals = (conv * len(names))(*[start[k] for k in names])
        assert setter(ctrl, refs, len(names), vals) == ok

    def inputs(k: int) -> FpcInputs:
        x = FpcInputs()
        for field, size in _IN:  # the unused rotors' elements as the FMU holds them
            refs = (ctypes.c_uint32 * size)(*[var[f"{field}[{i + 1}]"].valueReference
                                              for i in range(size)])
            assert lib.fpc_get_reals_vr(ctrl, refs, size, getattr(x, field)) == ok
            prefix = "ref." if field.endswith("_ref") or field == "rotor_health" else "plant."
            for i in range(size if size == 3 else n):
                getattr(x, field)[i] = data[k, cols.index(f"{prefix}{field}[{i + 1}]")]
        x.pose_age = data[k, cols.index("plant.pose_age")]
        x.armed = 1
        return x

    lib.fpc_start.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_void_p]
    lib.fpc_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_void_p, ctypes.c_void_p]
    assert lib.fpc_start(ctrl, 0.0, ctypes.byref(inputs(0))) in (0, 1)
    out = FpcOutputs()
    got, want = [], []
    commands = [cols.index(f"ctrl.{c}[{i + 1}]") for c in ("omega_cmd", "alpha_cmd", "beta_cmd")
                for i in range(n)] + [cols.index(f"ctrl.mu_c[{i}]") for i in (1, 2, 3)]
    for k in range(len(data) - 1):
        assert lib.fpc_step(ctrl, k * sc.step, ctypes.byref(inputs(k)), ctypes.byref(out)) in (0, 1)
        got.append(list(out.omega_cmd[:n]) + list(out.alpha_cmd[:n]) + list(out.beta_cmd[:n])
                   + list(out.mu_c))
        want.append(data[k, commands])
    assert np.array_equal(np.array(got), np.array(want))
