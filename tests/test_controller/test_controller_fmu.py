"""FullPoseController FMU on its own: FMI conformance, B'' against finite
differences, recorded QPs against piqp, bad parameters and bad inputs."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import piqp
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from helpers import problems

import plant
from controller import controller_fmu
from controller.qp_record import ALLOCATION, GUIDANCE, TWIN, qp_from_state
from orchestrator.sim.fmu import FmuInstance

H = 0.002
REF = ["pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref"]


@pytest.fixture
def make_ctrl():
    made = []

    def make(params=None, initialize=True, pos_ref=(0.0, 0.0, 0.0)):
        c = FmuInstance(controller_fmu(), f"ctrl{len(made)}")
        made.append(c)
        if initialize:
            c.slave.setupExperiment(startTime=0.0)
            c.set_many(params or {})
            c.write(c.signal("pos_ref"), pos_ref)
            c.slave.enterInitializationMode()
            c.slave.exitInitializationMode()
        return c

    yield make
    for c in made:
        c.close()


@pytest.mark.heavy  # (fmpy's schema validation of ~1,500 variables; also in the fmitools tier)
def test_controller_fmu_validates():
    assert validate_fmu(str(controller_fmu())) == []


@pytest.mark.parametrize("name", ["paper_hexacopter", "fixed_tilt_hexarotor", "quadrotor"])
def test_b_second_matches_finite_differences(name):
    rs = plant.load_airframe(name).rotor_set()
    rng = np.random.default_rng(7)
    n = rs.n
    a, b, w = rng.uniform(-0.6, 0.6, n), rng.uniform(-0.6, 0.6, n), rng.uniform(60, 200, n)
    analytic = rs.B_second(a, b, w)
    numeric = np.zeros_like(analytic)
    for i in range(n):
        for k, (vec, step) in enumerate(((a, 1e-6), (b, 1e-6), (w, 1e-4))):
            plus, minus = vec.copy(), vec.copy()
            plus[i] += step
            minus[i] -= step
            args_p = [plus if v is vec else v for v in (a, b, w)]
            args_m = [minus if v is vec else v for v in (a, b, w)]
            fp, tp = rs.wrench(*args_p)
            fm, tm = rs.wrench(*args_m)
            numeric[:, 3 * i + k] = (np.r_[fp, tp] - np.r_[fm, tm]) / (2 * step)
    np.testing.assert_allclose(analytic, numeric, rtol=1e-7, atol=1e-9)


def test_initial_commands_hold_the_measured_actuators(make_ctrl):
    c = make_ctrl()
    omega = c.read(c.signal("omega"))
    assert np.allclose(c.read(c.signal("omega_cmd")), omega)
    assert omega[0] == pytest.approx(math.sqrt(0.6656 * 9.81 / 6 / 1.14e-4), rel=1e-9)


def test_hover_measurement_gives_hover_command(make_ctrl):
    c = make_ctrl()
    before = c.read(c.signal("omega_cmd")).copy()
    for _ in range(50):
        c.step(H)
    after = c.read(c.signal("omega_cmd"))
    np.testing.assert_allclose(after, before, atol=1e-9)
    assert c.get("guid_status") == 0 and c.get("alloc_status") == 0
    assert c.get("feasible") is True


def test_recorded_qps_agree_with_piqp(make_ctrl, piqp_solve):
    c = make_ctrl(pos_ref=(0.3, -0.2, 0.1))  # a position error makes both QPs non-trivial
    for _ in range(5):
        c.step(H)
    state = c.slave.serializeFMUstate(c.slave.getFMUstate())
    for which in (GUIDANCE, ALLOCATION):
        qp = qp_from_state(bytes(state), which)
        status, x_piqp = piqp_solve(qp.A, qp.b, qp.lb, qp.ub, qp.C, qp.d)
        assert status == piqp.PIQP_SOLVED
        theirs = np.sum((qp.A @ x_piqp - qp.b) ** 2)
        ours = np.sum((qp.A @ qp.x - qp.b) ** 2)
        assert ours <= theirs * (1 + 1e-6) + 1e-9
        assert np.all(qp.x >= qp.lb - 1e-9) and np.all(qp.x <= qp.ub + 1e-9)
        if qp.C.size:
            assert np.all(qp.C @ qp.x <= qp.d + 1e-9)


def test_reference_twin_qp_agrees_with_piqp(make_ctrl, piqp_solve):
    """An attitude the force set cannot hold level (roll 0.9 rad at zero acceleration): the
    reference twin solves its QP every sample, each one the optimum piqp finds."""
    c = make_ctrl({"euler_ref[1]": 0.9})
    mu_ff, ref = c.signal("mu_ff"), c.signal("euler_ref_s")
    for k in range(20):
        c.step(H)
        assert not np.array_equal(c.read(mu_ff), c.read(ref))  # the twin departs from it
        if k % 5 != 4:
            continue
        qp = qp_from_state(bytes(c.slave.serializeFMUstate(c.slave.getFMUstate())), TWIN)
        assert qp.C.shape[0] > 0
        status, x_piqp = piqp_solve(qp.A, qp.b, qp.lb, qp.ub, qp.C, qp.d)
        assert status == piqp.PIQP_SOLVED
        theirs = np.sum((qp.A @ x_piqp - qp.b) ** 2)
        ours = np.sum((qp.A @ qp.x - qp.b) ** 2)
        assert ours <= theirs * (1 + 1e-6) + 1e-9
        assert np.all(qp.C @ qp.x <= qp.d + 1e-9)
        assert np.all(qp.x >= qp.lb - 1e-9) and np.all(qp.x <= qp.ub + 1e-9)


# ---------------------------------------------------------------------------
# Communication steps of any size: the controller samples on its own grid k Ts


TS = Fraction("0.002")
CMD = ["omega_cmd", "alpha_cmd", "beta_cmd", "mu_c", "f_b_c", "acc_c", "rate_c"]
COARSE = "longer than the sample time"


def _measurement(t: float) -> dict[str, list[float]]:
    """A smooth, plausible flight (the values need not be consistent with each other)."""
    s, c = math.sin, math.cos
    return {"pos": [0.05 * s(7 * t), -0.04 * c(5 * t), 0.03 * s(3 * t)],
            "vel": [0.35 * c(7 * t), 0.2 * s(5 * t), 0.09 * c(3 * t)],
            "acc": [-2.45 * s(7 * t), 1.0 * c(5 * t), -0.27 * s(3 * t)],
            "euler": [0.02 * s(4 * t), -0.03 * s(6 * t), 0.01 * t],
            "rate": [0.08 * c(4 * t), -0.18 * c(6 * t), 0.01]}


def _ctrl(t0: float = 0.0) -> FmuInstance:
    c = FmuInstance(controller_fmu(), "ctrl")
    c.initialize(t0, {"pos_ref[1]": 1.0, "pos_ref[2]": -0.5})
    return c


def _grid_instants_of_each_step(h: float, n: int) -> list[list[int]]:
    """Exact rational arithmetic, independent of the FMU's floating point and tolerances:
    the grid instants k Ts in [j h, (j + 1) h) of each step j = 0 .. n-1 (time from t0)."""
    hf = Fraction(repr(h))
    out, k = [], 0
    for j in range(n):
        here = []
        while k * TS < (j + 1) * hf:
            assert k * TS >= j * hf
            here.append(k)
            k += 1
        out.append(here)
    return out


def _run_any_step(h: float, duration: float, t0: float = 0.0
                  ) -> tuple[list[np.ndarray], list[np.ndarray], FmuInstance]:
    """The controller stepped by h (inputs set at each communication point), and the oracle:
    a second instance stepped by Ts = 2 ms, one sample per step (the behaviour the 2 ms
    scenario digests pin), fed for each grid instant the inputs the first had at the start of
    the step holding that instant, with ``pose_age`` the time from that start to the instant
    (a measurement set `age` before a sample is a measurement `age` old: the controller
    carries it forward exactly as a late pose; 0 within the grid's rounding tolerance).
    Returns the outputs after each step of h, the oracle's outputs expected there (the last
    sample at or before the step), the instance."""
    n = round(duration / h)
    grid = _grid_instants_of_each_step(h, n)
    b, a = _ctrl(t0), _ctrl(t0)
    sig = {name: b.signal(name) for name in _measurement(0.0)}
    cmd_b, cmd_a = b.signal(CMD), a.signal(CMD)
    got, want = [], []
    last = a.read(cmd_a).copy()  # before any sample: the initial outputs
    age_a = a.signal("pose_age")
    for j in range(n):
        t_comm = b.time
        inputs = _measurement(t_comm - t0)
        for name, values in inputs.items():
            b.write(sig[name], values)
        b.step(h)
        got.append(b.read(cmd_b).copy())
        tol = 1e-9 * h + 1e-10 * (abs(t_comm) + abs(t0))  # the FMU's rounding tolerance
        for k in grid[j]:
            for name, values in inputs.items():
                a.write(a.signal(name), values)
            age = (t0 + k * float(TS)) - t_comm
            a.write(age_a, [age if age > tol else 0.0])
            a.step(float(TS))
            last = a.read(cmd_a).copy()
        want.append(last)
    a.close()
    return got, want, b


@pytest.mark.parametrize("h", [0.0005, 0.001, 0.0007, 0.0013, 0.002, 0.0025, 0.003, 0.01])
def test_any_step_samples_the_ts_grid_with_the_inputs_held_since_the_last_point(h):
    """Bit-identical to the 2 ms oracle: a sample runs at each grid instant k Ts in the step
    [t, t + h) holding it, with the inputs set at t; the outputs between samples are held;
    several samples in one step (h > Ts) each use the same held inputs and advance the
    filters by Ts.  0.3 s: the 0.7 ms steps hit 21 grid instants exactly (every 14 ms)."""
    got, want, b = _run_any_step(h, 0.3)
    try:
        np.testing.assert_array_equal(np.array(got), np.array(want))
        assert len({tuple(g) for g in got}) > 20  # the commands really move
        coarse = [m for _, _, m in b.messages if COARSE in m]
        assert len(coarse) == (1 if h > 0.002 else 0), b.messages
    finally:
        b.close()


@pytest.mark.heavy  # (7,143 summed steps and two late starts: 3.4 s)
def test_the_sample_grid_does_not_drift_over_long_runs_or_at_a_late_start():
    """5 s of 0.7 ms steps whose communication points the importer sums up (fmpy-style
    time += h: 7143 additions), and a start at t0 = 1e5 s where a time carries only ~1e-11 s
    of precision: each grid instant is still taken in its own step."""
    for h, duration, t0 in ((0.0007, 5.0, 0.0), (0.001, 0.2, 1e5), (0.0007, 0.2, 1e5)):
        got, want, b = _run_any_step(h, duration, t0)
        b.close()
        np.testing.assert_array_equal(np.array(got), np.array(want), err_msg=f"{h} {t0}")


@pytest.mark.parametrize("h", [0.0025, 0.01, 0.02])
def test_steps_longer_than_ts_warn_once_per_run(make_ctrl, h):
    c = make_ctrl(pos_ref=(1.0, 0.0, 0.0))
    comp = c.slave.component
    statuses = []
    for _ in range(3):  # three runs: the warning comes back after each reset
        for k in range(20):
            statuses.append(c.slave.fmi2DoStep(comp, k * h, h, 1))
        c.slave.reset()
        c.slave.setupExperiment(startTime=0.0)
        c.slave.enterInitializationMode()
        c.slave.exitInitializationMode()
    coarse = [(s, m) for s, _, m in c.messages if COARSE in m]
    assert len(coarse) == 3 and all(s == "WARNING" for s, _ in coarse), c.messages
    assert f"communication step {h:.12g} s is longer than the sample time Ts = 0.002 s" \
        in coarse[0][1]
    assert "docs/controller.md" in coarse[0][1]
    # every step returns fmi2OK: the warning is the logged message (docs/fmus.md, "What
    # doStep returns")
    assert statuses == [0] * 20 * 3


def test_a_step_of_ts_or_less_does_not_warn(make_ctrl):
    c = make_ctrl()
    for h in (0.002, 0.002 * (1 + 1e-10), 0.0007, 0.0005):
        for _ in range(10):
            c.step(h)
    assert not [m for _, _, m in c.messages if COARSE in m], c.messages


def test_a_step_beyond_the_sample_cap_is_refused_untouched(make_ctrl):
    c = make_ctrl(pos_ref=(1.0, 0.0, 0.0))
    c.step(0.0007)
    before = c.read(c.signal(CMD)).copy()
    with pytest.raises(FMICallException):
        c.slave.doStep(c.time, 200.002)  # 100001 samples: one over the cap
    assert "would take 100001 control samples (limit 100000)" in problems(c)
    np.testing.assert_array_equal(c.read(c.signal(CMD)), before)


def test_timing_is_opt_in(make_ctrl):
    off = make_ctrl()
    on = make_ctrl({"timing": True})
    off.step(H)
    on.step(H)
    t_off = off.read(off.signal(["t_step", "t_guid", "t_alloc"]))
    t_on = on.read(on.signal(["t_step", "t_guid", "t_alloc"]))
    assert np.all(t_off == 0.0)
    assert np.all(t_on > 0.0) and t_on[0] >= t_on[1]


@pytest.mark.parametrize(
    ("params", "name"),
    [
        ({"Ts": 0.0}, "Ts"),
        ({"Ts": -0.002}, "Ts"),
        ({"gamma_opt": 0.0}, "gamma_opt"),
        ({"W_v[1]": -1.0}, "W_v[1]"),
        ({"W_u[4]": 0.0}, "W_u[4]"),
        ({"W_nu[6]": math.nan}, "W_nu[6]"),
        ({"w_pref": 0.0}, "w_pref"),
        ({"mass": 0.0}, "mass"),
        ({"euler_min[1]": 0.5, "euler_max[1]": 0.2}, "euler_min[1]"),
        ({"alpha_min[2]": 0.5, "alpha_max[2]": 0.2}, "alpha_min[2]"),
        ({"omega_min": 300.0}, "omega_min"),
        ({"K_pos_A[1]": 1.5}, "K_pos_A[1]"),
        ({"qp_max_iter": 0}, "qp_max_iter"),
        ({"poly_n": 2}, "poly_n"),
        ({"poly_margin": 0.0}, "poly_margin"),
        ({"force_constraint": 3}, "force_constraint"),
        ({"inertia[1,1]": -0.004}, "inertia"),
        ({"filt_wn": 0.0}, "filt_wn"),
    ],
)
def test_bad_parameters_are_refused(make_ctrl, params, name):
    c = make_ctrl(initialize=False)
    c.slave.setupExperiment(startTime=0.0)
    c.set_many(params)
    c.slave.enterInitializationMode()
    with pytest.raises(FMICallException) as err:
        c.slave.exitInitializationMode()
    assert err.value.status == 3
    assert f"parameter {name}" in problems(c) or f"parameters {name}" in problems(c)


# The airframe parameters both FMUs carry are checked by one set of rules
# (fmu_src/common/fp_params.c): both refuse the same value with the same message.
SHARED_AIRFRAME_RULES = [
    ({"alpha_max[1]": 2.0}, "parameter alpha_max[1] = 2: must be within [-pi/2, pi/2]"),
    ({"beta_min[3]": -1.6}, "parameter beta_min[3] = -1.6: must be within [-pi/2, pi/2]"),
    ({"k_d": -1e-6}, "parameter k_d = -1e-06: must not be negative"),
    ({"inertia[2,3]": 0.001},
     "parameter inertia[2,3] = 0.001: the inertia matrix must be symmetric"),
    ({"inertia[1,1]": -0.004}, "parameter inertia is not positive definite"),
    ({"rotor_pos[2,1]": math.nan}, "parameter rotor_pos[2,1] = nan: must be finite"),
    ({"rotor_dir[4]": 0}, "parameter rotor_dir[4] = 0: must be +1 or -1"),
    ({"omega_min": -1.0}, "parameter omega_min = -1: must not be negative"),
    ({"beta_min[2]": 0.5, "beta_max[2]": 0.2},
     "parameter beta_min[2] = 0.5: exceeds beta_max (inverted limits)"),
    ({"n_rotors": 9}, "parameter n_rotors = 9: must be in 1..8"),
    # physical plausibility (FP_* of common/multirotor.h; plant/airframe.py applies the same;
    # not declared ranges, so not "parameter NAME = VALUE")
    ({"k_t": 1e-300}, "parameters k_t, omega_max: a rotor's maximum thrust k_t omega_max^2 = "
                      "4.38649e-296 N is outside [0.001, 100000] N: less than any rotor's"),
    ({"omega_max": 1e19}, "parameter omega_max: 1e+19 rad/s is outside [0.10472, 52359.9] "
                          "rad/s (1 to 500000 rpm): faster than any rotor turns"),
    ({"k_d": 1.0}, "parameters k_d, k_t: the drag torque per newton of thrust k_d / k_t = "
                   "8771.93 m exceeds 10 m"),
    ({"mass": 665.6}, "parameters mass, g, k_t, omega_max: the thrust-to-weight ratio n_rotors "
                      "k_t omega_max^2 / (mass g) = 6 x 5.0006 N / 6529.54 N = 0.00459506 is "
                      "outside [0.1, 100]"),
]


@pytest.mark.parametrize(("params", "message"), SHARED_AIRFRAME_RULES,
                         ids=[m.split(":")[0] for _, m in SHARED_AIRFRAME_RULES])
def test_both_fmus_apply_the_same_airframe_rules(make_ctrl, make_plant, params, message):
    c = make_ctrl(initialize=False)
    c.slave.setupExperiment(startTime=0.0)
    c.set_many(params)
    c.slave.enterInitializationMode()
    with pytest.raises(FMICallException):
        c.slave.exitInitializationMode()
    p = make_plant(initialize=False)
    with pytest.raises(FMICallException):
        p.initialize(parameters=params)
    for inst in (c, p):
        found = [m for s, _, m in inst.messages if s == "ERROR" and m.startswith(message)]
        assert found, (inst.md.modelName, inst.messages)


def polytope_params(A, b):
    p = {"poly_n": len(b)}
    for i, (row, bi) in enumerate(zip(A, b, strict=True)):
        for j in range(3):
            p[f"poly_A[{i + 1},{j + 1}]"] = float(row[j])
        p[f"poly_b[{i + 1}]"] = float(bi)
    return p


def test_empty_polytope_is_refused(make_ctrl):
    box = np.vstack([np.eye(3), -np.eye(3)])
    c = make_ctrl(initialize=False)
    c.set_many(polytope_params(np.vstack([box, [[1.0, 0, 0]]]), [5, 5, 0, 5, 5, 30, -10]))
    c.slave.setupExperiment(startTime=0.0)
    c.slave.enterInitializationMode()
    with pytest.raises(FMICallException):
        c.slave.exitInitializationMode()
    assert "polytope is empty" in problems(c)


def test_unbounded_polytope_is_refused(make_ctrl):
    # no facet limits the force downwards (+z) or sideways in -x: unbounded
    A = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    c = make_ctrl(initialize=False)
    c.set_many(polytope_params(A, [5, 5, 5, 30]))
    c.slave.setupExperiment(startTime=0.0)
    c.slave.enterInitializationMode()
    with pytest.raises(FMICallException):
        c.slave.exitInitializationMode()
    assert "unbounded" in problems(c)


@pytest.mark.parametrize(
    ("signal", "index"), [("pos_ref", 2), ("euler_ref", 1), ("acc", 3), ("rate", 1),
                          ("omega", 4), ("vel_ref", 1)])
def test_non_finite_input_holds_the_last_command(make_ctrl, signal, index):
    c = make_ctrl(pos_ref=(0.5, 0.0, 0.0))
    for _ in range(3):
        c.step(H)
    outputs = c.signal(["omega_cmd", "alpha_cmd", "beta_cmd", "mu_c"])
    before = c.read(outputs).copy()
    name = f"{signal}[{index}]"
    good = c.get(name)
    for bad in (math.nan, math.inf):
        c.set(name, bad)
        c.step(H)  # fmi2OK, the warning logged
        np.testing.assert_array_equal(c.read(outputs), before)
        assert f"input {name}" in problems(c)
        assert np.isfinite(c.read(outputs)).all()
    c.set(name, good)
    c.step(H)
    assert not np.array_equal(c.read(outputs), before)


def test_tunable_gain_changes_between_steps(make_ctrl):
    c = make_ctrl(pos_ref=(0.5, 0.0, 0.0))
    c.step(H)
    acc_default = c.read(c.signal("acc_c")).copy()
    c.set("K_vel_D[1]", c.get("K_vel_D[1]") / 2)  # half the default velocity gain
    c.step(H)
    acc_half = c.read(c.signal("acc_c"))
    assert acc_half[0] == pytest.approx(acc_default[0] / 2, rel=0.05)
    c.set("W_v[1]", -1.0)
    with pytest.raises(FMICallException):
        c.step(H)
    assert "parameter W_v[1]" in problems(c)


def test_fixed_parameter_cannot_change_after_initialization(make_ctrl):
    c = make_ctrl()
    with pytest.raises(FMICallException):
        c.set("mass", 1.0)
    assert "fixed parameter" in problems(c)
