"""The controller's C core cross-built for a Cortex-M7 and flown in the loop under QEMU.

Oracles: the controller FMU (the same sources on the host: positions within 1e-9 m, the
issue's bound, and commands within what the libm differences below explain), the host's
glibc libm through Python's math (newlib's and glibc's functions may differ by at most one
unit in the last place: each is within one ulp of the exact result), arm-none-eabi-nm (what
the library links against) and the target's own counters (heap, text formatting).
"""

from __future__ import annotations

import math
import shutil
import struct
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from orchestrator.master import CoSimulation
from orchestrator.pil.build import EmbeddedBuild, build_embedded, missing_tools
from orchestrator.pil.target import FP_ERROR, FP_OK, LIBM, PilTarget
from orchestrator.runner import prepare

pytestmark = pytest.mark.embedded

MISSING = missing_tools()
needs_tools = pytest.mark.skipif(
    bool(MISSING),
    reason=f"{', '.join(MISSING)} absent: bash tests/tools/install_embedded_tools.sh")

# What the controller may call of the C library: libm, memory and string functions, and text
# formatting for its messages; nothing that allocates, does I/O or reads the clock.
ALLOWED = {"acos", "asin", "atan2", "cos", "sin", "tan", "fmod", "frexp", "hypot", "ldexp",
           "nextafter", "memcmp", "memcpy", "memmove", "memset", "strcmp", "strlen", "snprintf",
           "vsnprintf", "strtod"}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> EmbeddedBuild:
    return build_embedded(tmp_path_factory.mktemp("m7"), werror=True)


@pytest.fixture()
def target(built: EmbeddedBuild) -> Iterator[PilTarget]:
    with PilTarget(built.elf) as t:
        yield t


@needs_tools
def test_the_library_calls_libm_and_no_heap_io_or_clock(built: EmbeddedBuild) -> None:
    out = subprocess.run(["arm-none-eabi-nm", "-u", str(built.library)], capture_output=True,
                         text=True, check=True).stdout
    defined = subprocess.run(["arm-none-eabi-nm", "--defined-only", str(built.library)],
                             capture_output=True, text=True, check=True).stdout
    ours = {line.split()[-1] for line in defined.splitlines() if len(line.split()) == 3}
    used = {line.split()[-1] for line in out.splitlines() if line.strip().startswith("U ")}
    external = {s for s in used - ours if not s.startswith("__aeabi_")}  # (compiler runtime)
    assert external - ALLOWED == {"fp_clock_seconds"}  # the board's clock (fpc.h)
    # no mutable or initialized static data: every instance lives in its FpcController
    assert built.library_ram == 0
    assert built.memory.flash < 2 * 1024 * 1024 and built.memory.ram <= 512 * 1024


@needs_tools
def test_the_image_is_the_fmus_model(target: PilTarget) -> None:
    from fmpy import read_model_description

    from controller import controller_fmu

    assert target.hello() == read_model_description(str(controller_fmu())).guid


@needs_tools
def test_newlib_libm_within_one_ulp_of_glibc(target: PilTarget) -> None:
    rng = np.random.default_rng(37)
    for name in LIBM:
        if name in ("asin", "acos"):
            x, y = rng.uniform(-1.0, 1.0, 1000), None
        elif name in ("atan2", "hypot"):
            x, y = rng.uniform(-20.0, 20.0, 1000), rng.uniform(-20.0, 20.0, 1000)
        else:
            x, y = rng.uniform(-4 * math.pi, 4 * math.pi, 1000), None
        got = target.libm(name, x, y)
        fn = getattr(math, name)
        want = np.array([fn(a, b) for a, b in zip(x, y, strict=True)] if y is not None
                        else [fn(a) for a in x])
        ulps = np.abs(got - want) / np.spacing(np.abs(want))
        assert ulps.max() <= 1.0, name


def _pil_vs_fmu(elf: Path, name: str, duration: float,
                airframe: str | None = None) -> tuple[np.ndarray, np.ndarray, list[str], dict]:
    sc = prepare(name, duration, airframe=airframe)
    fmu = CoSimulation(sc).run()
    pil = CoSimulation(sc, pil=elf).run()
    assert pil.meta["outcome"] == fmu.meta["outcome"] == {"outcome": "completed"}
    return np.asarray(pil.data), np.asarray(fmu.data), list(pil.columns), pil.meta


def _positions(cols: list[str]) -> list[int]:
    return [cols.index(f"plant.pos[{k}]") for k in (1, 2, 3)]


@needs_tools
def test_pil_hover_flies_as_the_fmu(built: EmbeddedBuild) -> None:
    data, ref, cols, meta = _pil_vs_fmu(built.elf, "hover_varying_orientation", 2.0)
    pos = _positions(cols)
    assert np.abs(data[:, pos] - ref[:, pos]).max() <= 1e-9
    cmd = [i for i, c in enumerate(cols) if c.startswith(("ctrl.omega_cmd", "ctrl.alpha_cmd",
                                                          "ctrl.beta_cmd"))]
    # one-ulp libm differences through the filters and QPs: far below anything physical
    assert np.abs(data[:, cmd] - ref[:, cmd]).max() <= 1e-6
    on = meta["controller_on"]
    assert on["samples"] == 1001
    # the sample path allocates nothing and formats no text; a sample's stack fits a DTCM
    assert on["heap_bytes_in_samples"] == 0 and on["format_calls_in_samples"] == 0
    assert 0 < on["stack_bytes"] < 128 * 1024
    assert 0 < on["instructions"]["mean"] <= on["instructions"]["max"]


@needs_tools
def test_pil_flies_the_x8_as_the_fmu(built: EmbeddedBuild) -> None:
    data, ref, cols, _ = _pil_vs_fmu(built.elf, "hover_varying_orientation", 1.0,
                                     airframe="x8_coaxial")
    pos = _positions(cols)
    assert np.abs(data[:, pos] - ref[:, pos]).max() <= 1e-9


@needs_tools
def test_refusals_name_the_reason_and_keep_the_controller(target: PilTarget) -> None:
    assert target.defaults().status == FP_OK
    bad = target.set_ints([1], [2])  # Ts is a Real
    assert bad.status == FP_ERROR and "Ts" in bad.text and "Real" in bad.text
    assert target.set_reals([999999], [1.0]).status == FP_ERROR
    assert target.start(0.0).status == FP_OK
    late = target.set_reals([1], [0.004])  # a fixed parameter after the start
    assert late.status == FP_ERROR and "fixed parameter" in late.text
    _, ts = target.get_reals([1])
    assert ts[0] == 0.002
    none = struct.pack("<I", 0)
    off = target.sample(0.001, none, np.zeros(0), none, none)
    assert off.status == FP_ERROR and "due" in off.text
    ok = target.sample(0.0, none, np.zeros(0), none, none)
    assert ok.status in (FP_OK, 1)


@needs_tools
def test_cli_runs_the_controller_on_the_target(built: EmbeddedBuild, tmp_path: Path) -> None:
    fullpose = shutil.which("fullpose")
    assert fullpose is not None
    done = subprocess.run([fullpose, "run", "hover", "--duration", "0.5", "--pil", str(built.elf),
                           "--out", str(tmp_path / "r"), "--no-plots"], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr
    assert "instructions per sample" in done.stdout
    missing = subprocess.run([fullpose, "run", "hover", "--pil", str(tmp_path / "none.elf"),
                              "--out", str(tmp_path / "s")], capture_output=True, text=True)
    assert missing.returncode == 2 and "no such controller image" in missing.stderr
    assert "Traceback" not in missing.stderr and not (tmp_path / "s").exists()


@needs_tools
def test_every_libm_call_of_a_flight_within_one_ulp_of_the_hosts(built: EmbeddedBuild) -> None:
    from orchestrator.pil.instance import PilController
    from orchestrator.sim.fmu3 import open_fmu
    from plant import plant_fmu

    sc = prepare("hover_varying_orientation", 1.0)
    plant = open_fmu(plant_fmu(2), "plant")
    ctrl = PilController(built.trace_elf, trace_libm=True)
    try:
        CoSimulation(sc, fmus=(plant, ctrl)).run()
    finally:
        plant.close()
        ctrl.close()
    calls = np.concatenate(ctrl.libm_calls)
    assert ctrl.libm_dropped == 0
    seen = {LIBM[int(f)] for f in calls[:, 0]}
    assert {"sin", "cos", "atan2", "asin"} <= seen  # the attitude's trigonometry, every sample
    for f, x, y, r in calls:
        name = LIBM[int(f)]
        want = getattr(math, name)(x, y) if name in ("atan2", "hypot") else getattr(math, name)(x)
        assert abs(r - want) <= np.spacing(abs(want)), (name, x, y)


@needs_tools
def test_instruction_counting_is_exact_on_a_loop_of_known_length(target: PilTarget) -> None:
    # subs + bne per turn: the count grows by exactly 2 per turn (to the timer's 0.625 of an
    # instruction), whatever the fixed cost of the reads
    a, b, c = (target.calibrate(n) for n in (1_000, 11_000, 101_000))
    assert abs((b - a) - 20_000) <= 1.0 and abs((c - a) - 200_000) <= 1.0
    assert 2_000 <= a <= 2_020


@needs_tools
def test_a_target_that_dies_mid_run_fails_the_run_with_the_reason(built: EmbeddedBuild) -> None:
    from orchestrator.pil.instance import PilController
    from orchestrator.sim.engine import RunError
    from orchestrator.sim.fmu3 import open_fmu
    from plant import plant_fmu

    plant = open_fmu(plant_fmu(2), "plant")
    ctrl = PilController(built.elf)

    def kill(first: int, last: int) -> None:
        if last > 100:
            ctrl.target.proc.kill()

    try:
        with pytest.raises(RunError, match="stopped answering: QEMU exited with code -9"):
            CoSimulation(prepare("hover", 2.0), fmus=(plant, ctrl)).run(on_chunk=kill)
    finally:
        plant.close()
        ctrl.close()
