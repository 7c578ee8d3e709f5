"""Step metrics and the errors against the flown reference: synthetic runs whose answers are
known in closed form, then the real FMUs on the shipped ``position_step``."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from helpers import cli

from orchestrator.master import run
from orchestrator.output.metrics import compare_with_paper, compute_metrics
from orchestrator.output.run_result import RunResult
from orchestrator.output.step_metrics import MAX_STEPS, step_line, step_metrics
from orchestrator.runner import prepare

STEP = 0.002
G = 9.81  # m/s^2, the plant's gravity
WIDTH = {"ref.pos_ref": 3, "ref.vel_ref": 3, "ref.euler_ref": 3, "ref.euler_rate_ref": 3,
         "plant.pos": 3, "plant.euler": 3, "ctrl.pos_ref_s": 3, "ctrl.euler_ref_s": 3,
         "ctrl.ref_acc_limit": 2}


def times(duration: float) -> np.ndarray:
    return np.arange(round(duration / STEP) + 1) * STEP


def synthetic(t: np.ndarray, **signals: np.ndarray) -> RunResult:
    """A run of the given signals (keyword: group name with '.' -> '__'); the setpoint is at
    rest at [0, 0, -3] and level unless given, and the vehicle on it."""
    n = len(t)
    hover = np.tile([0.0, 0.0, -3.0], (n, 1))
    given = {k.replace("__", "."): np.asarray(v, dtype=float).reshape(n, -1)
             for k, v in signals.items()}
    given.setdefault("ref.pos_ref", hover)
    given.setdefault("ref.euler_ref", np.zeros((n, 3)))
    given.setdefault("plant.pos", given["ref.pos_ref"])
    given.setdefault("plant.euler", given["ref.euler_ref"])
    columns, blocks = ["time"], [t[:, None]]
    for name, value in given.items():
        assert value.shape[1] == WIDTH[name], name
        columns += [f"{name}[{i + 1}]" for i in range(value.shape[1])]
        blocks.append(value)
    return RunResult(columns, np.hstack(blocks), {"step": STEP, "n_rotors": 6})


def first_order(t: np.ndarray, t0: float, tau: float) -> np.ndarray:
    """0 before t0, then 1 - exp(-(t - t0)/tau)."""
    return np.where(t >= t0, -np.expm1(-np.maximum(t - t0, 0.0) / tau), 0.0)


def second_order(t: np.ndarray, t0: float, zeta: float, wn: float) -> np.ndarray:
    """The unit step response of wn^2 / (s^2 + 2 zeta wn s + wn^2) from t0."""
    s = np.maximum(t - t0, 0.0)
    wd = wn * math.sqrt(1 - zeta**2)
    y = 1 - np.exp(-zeta * wn * s) * (np.cos(wd * s) + zeta / math.sqrt(1 - zeta**2)
                                      * np.sin(wd * s))
    return np.where(t >= t0, y, 0.0)


def bump(t: np.ndarray, t0: float, tau: float) -> np.ndarray:
    """s e^(1 - s), s = (t - t0)/tau: 0 before t0, 1 at t0 + tau (its peak), back to 0."""
    s = np.maximum(t - t0, 0.0) / tau
    return s * np.exp(1 - s)


def step_setpoint(t: np.ndarray, t0: float, jump: tuple[float, float, float],
                  start: tuple[float, float, float] = (0.0, 0.0, -3.0)) -> np.ndarray:
    return np.asarray(start) + np.outer(t >= t0, jump)


def only_step(result: RunResult) -> dict:
    steps = compute_metrics(result)["steps"]
    assert len(steps) == 1, steps
    return steps[0]


def assert_settles_at(settle: float | None, expected: float) -> None:
    """settle is the first sample at or after the analytic time."""
    assert settle is not None
    assert expected - 1e-9 <= settle < expected + STEP + 1e-9, (settle, expected)


# ---------------------------------------------------------------------------
# synthetic runs


def test_first_order_step_settles_at_tau_ln_size_over_band():
    """x = L (1 - exp(-t/tau)) is within 1 cm of L from tau ln(L / 1 cm) on; the polytope
    bound of L = 2 m at 2 m/s^2 is 2 sqrt(L/a) = 2 s."""
    t, t0, L, tau = times(6.0), 1.0, 2.0, 0.25
    ref = step_setpoint(t, t0, (L, 0.0, 0.0))
    pos = ref.copy()
    pos[:, 0] = L * first_order(t, t0, tau)
    s = only_step(synthetic(t, ref__pos_ref=ref, plant__pos=pos,
                            ctrl__ref_acc_limit=np.tile([2.0, 4.0], (len(t), 1))))
    assert s["kind"] == "position" and s["time"] == pytest.approx(t0)
    assert s["end"] == pytest.approx(t[-1])
    assert s["jump"] == [L, 0.0, 0.0] and s["size"] == L and s["band"] == 0.01
    assert_settles_at(s["settle_time"], tau * math.log(L / 0.01))
    assert s["overshoot"] == 0.0 and s["peak_tilt"] == 0.0
    assert s["sag"] == 0.0 and s["sag_of"] == "altitude"
    assert s["acc_limit"] == [2.0, 4.0] and s["bound"] == pytest.approx(2.0, rel=1e-15)
    assert s["bound_ratio"] == pytest.approx(s["settle_time"] / 2.0, rel=1e-15)
    assert step_line(s) == (
        f"step x +2.000 m at 1.000 s: within 1 cm after {s['settle_time']:.3f} s (0.66x 2 "
        "sqrt(L/a_max) = 2.000 s), overshoot 0.0 mm, peak tilt 0.0 deg, sag 0.0 mm (altitude)")


def test_errors_are_against_the_flown_reference_else_the_given_one():
    """A vehicle 3 mm below the shaped reference of a 2 m step: 3 mm of error against it; in
    results without the shaped columns, against the step itself."""
    t, t0 = times(4.0), 1.0
    ref = step_setpoint(t, t0, (2.0, 0.0, 0.0))
    shaped = ref.copy()
    shaped[:, 0] = 2.0 * first_order(t, t0, 0.3)
    euler_ref = np.zeros((len(t), 3))
    euler_ref[:, 2] = np.where(t >= t0, 1.0, 0.0)
    euler_shaped = euler_ref.copy()
    euler_shaped[:, 2] = first_order(t, t0, 0.3)
    euler = euler_shaped + np.radians([0.0, 0.0, 0.25])
    signals = {"ref__pos_ref": ref, "plant__pos": shaped + np.array([0.0, 0.0, 0.003]),
               "ref__euler_ref": euler_ref, "plant__euler": euler}
    m = compute_metrics(synthetic(t, ctrl__pos_ref_s=shaped, ctrl__euler_ref_s=euler_shaped,
                                  **signals))
    assert m["errors_against"] == {"position": "ctrl.pos_ref_s", "attitude": "ctrl.euler_ref_s"}
    assert m["position_error"]["max"] == pytest.approx(0.003, rel=1e-9)
    assert m["position_error"]["x"]["max"] == 0.0
    assert m["attitude_error_vs_mu_ref"]["max"] == pytest.approx(0.25, rel=1e-9)
    given = compute_metrics(synthetic(t, **signals))
    assert given["errors_against"] == {"position": "ref.pos_ref", "attitude": "ref.euler_ref"}
    assert given["position_error"]["x"]["max"] == pytest.approx(2.0)
    assert given["attitude_error_vs_mu_ref"]["psi"]["max"] == pytest.approx(
        math.degrees(1.0) - 0.25)
    assert [s["kind"] for s in m["steps"]] == ["position", "attitude"]


def test_underdamped_step_overshoot_tilt_and_sag():
    """A -0.5 m y step flown as a second-order response with zeta 0.5 overshoots by
    L exp(-pi zeta / sqrt(1 - zeta^2)); roll and pitch peaking together at phi_m, theta_m
    tilt by arccos(cos phi_m cos theta_m); the altitude dips by 4 cm."""
    t, t0, L, zeta, wn = times(5.0), 0.5, 0.5, 0.5, 4.0
    ref = step_setpoint(t, t0, (0.0, -L, 0.0))
    pos = ref.copy()
    pos[:, 1] = -L * second_order(t, t0, zeta, wn)
    pos[:, 2] += 0.04 * bump(t, t0, 0.3)
    phi_m, theta_m = 0.3, -0.2
    euler = np.outer(bump(t, t0, 0.3), [phi_m, theta_m, 0.0])
    s = only_step(synthetic(t, ref__pos_ref=ref, plant__pos=pos, plant__euler=euler))
    assert s["jump"] == [0.0, -L, 0.0]
    assert s["overshoot"] == pytest.approx(L * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)),
                                           rel=1e-4)
    assert s["peak_tilt"] == pytest.approx(
        math.degrees(math.acos(math.cos(phi_m) * math.cos(theta_m))), rel=1e-12)
    assert s["sag"] == pytest.approx(0.04, rel=1e-12) and s["sag_of"] == "altitude"
    assert s["acc_limit"] is None and s["bound"] is None and s["bound_ratio"] is None
    assert "overshoot 81.5 mm" in step_line(s) and "sag 40.0 mm (altitude)" in step_line(s)


def test_vertical_step_sags_horizontally():
    """A 2 m climb (NED z -3 -> -5) with x and y bumps of 3 and 4 cm at the same time: a
    horizontal deviation of 5 cm; its bound 2 sqrt(2 m / 4 m/s^2)."""
    t, t0 = times(4.0), 1.0
    ref = step_setpoint(t, t0, (0.0, 0.0, -2.0))
    pos = ref.copy()
    pos[:, 2] = -3.0 - 2.0 * first_order(t, t0, 0.2)
    pos[:, 0] += 0.03 * bump(t, t0, 0.4)
    pos[:, 1] += 0.04 * bump(t, t0, 0.4)
    s = only_step(synthetic(t, ref__pos_ref=ref, plant__pos=pos,
                            ctrl__ref_acc_limit=np.tile([2.0, 4.0], (len(t), 1))))
    assert s["sag"] == pytest.approx(0.05, rel=1e-12) and s["sag_of"] == "horizontal position"
    assert s["bound"] == pytest.approx(2.0 * math.sqrt(0.5), rel=1e-15)
    assert step_line(s).startswith("step z -2.000 m at 1.000 s: within 1 cm after ")


@pytest.mark.parametrize(("before", "after"), [(3.0, -3.0), (0.0, 4.0)])
def test_heading_step_is_the_wrapped_jump(before, after):
    """A heading step is flown the short way round: 3 -> -3 rad is +0.283 rad, 0 -> 4 rad is
    -2.283 rad; within 1 deg after tau ln(|jump| / 1 deg), the position untouched."""
    t, t0, tau = times(5.0), 1.0, 0.3
    jump = (after - before + math.pi) % (2 * math.pi) - math.pi
    euler_ref = np.zeros((len(t), 3))
    euler_ref[:, 2] = np.where(t >= t0, after, before)
    euler = np.zeros((len(t), 3))
    euler[:, 2] = before + jump * first_order(t, t0, tau)
    s = only_step(synthetic(t, ref__euler_ref=euler_ref, plant__euler=euler))
    assert s["kind"] == "attitude" and s["band"] == 1.0
    assert s["jump"] == [0.0, 0.0, pytest.approx(jump, abs=1e-12)]
    assert s["size"] == pytest.approx(abs(jump), abs=1e-12)
    assert_settles_at(s["settle_time"], tau * math.log(math.degrees(abs(jump))))
    assert s["overshoot"] == pytest.approx(0.0, abs=1e-9) and s["peak_tilt"] == 0.0
    assert s["sag"] == 0.0 and s["sag_of"] == "position" and s["bound"] is None
    assert step_line(s).startswith(f"step yaw {jump:+.3f} rad at 1.000 s: within 1 deg after")


def test_roll_step_overshoot_in_degrees_and_its_tilt():
    """A 0.2 rad roll step flown with zeta 0.5: overshoot 0.2 exp(-pi/sqrt(3)) rad (in deg),
    and the peak tilt is the peak roll."""
    t, t0 = times(4.0), 1.0
    euler_ref = np.zeros((len(t), 3))
    euler_ref[:, 0] = np.where(t >= t0, 0.2, 0.0)
    euler = np.zeros((len(t), 3))
    euler[:, 0] = 0.2 * second_order(t, t0, 0.5, 5.0)
    s = only_step(synthetic(t, ref__euler_ref=euler_ref, plant__euler=euler))
    over = 0.2 * math.exp(-math.pi / math.sqrt(3))
    assert s["overshoot"] == pytest.approx(math.degrees(over), rel=1e-4)
    assert s["peak_tilt"] == pytest.approx(math.degrees(0.2 + over), rel=1e-4)


def test_smooth_references_have_no_steps():
    """Sines with their derivatives, a 3 m/s ramp with corners on samples and a 1.5 m/s one
    with corners between them, a sine given without its velocity and a heading that wraps
    at +-pi: no steps."""
    t = times(6.0)
    n = len(t)
    ramp_on = np.clip(t - 1.0, 0.0, 2.0) * 3.0
    ramp_off = np.clip(t - 1.0007, 0.0, 2.0) * 1.5
    pos = np.column_stack([np.sin(2 * t), ramp_on, -3.0 + ramp_off])
    vel = np.column_stack([2 * np.cos(2 * t), np.where((t >= 1.0) & (t < 3.0), 3.0, 0.0),
                           np.where((t >= 1.0007) & (t < 3.0007), 1.5, 0.0)])
    heading = (0.9 * t + math.pi) % (2 * math.pi) - math.pi
    euler = np.column_stack([0.3 * np.sin(t), np.zeros(n), heading])
    rate = np.column_stack([0.3 * np.cos(t), np.zeros(n), np.full(n, 0.9)])
    r = synthetic(t, ref__pos_ref=pos, ref__vel_ref=vel, ref__euler_ref=euler,
                  ref__euler_rate_ref=rate)
    assert step_metrics(r) == []
    no_rate = synthetic(t, ref__pos_ref=np.column_stack([np.sin(t), np.zeros(n),
                                                         np.full(n, -3.0)]))
    assert compute_metrics(no_rate)["steps"] == []


def test_each_step_is_judged_until_the_next():
    """Out by 1 m at 1 s, back at 3 s, out again at 5.9 s where the vehicle never follows:
    three windows, the last never settled; only the first MAX_STEPS of a staircase."""
    t, tau = times(6.0), 0.2
    ref = step_setpoint(t, 1.0, (1.0, 0.0, 0.0)) - np.outer(t >= 3.0, [1.0, 0.0, 0.0]) \
        + np.outer(t >= 5.9, [1.0, 0.0, 0.0])
    pos = ref.copy()
    pos[:, 0] = np.where(t < 3.0, first_order(t, 1.0, tau),
                         (1 - math.exp(-2.0 / tau)) * (1 - first_order(t, 3.0, tau)))
    steps = compute_metrics(synthetic(t, ref__pos_ref=ref, plant__pos=pos))["steps"]
    assert [(s["time"], s["end"]) for s in steps] == [
        (pytest.approx(1.0), pytest.approx(3.0)), (pytest.approx(3.0), pytest.approx(5.9)),
        (pytest.approx(5.9), pytest.approx(6.0))]
    assert [s["jump"][0] for s in steps] == [1.0, -1.0, 1.0]
    assert_settles_at(steps[0]["settle_time"], tau * math.log(100.0))
    assert steps[2]["settle_time"] is None
    assert "not within 1 cm for good by 6.000 s" in step_line(steps[2])
    stairs = np.column_stack([np.floor(t / 0.02) * 0.05, np.zeros(len(t)),
                              np.full(len(t), -3.0)])
    assert len(step_metrics(synthetic(t, ref__pos_ref=stairs))) == MAX_STEPS


# ---------------------------------------------------------------------------
# the FMUs


def test_position_step_prints_its_step_line(tmp_path):
    """The shipped 1 m step on the paper hexacopter: a finite time to 1 cm, printed as
    metrics.json has it, the errors against the shaped reference (millimetres, not the
    step's metre)."""
    res = cli("run", "position_step", "--duration", "5", "--no-plots", "--no-timing",
              "--out", str(tmp_path))
    assert res.returncode == 0, res.stderr
    metrics = json.loads((tmp_path / "metrics.json").read_text())["metrics"]
    (s,) = metrics["steps"]
    assert s["kind"] == "position" and s["jump"] == [1.0, 0.0, 0.0]
    # the shaping never asks for more than its acceleration limit (ratio about 1 or more),
    # and the step reaches 1 cm within twice the bound (issue requirement)
    assert s["settle_time"] > 0.0 and 0.9 < s["bound_ratio"] <= 2.0
    assert metrics["errors_against"]["position"] == "ctrl.pos_ref_s"
    assert metrics["position_error"]["max"] < 0.01
    lines = res.stdout.splitlines()
    assert step_line(s) in lines
    assert re.search(r"^step x \+1\.000 m at 1\.000 s: within 1 cm after \d\.\d{3} s \(",
                     res.stdout, re.M)
    assert any(ln.startswith("max position error  0.00") and
               ln.endswith("against the flown (shaped) reference") for ln in lines)


def test_quadrotor_step_tilts_as_its_acceleration_needs(tmp_path):
    """On the under-actuated quadrotor (shipped, not the paper's): the CLI prints the step
    line and exits 0; the peak tilt is what the horizontal acceleration needs,
    atan(|a_h| / (g - a_z))."""
    res = cli("run", "position_step", "--airframe", "quadrotor", "--duration", "5",
              "--no-plots", "--no-timing", "--out", str(tmp_path))
    assert res.returncode == 0, res.stderr
    assert re.search(r"^step x \+1\.000 m at 1\.000 s: within 1 cm after .* peak tilt "
                     r"\d+\.\d deg, sag \d+\.\d mm \(altitude\)$", res.stdout, re.M)
    (s,) = json.loads((tmp_path / "metrics.json").read_text())["metrics"]["steps"]
    r = RunResult.read(tmp_path)
    a = r.get("plant.acc")[r.time >= 1.0]
    needed = np.degrees(np.arctan2(np.hypot(a[:, 0], a[:, 1]), G - a[:, 2])).max()
    assert s["peak_tilt"] == pytest.approx(needed, abs=0.01)
    assert s["peak_tilt"] > 5.0


@pytest.mark.parametrize("name", ["hover_varying_orientation", "translation_frequency_sweep",
                                  "full_pose_with_disturbances"])
def test_paper_comparisons_unchanged_by_the_flown_reference(name):
    """The paper's scenarios have smooth references: the shaped reference is the input, so
    the paper lines and the errors they read are those against ref.pos_ref / ref.euler_ref."""
    r = run(prepare(name, duration=30.0))
    keep = [i for i, c in enumerate(r.columns)
            if not c.startswith(("ctrl.pos_ref_s", "ctrl.euler_ref_s"))]
    given = RunResult([r.columns[i] for i in keep], r.data[:, keep], dict(r.meta), r.integer)
    m, g = compute_metrics(r), compute_metrics(given)
    assert m["errors_against"]["position"] == "ctrl.pos_ref_s"
    assert g["errors_against"]["position"] == "ref.pos_ref"
    assert m["steps"] == [] == g["steps"]
    assert compare_with_paper(m, name) == compare_with_paper(g, name)
    assert m["position_error"] == g["position_error"]
    if name == "hover_varying_orientation":
        # the controller's unwrapped heading of a sine yaw differs from the input by
        # rounding (3e-14 rad): the attitude errors agree to the last digits
        for axis in ("max", "max_axis"):
            assert m["attitude_error_vs_mu_ref"][axis] == pytest.approx(
                g["attitude_error_vs_mu_ref"][axis], rel=1e-12)
    else:
        assert m["attitude_error_vs_mu_ref"] == g["attitude_error_vs_mu_ref"]
