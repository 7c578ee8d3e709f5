"""The closed loop at communication steps other than the controller's Ts = 2 ms.

Both FMUs accept any step h > 0 (docs/plant.md and docs/controller.md, "Communication
steps"): the plant integrates h in ceil(h / h_internal) equal RK4 steps, the controller
samples its own grid k Ts with the inputs held since the last communication point.  Each case
runs a shipped scenario through the orchestrator's master (fmpy-loaded FMU archives, the C
step kernel) at step h and compares it with the same scenario at 2 ms, at the instants both
share.  The scenario files only take multiples of Ts (orchestrator.scenario.checks), so
the step is replaced on the loaded scenario.

Bounds, from requirements and a delay argument rather than from the measurements:

* h dividing Ts (1 ms, 0.5 ms): every sample sees exactly the inputs of its grid instant and
  the plant takes the same 0.5 ms RK4 steps with the same held commands: bit-identical.
* any other h: an input change (a reference step, a measurement) reaches the controller at
  the first communication point after it and a sample at the first grid instant after that,
  so at most ceil(h / Ts) samples later than in the 2 ms loop.  To first order a loop's
  deviation grows linearly with its delay.  A late input is a late measurement or a late
  reference.  The loop with exactly one sample of delay in its feedback is the Jacobi
  coupling at 2 ms (commands one sample late), measured here on the same scenario.  A
  reference one sample late moves the whole response one sample later (the loop is time
  invariant; the scenarios start at rest): its deviation is the 2 ms loop's largest motion
  in one sample, which a shaped 1 m step makes larger than the feedback delay's.  Bound:
  ceil(h / Ts) times the sum of the two, in position and in attitude, where mu_ref is
  feasible.  Where it is not, the guidance QP sits on the feasible-force set's boundary and
  trades attitude against force through its active set: a non-smooth map that no linear
  delay argument bounds (a 0.3 ms difference moves mu_c by 0.3 deg there), so those rows
  are held to the requirement below.
* the controller carries inputs set before its sample instant forward over their age (the
  reference by its derivatives, the pose by the measured rates), so a smooth reference
  arrives smooth and not as a staircase of jumps for the reference shaping.
* whatever h: within the paper's 2 cm position accuracy of the 2 ms loop, and in scenario 1
  the loop still tracks within 2 cm.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from orchestrator.master import run
from orchestrator.output.run_result import RunResult
from orchestrator.scenario.catalogue import load_scenario
from orchestrator.scenario.model import Scenario

TS = 0.002
ACCURACY = 0.02  # m: the paper's position accuracy
COARSE = "longer than the sample time"
CASES = {"position_step": 5.0, "hover_varying_orientation": 10.0}  # scenario: seconds


def _columns(r: RunResult, name: str) -> np.ndarray:
    first = r.columns.index(f"{name}[1]")
    n = sum(1 for c in r.columns if c.startswith(f"{name}["))
    return r.data[:, first:first + n]


def _common_rows(r: RunResult, ref: RunResult) -> tuple[np.ndarray, np.ndarray]:
    """Rows of r and of the 2 ms reference at the same instants k Ts."""
    t = r.data[:, 0]
    k = np.round(t / TS)
    on = (np.abs(t - k * TS) < 1e-9) & (k < ref.data.shape[0])
    return np.nonzero(on)[0], k[on].astype(int)


def deviation(r: RunResult, ref: RunResult, feasible_only: bool = False) -> tuple[float, float]:
    """(max position deviation in m, max attitude deviation in rad) of r from ref, on the
    rows where ref's mu_ref is feasible if feasible_only."""
    a, b = _common_rows(r, ref)
    if feasible_only:
        keep = ref.get("ctrl.feasible")[b] > 0.5
        a, b = a[keep], b[keep]
    assert a.size > 100
    dp = np.linalg.norm(_columns(r, "plant.pos")[a] - _columns(ref, "plant.pos")[b], axis=1)
    dot = np.abs(np.sum(_columns(r, "plant.quat")[a] * _columns(ref, "plant.quat")[b], axis=1))
    return float(dp.max()), float(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)).max())


def motion_in_one_sample(r: RunResult) -> tuple[float, float]:
    """(largest position change in m, largest attitude change in rad) from one 2 ms sample
    to the next: the deviation of the same flight one sample later."""
    dp = np.linalg.norm(np.diff(_columns(r, "plant.pos"), axis=0), axis=1)
    q = _columns(r, "plant.quat")
    dot = np.abs(np.sum(q[1:] * q[:-1], axis=1))
    return float(dp.max()), float(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)).max())


def tracking_error(r: RunResult) -> float:
    return float(np.max(np.linalg.norm(_columns(r, "plant.pos") - _columns(r, "ref.pos_ref"),
                                       axis=1)))


class Reference:
    def __init__(self, name: str) -> None:
        self.scenario: Scenario = replace(load_scenario(name), duration=CASES[name])
        self.gs = run(self.scenario, progress=False)
        self.delayed = run(replace(self.scenario, coupling="jacobi"), progress=False)
        late_feedback = deviation(self.delayed, self.gs, feasible_only=True)
        late_reference = motion_in_one_sample(self.gs)
        self.one_sample = (late_feedback[0] + late_reference[0],
                           late_feedback[1] + late_reference[1])

    def at(self, h: float) -> RunResult:
        return run(replace(self.scenario, step=h), progress=False)


@pytest.fixture(scope="module")
def references() -> dict[str, Reference]:
    return {name: Reference(name) for name in CASES}


def _coarse_warnings(r: RunResult) -> list[str]:
    return [m for m in r.meta["first_warnings"] if COARSE in m]


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("h", [0.001, 0.0005])
def test_steps_dividing_ts_fly_bit_identically(references, name, h):
    ref = references[name]
    r = ref.at(h)
    a, b = _common_rows(r, ref.gs)
    assert b.size == ref.gs.data.shape[0]  # every 2 ms instant
    assert r.columns == ref.gs.columns
    np.testing.assert_array_equal(r.data[a, 1:], ref.gs.data[b, 1:])
    assert r.meta["warnings"] == ref.gs.meta["warnings"]
    assert not _coarse_warnings(r)


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("h", [0.0007, 0.0025, 0.003, 0.01, 0.02])
def test_any_step_stays_within_its_delay_of_the_2ms_loop(references, record_property, name,
                                                         h):
    ref = references[name]
    r = ref.at(h)
    assert r.meta["outcome"]["outcome"] == "completed"
    dp, da = deviation(r, ref.gs, feasible_only=True)
    one_p, one_a = ref.one_sample
    late = math.ceil(h / TS - 1e-9)  # samples an input change may come late
    record_property("max_position_deviation_mm", dp * 1e3)
    record_property("max_attitude_deviation_deg", math.degrees(da))
    record_property("one_sample_delay_mm_deg", (one_p * 1e3, math.degrees(one_a)))
    assert dp <= late * one_p, (dp, one_p)
    assert da <= late * one_a, (da, one_a)
    assert deviation(r, ref.gs)[0] <= ACCURACY  # every row, feasible or not
    if name == "hover_varying_orientation":
        assert tracking_error(ref.gs) < ACCURACY  # the 2 ms loop meets it (11.5 mm)
        assert tracking_error(r) < ACCURACY
    # h > Ts: the controller says once that held measurements degrade control
    extra = r.meta["warnings"] - ref.gs.meta["warnings"]
    assert extra == (1 if h > TS else 0), r.meta["first_warnings"]
    assert len(_coarse_warnings(r)) == extra
