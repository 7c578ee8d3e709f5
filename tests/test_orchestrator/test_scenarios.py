"""Scenario files and structured signals, against independent oracles.

Derivatives are checked against central finite differences of the values on a fine grid
and, for sines and chirps, against closed forms written here; the shipped scenarios against
the paper's formulas (Sec. IV-A to IV-C) evaluated here; bad files must fail at load time
with an error naming the file, the dotted field and the expectation.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from orchestrator.scenario.catalogue import (
    check_scenario,
    list_scenarios,
    load_scenario,
    scenario_names,
)
from orchestrator.scenario.model import Scenario
from orchestrator.scenario.parser import with_overrides
from orchestrator.scenario.reader import ScenarioError
from orchestrator.scenario.signals import (
    Chirp,
    Constant,
    Ramp,
    Sine,
    Steps,
    Sum,
    Waypoints,
    parse_signal,
    value_range,
)

ROOT = Path(__file__).resolve().parents[2]
H_FD = 1e-4  # finite-difference step, s


def central(f, t, h=H_FD):
    """First and second central differences of f at t."""
    fp, f0, fm = f(t + h), f(t), f(t - h)
    return (fp - fm) / (2 * h), (fp - 2 * f0 + fm) / h**2


def away_from(t, points, margin=3 * H_FD):
    """Mask of grid points at least `margin` away from every breakpoint."""
    mask = np.ones_like(t, dtype=bool)
    for p in points:
        mask &= np.abs(t - p) > margin
    return mask


SIGNALS = {
    "constant": (Constant(-2.5), []),
    "sine": (Sine(amplitude=1.3, omega=0.7, phase=0.4, offset=-0.2), []),
    "chirp": (Chirp(amplitude=3.0, omega0=0.1, omega1=1.5, t0=2.0, t1=15.0, phase=0.3,
                    offset=0.5), [2.0, 15.0]),
    "steps": (Steps((1.0, 4.0, 9.0), (2.0, -1.0, 0.5), initial=0.3), [1.0, 4.0, 9.0]),
    "ramp": (Ramp(start=1.0, end=-3.0, t0=2.0, t1=7.0), [2.0, 7.0]),
    "waypoints": (Waypoints((1.0, 3.0, 8.0, 12.0), (0.0, 2.0, -1.0, -1.5)), []),
    "sum": (Sum((Sine(0.5, 2.0), Ramp(0.0, 1.0, 3.0, 5.0), Constant(1.0))), [3.0, 5.0]),
}


@pytest.mark.parametrize("kind", sorted(SIGNALS))
def test_derivatives_match_finite_differences(kind):
    signal, breaks = SIGNALS[kind]
    t = np.linspace(-1.0, 20.0, 4001)
    keep = away_from(t, breaks)
    d1_fd, d2_fd = central(signal.value, t)
    d1, d2 = signal.derivative(t, 1), signal.derivative(t, 2)
    assert d1.shape == t.shape and d2.shape == t.shape and signal.value(t).dtype == np.float64
    np.testing.assert_allclose(d1[keep], d1_fd[keep], rtol=0, atol=1e-6)
    np.testing.assert_allclose(d2[keep], d2_fd[keep], rtol=0, atol=2e-5)


def test_derivative_order_is_checked():
    with pytest.raises(ValueError, match="order"):
        Sine(1.0, 1.0).derivative(np.zeros(2), 3)


def test_sine_closed_form():
    a, w, phi, off = 1.3, 0.7, 0.4, -0.2
    s = Sine(amplitude=a, omega=w, phase=phi, offset=off)
    t = np.linspace(0, 30, 301)
    np.testing.assert_allclose(s.value(t), off + a * np.sin(w * t + phi), atol=1e-14)
    np.testing.assert_allclose(s.derivative(t, 1), a * w * np.cos(w * t + phi), atol=1e-14)
    np.testing.assert_allclose(s.derivative(t, 2), -a * w**2 * np.sin(w * t + phi), atol=1e-14)


def test_chirp_closed_form():
    """theta = phase + int_0^t omega: before t0 linear, a parabola on the ramp, then linear."""
    a, w0, w1, t0, t1, phi = 3.0, 0.1, 1.5, 2.0, 15.0, 0.3
    c = Chirp(amplitude=a, omega0=w0, omega1=w1, t0=t0, t1=t1, phase=phi)
    k = (w1 - w0) / (t1 - t0)
    t = np.linspace(0, 25, 2501)
    theta = np.where(t < t0, phi + w0 * t,
                     np.where(t < t1, phi + w0 * t + 0.5 * k * (t - t0) ** 2,
                              phi + w0 * t1 + 0.5 * k * (t1 - t0) ** 2 + w1 * (t - t1)))
    omega = np.where(t < t0, w0, np.where(t < t1, w0 + k * (t - t0), w1))
    domega = np.where((t >= t0) & (t < t1), k, 0.0)
    np.testing.assert_allclose(c.value(t), a * np.sin(theta), atol=1e-12)
    np.testing.assert_allclose(c.derivative(t, 1), a * omega * np.cos(theta), atol=1e-12)
    np.testing.assert_allclose(c.derivative(t, 2),
                               a * (domega * np.cos(theta) - omega**2 * np.sin(theta)),
                               atol=1e-12)
    # the instantaneous angular frequency reaches omega1 at t1
    assert c.angular_frequency(np.array([t1]))[0] == pytest.approx(w1)


def test_steps_and_ramp_values():
    s = Steps((1.0, 4.0), (2.0, -1.0), initial=0.3)
    np.testing.assert_array_equal(s.value([0.0, 0.999, 1.0, 3.9, 4.0, 100.0]),
                                  [0.3, 0.3, 2.0, 2.0, -1.0, -1.0])
    assert not s.derivative(np.linspace(0, 5, 11), 1).any()
    assert not s.derivative(np.linspace(0, 5, 11), 2).any()
    r = Ramp(start=1.0, end=-3.0, t0=2.0, t1=7.0)
    np.testing.assert_allclose(r.value([0.0, 2.0, 4.5, 7.0, 9.0]), [1.0, 1.0, -1.0, -3.0, -3.0])
    np.testing.assert_allclose(r.derivative([1.0, 3.0, 8.0], 1), [0.0, -0.8, 0.0])


def test_waypoints_pass_through_at_rest_and_are_c2():
    times, values = (1.0, 3.0, 8.0, 12.0), (0.0, 2.0, -1.0, -1.5)
    w = Waypoints(times, values)
    tw = np.array(times)
    np.testing.assert_allclose(w.value(tw), values, atol=1e-15)
    np.testing.assert_allclose(w.derivative(tw, 1), 0.0, atol=1e-15)
    np.testing.assert_allclose(w.derivative(tw, 2), 0.0, atol=1e-15)
    # symmetric segment: halfway in time is halfway in value
    np.testing.assert_allclose(w.value([2.0]), [1.0])
    # constant outside
    np.testing.assert_allclose(w.value([-5.0, 0.99, 12.01, 50.0]), [0.0, 0.0, -1.5, -1.5])
    # C2: value, velocity and acceleration continuous across every waypoint
    eps = 1e-7
    for order in (0, 1, 2):
        f = w.value if order == 0 else (lambda t, o=order: w.derivative(t, o))
        jump = np.abs(f(tw + eps) - f(tw - eps))
        assert jump.max() < 1e-5, (order, jump)
    # the acceleration from finite differences of the value matches everywhere: no impulse
    # at a waypoint (which would show as ~ dv / h); there the jerk jumps, so the central
    # difference is only O(h) accurate
    t = np.linspace(0.0, 13.0, 13001)
    _, d2_fd = central(w.value, t)
    near = ~away_from(t, times, 1.5 * H_FD)
    assert near.sum() == len(times)
    np.testing.assert_allclose(w.derivative(t, 2)[~near], d2_fd[~near], atol=2e-5)
    np.testing.assert_allclose(w.derivative(t, 2)[near], d2_fd[near], atol=1e-3)


def test_sums_add():
    terms = (Sine(0.5, 2.0, 0.1), Chirp(1.0, 0.0, 1.0, 10.0), Ramp(0.0, 1.0, 3.0, 5.0),
             Steps((2.0,), (1.0,)), Waypoints((0.0, 4.0), (1.0, 3.0)))
    total = Sum(terms)
    t = np.linspace(0, 12, 241)
    for order in (0, 1, 2):
        def ev(s, o=order):
            return s.value(t) if o == 0 else s.derivative(t, o)

        np.testing.assert_allclose(ev(total), sum(ev(s) for s in terms), atol=1e-14)
    assert isinstance(terms[0] + terms[1], Sum)


def test_parser_number_table_and_array():
    src = "f.toml"
    assert parse_signal(2.5, src, "x").value([0.0, 3.0]).tolist() == [2.5, 2.5]
    sig = parse_signal([1.0, {"type": "sine", "amplitude": 2.0, "omega": 0.5}], src, "x")
    t = np.linspace(0, 10, 11)
    np.testing.assert_allclose(sig.value(t), 1.0 + 2.0 * np.sin(0.5 * t))
    np.testing.assert_allclose(sig.derivative(t, 2), -0.5 * np.sin(0.5 * t))
    same = parse_signal({"type": "sum", "terms": [1.0, {"type": "constant", "value": 2.0}]},
                        src, "x")
    np.testing.assert_allclose(same.value(t), 3.0)


# ---------------------------------------------------------------------------
# Shipped scenarios


def test_shipped_scenarios_listed_and_valid():
    names = scenario_names()
    assert names == sorted(["full_pose_with_disturbances", "hover", "hover_varying_orientation",
                            "position_step", "translation_frequency_sweep",
                            "quadrotor_translation", "quadrotor_hover_attitude",
                            "fixed_tilt_translation", "fixed_tilt_hover_attitude",
                            "rotor_failure_hover", "rotor_failure_no_reconfiguration",
                            "rotor_failure_detected",
                            "robustness_inertia_corner",
                            "robustness_inertia_corner_prototype", "takeoff_and_land",
                            "mission_full_pose"])
    loaded = list_scenarios()
    assert [s.name for s in loaded] == names
    for sc in loaded:
        expected = ("quadrotor" if sc.name.startswith("quadrotor_") else
                    "fixed_tilt_hexarotor" if sc.name.startswith("fixed_tilt_") else
                    "paper_hexacopter")
        assert sc.airframe.name == expected
        assert sc.step == 0.002 and sc.coupling == "gauss-seidel"
        assert Path(sc.source).name == f"{sc.name}.toml"
        assert sc.description
        assert check_scenario(sc.source).name == sc.name
    durations = {s.name: s.duration for s in loaded}
    assert durations["hover"] == durations["position_step"] == 10.0
    for paper in ("hover_varying_orientation", "translation_frequency_sweep",
                  "full_pose_with_disturbances"):
        assert durations[paper] == 100.0
        assert load_scenario(paper).n_steps == 50000


T_CHECK = np.array([0.0, 3.7, 12.5, 41.0, 70.2, 99.9])


def _paper_position_scenario_2(t):
    # xi_ref = [3 sin(w_x t), 2 sin(w_y t), -3] with w_x, w_y ramping linearly from 0 over
    # 100 s: the phase is int_0^t w = w_end t^2 / (2 * 100)
    th_x, th_y = 0.5 * t**2 / 200.0, 0.7 * t**2 / 200.0
    pos = np.column_stack([3 * np.sin(th_x), 2 * np.sin(th_y), np.full_like(t, -3.0)])
    vel = np.column_stack([3 * 0.005 * t * np.cos(th_x), 2 * 0.007 * t * np.cos(th_y),
                           np.zeros_like(t)])
    acc = np.column_stack([
        3 * (0.005 * np.cos(th_x) - (0.005 * t) ** 2 * np.sin(th_x)),
        2 * (0.007 * np.cos(th_y) - (0.007 * t) ** 2 * np.sin(th_y)),
        np.zeros_like(t)])
    return pos, vel, acc


def test_scenario_1_is_the_paper():
    ref = load_scenario("hover_varying_orientation").references(T_CHECK)
    t = T_CHECK
    np.testing.assert_allclose(ref["pos_ref"], np.tile([0.0, 0.0, -3.0], (len(t), 1)))
    assert not ref["vel_ref"].any() and not ref["acc_ref"].any()
    mu = np.column_stack([0.7 * np.sin(0.2 * t), -0.7 * np.sin(0.5 * t),
                          -0.35 * np.sin(0.5 * t)])
    dmu = np.column_stack([0.14 * np.cos(0.2 * t), -0.35 * np.cos(0.5 * t),
                           -0.175 * np.cos(0.5 * t)])
    np.testing.assert_allclose(ref["euler_ref"], mu, atol=1e-14)
    np.testing.assert_allclose(ref["euler_rate_ref"], dmu, atol=1e-14)
    assert set(ref) == {"pos_ref", "vel_ref", "acc_ref", "euler_ref", "euler_rate_ref"}
    assert all(v.shape == (len(t), 3) for v in ref.values())


def test_scenario_2_is_the_paper():
    sc = load_scenario("translation_frequency_sweep")
    ref = sc.references(T_CHECK)
    pos, vel, acc = _paper_position_scenario_2(T_CHECK)
    np.testing.assert_allclose(ref["pos_ref"], pos, atol=1e-12)
    np.testing.assert_allclose(ref["vel_ref"], vel, atol=1e-12)
    np.testing.assert_allclose(ref["acc_ref"], acc, atol=1e-12)
    assert not ref["euler_ref"].any() and not ref["euler_rate_ref"].any()
    assert not any(v.any() for k, v in sc.disturbances(T_CHECK).items() if k != "efficiency")
    # the frequency ranges of the paper: 0..0.5 and 0..0.7 rad/s
    x, y = sc.position[0], sc.position[1]
    assert isinstance(x, Chirp) and isinstance(y, Chirp)
    assert (x.angular_frequency([0.0, 100.0]).tolist(), y.angular_frequency([0.0, 100.0])
            .tolist()) == ([0.0, 0.5], [0.0, 0.7])


def test_scenario_3_is_the_paper():
    sc = load_scenario("full_pose_with_disturbances")
    t = np.arange(0.0, 100.0, 0.01)
    ref = sc.references(t)
    pos, vel, acc = _paper_position_scenario_2(t)
    np.testing.assert_allclose(ref["pos_ref"], pos, atol=1e-12)
    np.testing.assert_allclose(ref["vel_ref"], vel, atol=1e-12)
    np.testing.assert_allclose(ref["acc_ref"], acc, atol=1e-12)
    mu = np.column_stack([0.53 * np.sin(0.2 * t), -0.35 * np.sin(0.5 * t), np.zeros_like(t)])
    np.testing.assert_allclose(ref["euler_ref"], mu, atol=1e-14)
    a_d = sc.disturbances(t)["a_d"]
    # varying steps (Fig. 8): piecewise constant, both signs on x and y, up to ~3 m/s^2,
    # z smaller, the strongest around t = 70 s; zero at the start and at the end
    assert np.abs(a_d[:, :2]).max() == pytest.approx(3.0)
    assert 0 < np.abs(a_d[:, 2]).max() < np.abs(a_d[:, :2]).max()
    for axis in (0, 1):
        assert a_d[:, axis].min() < 0 < a_d[:, axis].max()
        assert len(np.flatnonzero(np.diff(a_d[:, axis]))) >= 8
    at70 = sc.disturbances(np.array([71.0]))["a_d"][0]
    assert np.linalg.norm(at70[:2]) == pytest.approx(np.abs(a_d[:, :2]).max(axis=0).max()
                                                     * math.sqrt(2))
    assert not a_d[0].any() and not a_d[-1].any()
    assert not sc.disturbances(t)["f_d"].any() and (sc.disturbances(t)["efficiency"] == 1).all()


def test_small_scenarios():
    t = np.array([0.0, 0.999, 1.0, 5.0])
    hover = load_scenario("hover").references(t)
    np.testing.assert_array_equal(hover["pos_ref"], np.tile([0.0, 0.0, -3.0], (4, 1)))
    step = load_scenario("position_step").references(t)
    np.testing.assert_array_equal(step["pos_ref"][:, 0], [0.0, 0.0, 1.0, 1.0])
    np.testing.assert_array_equal(step["pos_ref"][:, 1:], np.tile([0.0, -3.0], (4, 1)))
    pos0, euler0 = load_scenario("position_step").initial_pose()
    np.testing.assert_array_equal(pos0, [0.0, 0.0, -3.0])
    np.testing.assert_array_equal(euler0, [0.0, 0.0, 0.0])


# ---------------------------------------------------------------------------
# User files

BASE = """\
name = "t"
duration = 10.0
airframe = "paper_hexacopter"
[reference.position]
z = -3.0
"""


def write(tmp_path: Path, text: str, name: str = "scenario.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_degrees_are_converted_to_radians(tmp_path):
    path = write(tmp_path, BASE + """
[reference.attitude_deg]
roll = { type = "sine", amplitude = 30.0, omega = 0.5 }
pitch = -10.0
yaw = { type = "ramp", from = 0.0, to = 90.0, t0 = 1.0, t1 = 4.0 }
""")
    ref = load_scenario(path).references(np.array([0.5, 2.0, 6.0]))
    t = np.array([0.5, 2.0, 6.0])
    np.testing.assert_allclose(ref["euler_ref"][:, 0], math.pi / 6 * np.sin(0.5 * t))
    np.testing.assert_allclose(ref["euler_ref"][:, 1], -math.pi / 18)
    np.testing.assert_allclose(ref["euler_ref"][:, 2], [0.0, math.pi / 6, math.pi / 2])
    np.testing.assert_allclose(ref["euler_rate_ref"][:, 0], math.pi / 12 * np.cos(0.5 * t))
    np.testing.assert_allclose(ref["euler_rate_ref"][:, 2], [0.0, math.pi / 6, 0.0])
    np.testing.assert_allclose(ref["euler_rate_ref"][:, 1], 0.0)


def test_faults_give_the_efficiency_profile(tmp_path):
    path = write(tmp_path, BASE + """
[[fault]]
time = 5.0
rotor = 2
efficiency = 0.0
[[fault]]
time = 2.0
rotor = 2
efficiency = 0.5
[[fault]]
time = 3.0
rotor = 6
efficiency = 0.75
""")
    sc = load_scenario(path)
    t = np.array([0.0, 1.999, 2.0, 3.0, 4.9, 5.0, 9.0])
    eff = sc.disturbances(t)["efficiency"]
    expected = np.ones((len(t), 8))
    expected[:, 1] = [1.0, 1.0, 0.5, 0.5, 0.5, 0.0, 0.0]
    expected[:, 5] = [1.0, 1.0, 1.0, 0.75, 0.75, 0.75, 0.75]
    np.testing.assert_array_equal(eff, expected)


def test_disturbance_tables(tmp_path):
    path = write(tmp_path, BASE + """
[disturbance.force]
z = { type = "steps", times = [1.0, 2.0], values = [1.0, 0.0] }
[disturbance.torque]
x = 0.01
[disturbance.acceleration]
y = [0.1, { type = "sine", amplitude = 0.2, omega = 1.0 }]
""")
    d = load_scenario(path).disturbances(np.array([0.5, 1.5]))
    np.testing.assert_array_equal(d["f_d"], [[0, 0, 0], [0, 0, 1.0]])
    np.testing.assert_array_equal(d["tau_d"], [[0.01, 0, 0], [0.01, 0, 0]])
    np.testing.assert_allclose(d["a_d"][:, 1], 0.1 + 0.2 * np.sin([0.5, 1.5]))
    assert d["efficiency"].shape == (2, 8)


def test_parameter_overrides_and_relative_airframe(tmp_path):
    frame = (ROOT / "plant" / "airframes" / "quadrotor.toml").read_text()
    write(tmp_path, frame.replace('name = "quadrotor"', 'name = "my_quad"'), "frames_quad.toml")
    path = write(tmp_path, """\
duration = 10.0
step = 0.004
airframe = "frames_quad.toml"
coupling = "jacobi"
[reference.position]
z = -3.0
[plant]
mass = 1
init_trim = false
noise_seed = 7
"pos0[1]" = 0.5
inertia = [[0.01, 0, 0], [0, 0.02, 0], [0, 0, 0.03]]
[controller]
K_pos_D = [3.0, 3.0, 2.0]
"W_v[3]" = 20.0
""")
    sc = load_scenario(path)
    assert sc.airframe.name == "my_quad" and sc.airframe.n_rotors == 4
    assert sc.step == 0.004 and sc.n_steps == 2500 and sc.coupling == "jacobi"
    assert sc.plant_parameters["mass"] == 1.0 and isinstance(sc.plant_parameters["mass"], float)
    assert sc.plant_parameters["init_trim"] is False
    assert sc.plant_parameters["noise_seed"] == 7
    assert sc.plant_parameters["inertia[2,2]"] == 0.02
    assert sc.controller_parameters == {"K_pos_D[1]": 3.0, "K_pos_D[2]": 3.0,
                                        "K_pos_D[3]": 2.0, "W_v[3]": 20.0}
    assert sc.name == "scenario"  # default: the file name
    pos0, _ = sc.initial_pose()
    np.testing.assert_array_equal(pos0, [0.5, 0.0, -3.0])
    # the rotor count of a fault is the airframe's
    path.write_text(path.read_text().replace(
        "[plant]", "[[fault]]\ntime = 1.0\nrotor = 5\nefficiency = 0.0\n[plant]"))
    with pytest.raises(ScenarioError, match=r"field 'fault\[1\]\.rotor': .*1\.\.4"):
        load_scenario(path)


def test_with_overrides(tmp_path):
    sc = load_scenario("hover")
    new = with_overrides(sc, duration=4.0, settings=[
        "controller.K_pos_D[1]=3.0", "plant.noise_pos=0.01", "plant.init_trim=false",
        "controller.W_v=[10, 10, 5]", "plant.noise_seed = 3"])
    assert isinstance(new, Scenario) and new.duration == 4.0 and new.n_steps == 2000
    assert new.controller_parameters == {"K_pos_D[1]": 3.0, "W_v[1]": 10.0, "W_v[2]": 10.0,
                                         "W_v[3]": 5.0}
    assert new.plant_parameters == {"noise_pos": 0.01, "init_trim": False, "noise_seed": 3}
    assert sc.duration == 10.0 and sc.plant_parameters == {} and sc.controller_parameters == {}
    assert with_overrides(sc).duration == 10.0


@pytest.mark.parametrize(("setting", "field", "expect"), [
    ("controller.K_pos_DD=1.0", "controller.K_pos_DD", "no variable"),
    ("plant.pos[1]=1.0", "plant.pos[1]", "causality is parameter"),
    ("controller.mu_c=[0, 0, 0]", "controller.mu_c", "causality is parameter"),
    ("plant.mass=true", "plant.mass", "expected a number"),
    ("plant.init_trim=1", "plant.init_trim", "expected true or false"),
    ("plant.noise_seed=1.5", "plant.noise_seed", "expected an integer"),
    ("controller.K_pos_D=[1.0, 2.0]", "controller.K_pos_D", "array of 3"),
    ("plant.mass=heavy", "plant.mass", "expected a number, true/false or an array"),
    ("airframe.mass=1.0", "airframe.mass", "plant.NAME=VALUE or controller.NAME=VALUE"),
    ("controller.Ts=0.004", "controller.Ts", "divides the communication step"),
    # integers beyond an FMI Integer's 32 bits reached the FMU wrapped around (4294967301
    # flew as 5), or were refused as a value never typed (1661992959): named as typed
    ("controller.qp_max_iter=4294967301", "controller.qp_max_iter",
     "expected an integer in 1..1000 (its declared range in the FullPoseController FMU), "
     "got 4294967301"),
    ("controller.qp_max_iter=99999999999999999999", "controller.qp_max_iter",
     "got 99999999999999999999"),
    ("plant.noise_seed=99999999999999999999", "plant.noise_seed",
     "expected an integer in -2147483648..2147483647 (a 32-bit FMI Integer), "
     "got 99999999999999999999"),
    ("plant.noise_seed=-2147483649", "plant.noise_seed", "got -2147483649"),
    ("plant.mass=1e400", "plant.mass", "expected a finite number, got 1e400"),
    ("controller.K_pos_D=" + "[" * 40 + "]" * 40, "controller.K_pos_D",
     "nested deeper than 32 levels"),
    ("controller.K_pos_D=" + "[" * 5000 + "]" * 5000, "controller.K_pos_D",
     "nested deeper than 32 levels"),
])
def test_with_overrides_rejects_bad_settings(setting, field, expect):
    sc = load_scenario("hover")
    with pytest.raises(ScenarioError) as info:
        with_overrides(sc, settings=[setting])
    msg = str(info.value)
    assert sc.source in msg and f"'{field}'" in msg and expect in msg, msg
    assert setting in msg or field == "controller.Ts"


@pytest.mark.parametrize(("duration", "expect"), [(-1.0, "positive"), (0.0, "positive"),
                                                  (1.001, "multiple of the communication")])
def test_with_overrides_rejects_bad_durations(duration, expect):
    with pytest.raises(ScenarioError, match=expect):
        with_overrides(load_scenario("hover"), duration=duration)


def _sine(extra: str = "") -> str:
    return "{ type = \"sine\", amplitude = 1.0, omega = 0.5" + extra + " }"


INVALID = [
    # (id, replace BASE line or append, field, expectation)
    ("duration-string", ('duration = 10.0', 'duration = "10"'), "duration",
     "expected a number"),
    ("duration-negative", ('duration = 10.0', 'duration = -5.0'), "duration",
     "expected a positive number"),
    ("duration-missing", ('duration = 10.0', ''), "duration", "missing"),
    ("duration-not-multiple", ('duration = 10.0', 'duration = 10.001'), "duration",
     "multiple of the communication step"),
    ("name-number", ('name = "t"', 'name = 3'), "name", "expected a string"),
    ("unknown-top", "durration = 10.0", "durration", "unknown field"),
    ("unknown-axis", ("z = -3.0", "z = -3.0\nw = 1.0"), "reference.position.w",
     "unknown field"),
    ("unknown-reference", "[reference.velocity]\nx = 1.0", "reference.velocity",
     "unknown field"),
    ("unknown-disturbance", "[disturbance.wind]\nx = 1.0", "disturbance.wind",
     "unknown field"),
    ("unknown-signal-key", f"[reference.attitude]\nroll = {_sine(', offst = 1.0')}",
     "reference.attitude.roll.offst", "unknown field"),
    ("frequency-key", "[reference.attitude_deg]\nroll = { type = \"sine\", amplitude = 1.0, "
     "frequency = 0.5 }", "reference.attitude_deg.roll.frequency", "rad/s"),
    ("unknown-signal-type", ("z = -3.0", 'z = { type = "square", amplitude = 1.0 }'),
     "reference.position.z.type", "expected one of 'constant'"),
    ("signal-without-type", ("z = -3.0", "z = { amplitude = 1.0 }"),
     "reference.position.z.type", "missing"),
    ("signal-string", ("z = -3.0", 'z = "-3"'), "reference.position.z", "expected a number, "
     "a table"),
    ("amplitude-string", "[reference.attitude_deg]\nroll = { type = \"sine\", amplitude = "
     "\"big\", omega = 0.5 }", "reference.attitude_deg.roll.amplitude", "expected a number"),
    ("sine-missing-omega", "[reference.attitude_deg]\nroll = { type = \"sine\", amplitude = "
     "1.0 }", "reference.attitude_deg.roll.omega", "missing"),
    ("sum-term-bad", ("z = -3.0", 'z = [-3.0, { type = "sine", omega = 1.0 }]'),
     "reference.position.z[2].amplitude", "missing"),
    ("steps-not-increasing", "[disturbance.acceleration]\nx = { type = \"steps\", times = "
     "[1.0, 3.0, 3.0], values = [1.0, 2.0, 0.0] }", "disturbance.acceleration.x.times",
     "strictly increasing"),
    ("steps-length", "[disturbance.force]\ny = { type = \"steps\", times = [1.0, 2.0], "
     "values = [1.0] }", "disturbance.force.y.values", "expected 2 values"),
    ("waypoints-empty", ("z = -3.0", 'z = { type = "waypoints", times = [], values = [] }'),
     "reference.position.z.times", "non-empty array"),
    ("chirp-t1-before-t0", ("z = -3.0", 'z = { type = "chirp", amplitude = 1.0, omega0 = 0.0,'
                            ' omega1 = 1.0, t0 = 5.0, t1 = 2.0 }'),
     "reference.position.z.t1", "after t0"),
    ("ramp-t1-before-t0", ("z = -3.0", 'z = { type = "ramp", from = 0.0, to = 1.0, t0 = 5.0,'
                           ' t1 = 5.0 }'), "reference.position.z.t1", "after t0"),
    ("both-attitudes", "[reference.attitude]\nroll = 0.1\n[reference.attitude_deg]\nroll = 1.0",
     "reference.attitude_deg", "not both"),
    ("unknown-fmu-parameter", "[plant]\nmasss = 1.0", "plant.masss", "no variable 'masss'"),
    ("output-not-parameter", "[controller]\nfeasible = true", "controller.feasible",
     "causality is parameter"),
    ("input-not-parameter", "[plant]\n\"a_d[1]\" = 1.0", "plant.a_d[1]",
     "causality is parameter"),
    ("boolean-for-real", "[plant]\nmass = true", "plant.mass", "expected a number"),
    ("real-for-boolean", "[plant]\ninit_trim = 1.0", "plant.init_trim", "expected true or false"),
    ("real-for-integer", "[controller]\nqp_max_iter = 20.5", "controller.qp_max_iter",
     "expected an integer"),
    ("integer-beyond-32-bits", "[plant]\nnoise_seed = 4294967297", "plant.noise_seed",
     "-2147483648..2147483647 (a 32-bit FMI Integer), got 4294967297"),
    ("integer-beyond-declared", "[controller]\nfail_poly_n = [0, 0, 0, 0, 0, 0, 0, 99]",
     "controller.fail_poly_n[8]", "0..32 (its declared range"),
    ("real-beyond-a-double", "[plant]\nmass = 1e400", "plant.mass",
     "expected a finite number, got 1e400"),
    ("signal-beyond-a-double", ("z = -3.0", "z = -1.8e308"), "reference.position.z",
     "expected a finite number, got -1.8e308"),
    ("vector-element-type", "[controller]\nK_pos_D = [1.0, false, 2.0]", "controller.K_pos_D[2]",
     "expected a number"),
    ("matrix-shape", "[plant]\ninertia = [0.1, 0.2, 0.3]", "plant.inertia",
     "3x3 matrix"),
    ("plant-not-table", "plant = 3", "plant", "expected a table"),
    ("rotor-beyond-airframe", "[[fault]]\ntime = 1.0\nrotor = 7\nefficiency = 0.0",
     "fault[1].rotor", "1..6"),
    ("rotor-zero", "[[fault]]\ntime = 1.0\nrotor = 0\nefficiency = 0.0", "fault[1].rotor",
     "1..6"),
    ("rotor-float", "[[fault]]\ntime = 1.0\nrotor = 1.0\nefficiency = 0.0", "fault[1].rotor",
     "expected an integer"),
    ("efficiency-above-1", "[[fault]]\ntime = 1.0\nrotor = 1\nefficiency = 1.5",
     "fault[1].efficiency", "0..1"),
    ("efficiency-negative", "[[fault]]\ntime = 1.0\nrotor = 1\nefficiency = 0.0\n[[fault]]\n"
     "time = 2.0\nrotor = 1\nefficiency = -0.1", "fault[2].efficiency", "0..1"),
    ("fault-time-negative", "[[fault]]\ntime = -1.0\nrotor = 1\nefficiency = 0.0",
     "fault[1].time", ">= 0"),
    ("fault-unknown-key", "[[fault]]\ntime = 1.0\nmotor = 1\nrotor = 1\nefficiency = 0.0",
     "fault[1].motor", "unknown field"),
    ("fault-duplicate", "[[fault]]\ntime = 1.0\nrotor = 1\nefficiency = 0.0\n[[fault]]\n"
     "time = 1.0\nrotor = 1\nefficiency = 0.5", "fault[2].time", "already has a fault"),
    ("fault-not-array", "fault = 1", "fault", "array of tables"),
    ("missing-airframe-file", ('airframe = "paper_hexacopter"', 'airframe = "nowhere/x.toml"'),
     "airframe", "no airframe file"),
    ("unknown-airframe-name", ('airframe = "paper_hexacopter"', 'airframe = "hexa9"'),
     "airframe", "expected one of"),
    ("airframe-missing", ('airframe = "paper_hexacopter"', ''), "airframe", "missing"),
    ("step-not-multiple", "step = 0.003", "step", "multiple of 0.002"),
    ("step-too-small", "step = 0.0005", "step", "multiple of 0.002"),
    ("step-negative", "step = -0.002", "step", "expected a positive number"),
    ("coupling-unknown", 'coupling = "parallel"', "coupling", "'gauss-seidel'"),
    ("ts-not-dividing-step", "[controller]\nTs = 0.004", "controller.Ts",
     "divides the communication step"),
]


def _apply(edit) -> str:
    if isinstance(edit, tuple):
        old, new = edit
        assert old in BASE
        return BASE.replace(old, new)
    if edit.lstrip().startswith("["):
        return BASE + "\n" + edit + "\n"
    return edit + "\n" + BASE  # a top-level key goes before the first table


@pytest.mark.parametrize(("edit", "field", "expect"), [c[1:] for c in INVALID],
                         ids=[c[0] for c in INVALID])
def test_invalid_files_fail_naming_file_field_and_expectation(tmp_path, edit, field, expect):
    path = write(tmp_path, _apply(edit))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    assert f"field '{field}'" in msg, msg
    assert expect in msg, msg
    assert info.value.field == field


def test_invalid_airframe_file_is_reported(tmp_path):
    write(tmp_path, 'name = "bad"\n[body]\nmass = -1.0\n', "bad_frame.toml")
    path = write(tmp_path, BASE.replace('"paper_hexacopter"', '"bad_frame.toml"'))
    with pytest.raises(ScenarioError, match=r"field 'airframe': invalid airframe: .*body\.mass"):
        load_scenario(path)


def test_unreadable_files(tmp_path):
    bad = write(tmp_path, "duration = = 3\n")
    with pytest.raises(ScenarioError, match=re.escape(str(bad)) + ".*not valid TOML"):
        load_scenario(bad)
    with pytest.raises(ScenarioError, match="file not found"):
        load_scenario(tmp_path / "absent.toml")
    with pytest.raises(ScenarioError, match="no such file or shipped scenario"):
        load_scenario("no_such_scenario")


def test_files_that_are_not_utf8_or_nest_too_deep_are_named(tmp_path):
    """A Latin-1 file and one nested thousands deep gave messages without the file ("'utf-8'
    codec can't decode byte 0xe9 ...", "maximum recursion depth exceeded")."""
    latin = tmp_path / "latin.toml"
    latin.write_bytes(BASE.replace('name = "t"', '# caf\xe9\nname = "t"').encode("latin-1"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(latin)
    assert str(info.value) == (f"{latin}: not UTF-8 text (byte 0xe9 at offset 5, line 1): "
                               "TOML files are UTF-8; save it as UTF-8")
    for depth, field in ((40, "controller.K_pos_D"), (5000, "")):
        deep = write(tmp_path, BASE + "[controller]\nK_pos_D = " + "[" * depth + "]" * depth
                     + "\n", f"deep{depth}.toml")
        with pytest.raises(ScenarioError) as info:
            load_scenario(deep)
        assert info.value.field == field
        assert str(info.value).startswith(f"{deep}: ")
        assert str(info.value).endswith("nested deeper than 32 levels of tables and arrays")
    tables = write(tmp_path, BASE + "[controller]\nx = " + "{a=" * 1000 + "1" + "}" * 1000
                   + "\n", "tables.toml")
    with pytest.raises(ScenarioError, match=re.escape(str(tables)) + ": nested deeper"):
        load_scenario(tables)
    # as deep as a file of ours goes is fine, and line ends of any kind read as before
    crlf = write(tmp_path, BASE.replace("\n", "\r\n"), "crlf.toml")
    assert load_scenario(crlf).duration == 10.0


def test_documented_example_loads(tmp_path):
    """The full example of docs/scenarios.md is a valid scenario."""
    text = (ROOT / "docs" / "scenarios.md").read_text()
    block = re.search(r"```toml\n(.*?)```", text, re.S)
    assert block is not None
    sc = load_scenario(write(tmp_path, block.group(1)))
    assert sc.faults and sc.plant_parameters and sc.controller_parameters
    ref = sc.references(np.linspace(0, sc.duration, 11))
    assert np.isfinite(np.concatenate(list(ref.values()), axis=1)).all()


# ---------------------------------------------------------------------------
# Plausibility checks (units): the oracle for the controller's Euler bounds is the installed
# FMU's modelDescription (its documented defaults are +-60 deg, docs/controller.md)

DEG = math.pi / 180.0


def _controller_start(name: str) -> float:
    from fmpy import read_model_description

    from controller import controller_fmu

    md = read_model_description(str(controller_fmu()))
    return float(next(v.start for v in md.modelVariables if v.name == name))


def _bounds(index: int) -> tuple[float, float]:
    return _controller_start(f"euler_min[{index}]"), _controller_start(f"euler_max[{index}]")


def _rejected(tmp_path: Path, text: str) -> ScenarioError:
    path = write(tmp_path, BASE + text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert str(info.value).startswith(f"{path}: field '{info.value.field}': "), info.value
    return info.value


def test_euler_bound_oracle_is_the_documented_default():
    for index in (1, 2):
        lo, hi = _bounds(index)
        assert lo == pytest.approx(-60 * DEG) and hi == pytest.approx(60 * DEG)


def test_radian_roll_amplitude_that_reads_as_degrees_is_an_error(tmp_path):
    err = _rejected(tmp_path, """
[reference.attitude]
roll = { type = "sine", amplitude = 40.0, omega = 0.5 }
""")
    lo, hi = _bounds(1)
    assert err.field == "reference.attitude.roll.amplitude"
    msg = str(err)
    assert "40 rad" in msg and f"{40 / DEG:.5g} deg" in msg, msg
    assert f"{lo:.5g}..{hi:.5g} rad" in msg and f"{lo / DEG:.5g}..{hi / DEG:.5g} deg" in msg, msg
    assert "if you meant degrees, use [reference.attitude_deg]" in msg, msg


def test_radian_attitude_inside_the_bounds_passes(tmp_path):
    sc = load_scenario(write(tmp_path, BASE + """
[reference.attitude]
roll = { type = "sine", amplitude = 0.5, omega = 0.5 }
pitch = [0.2, { type = "sine", amplitude = -0.5, omega = 0.3 }]
yaw = { type = "ramp", from = 0.0, to = 30.0, t0 = 0.0, t1 = 10.0 }
"""))
    assert sc.warnings == ()
    # yaw is not bounded by the controller: any angle, many turns
    assert sc.references(np.array([10.0]))["euler_ref"][0, 2] == 30.0


@pytest.mark.parametrize("t1", [5.0, 100.0])
def test_ramp_past_the_bound_is_an_error_even_after_the_run(tmp_path, t1):
    err = _rejected(tmp_path, f"""
[reference.attitude]
pitch = {{ type = "ramp", from = 0.0, to = 2.0, t0 = 1.0, t1 = {t1} }}
""")
    hi = _bounds(2)[1]
    assert 2.0 > hi
    assert err.field == "reference.attitude.pitch.to"
    msg = str(err)
    assert f"2 rad ({2 / DEG:.5g} deg)" in msg and f"{hi / DEG:.5g} deg" in msg, msg
    assert ("at t = 5 s" if t1 == 5.0 else "after this run's 10 s") in msg, msg
    assert "[reference.attitude_deg]" in msg  # 2 read as degrees is inside the bounds


def test_radian_value_out_of_bounds_also_in_degrees_says_so(tmp_path):
    msg = str(_rejected(tmp_path, "[reference.attitude]\nroll = 80.0\n"))
    assert "'reference.attitude.roll'" in msg
    assert "use [reference.attitude_deg] (80 deg is outside the bounds too)" in msg, msg
    far = _rejected(tmp_path, "[reference.attitude]\nroll = 400.0\n")
    assert "attitude_deg" not in str(far)  # 400 is no plausible angle in degrees either


def test_degree_attitude_inside_the_bounds_passes_and_outside_fails(tmp_path):
    lo, hi = _bounds(1)
    sc = load_scenario(write(tmp_path, BASE + f"""
[reference.attitude_deg]
roll = {{ type = "sine", amplitude = 40.0, omega = 0.5 }}
pitch = {hi / DEG!r}
"""))
    assert sc.warnings == ()
    err = _rejected(tmp_path, """
[reference.attitude_deg]
roll = { type = "sine", amplitude = 80.0, omega = 0.5 }
""")
    assert err.field == "reference.attitude_deg.roll.amplitude"
    msg = str(err)
    assert "80 deg" in msg and f"{lo / DEG:.5g}..{hi / DEG:.5g} deg" in msg, msg
    assert "euler_min[1], euler_max[1]" in msg and "use [reference.attitude_deg]" not in msg


def test_most_specific_field_of_a_sum(tmp_path):
    err = _rejected(tmp_path, """
[reference.attitude]
roll = [0.1, { type = "steps", times = [1.0, 2.0], values = [0.2, 30.0] }]
""")
    assert err.field == "reference.attitude.roll[2].values[2]"
    err = _rejected(tmp_path, """
[reference.attitude]
pitch = { type = "sum", terms = [0.1, { type = "sine", amplitude = 40.0, omega = 1.0 }] }
""")
    assert err.field == "reference.attitude.pitch.terms[2].amplitude"
    # neither term alone leaves the bounds: the sum's own field
    err = _rejected(tmp_path, """
[reference.attitude]
roll = [0.5, { type = "sine", amplitude = 0.7, omega = 0.5 }]
""")
    assert err.field == "reference.attitude.roll"


def test_controller_override_of_the_bounds_is_honoured(tmp_path):
    text = "[reference.attitude_deg]\nroll = 70.0\n"
    assert 70 * DEG > _bounds(1)[1]
    assert _rejected(tmp_path, text).field == "reference.attitude_deg.roll"
    sc = load_scenario(write(tmp_path, BASE + text + "[controller]\n"
                             "euler_min = [-1.3, -1.0]\neuler_max = [1.3, 1.0]\n"))
    assert sc.controller_parameters["euler_max[1]"] == 1.3
    # a narrower bound given on top of a valid scenario is checked too
    paper = load_scenario("hover_varying_orientation")  # roll amplitude 0.7 rad
    with pytest.raises(ScenarioError) as info:
        with_overrides(paper, settings=["controller.euler_max[1]=0.5"])
    assert info.value.field == "reference.attitude.roll.amplitude"
    assert "euler_min[1], euler_max[1] as overridden" in str(info.value)
    err = _rejected(tmp_path, "[controller]\n\"euler_max[2]\" = 2.0\n")
    assert err.field == "controller.euler_max[2]" and "(-pi/2, pi/2)" in str(err)


def test_yaw_is_unbounded_but_a_radian_swing_beyond_a_turn_is_an_error(tmp_path):
    err = _rejected(tmp_path, """
[reference.attitude]
yaw = { type = "sine", amplitude = 90.0, omega = 0.5 }
""")
    assert err.field == "reference.attitude.yaw.amplitude"
    assert "full turn" in str(err) and "use [reference.attitude_deg]" in str(err)
    for ok in ("yaw = 7.0", 'yaw = { type = "sine", amplitude = 3.0, omega = 0.5, offset = 20.0 }',
               'yaw = { type = "steps", times = [1.0], values = [90.0] }'):
        assert load_scenario(write(tmp_path, BASE + "[reference.attitude]\n" + ok + "\n"))
    assert load_scenario(write(tmp_path, BASE + """
[reference.attitude_deg]
yaw = { type = "sine", amplitude = 90.0, omega = 0.5 }
"""))


def test_far_position_step_is_a_warning_naming_the_field(tmp_path):
    path = write(tmp_path, BASE.replace("z = -3.0", "z = -3.0\nx = { type = \"steps\", "
                                        "times = [5.0], values = [1000.0] }"))
    sc = load_scenario(path)
    assert sc.warnings == (
        f"{path}: field 'reference.position.x': a step of 1000 m (from 0 to 1000 m at t = 5 s) "
        "while the rest of the trajectory stays within 3 m of the origin; is this the "
        "intended unit (m)?",)
    assert with_overrides(sc, settings=["plant.noise_pos=0.01"]).warnings == sc.warnings
    assert with_overrides(sc, duration=4.0).warnings == ()  # the step is after the run
    near = load_scenario(write(tmp_path, BASE.replace("z = -3.0", "z = -3.0\nx = { type = "
                                                      "\"steps\", times = [5.0], values = "
                                                      "[2.0] }")))
    assert near.warnings == ()


def test_large_but_proportionate_trajectory_is_no_warning(tmp_path):
    """400 m in 40 s (a minimum-jerk peak of 1.875 x 10 m/s) beside a 20 m sine at 30 m."""
    sc = load_scenario(write(tmp_path, BASE.replace("duration = 10.0", "duration = 40.0")
                             .replace("z = -3.0", """\
x = { type = "waypoints", times = [0.0, 40.0], values = [0.0, 400.0] }
y = { type = "sine", amplitude = 20.0, omega = 0.5 }
z = -30.0""")))
    assert sc.warnings == ()


def test_millimetres_are_warnings_naming_the_field(tmp_path):
    """A scenario written in millimetres (the issue's: a 1 m step flown at 3 m, as 1000
    and -3000) flew without a word and reported a 1000 m error.  Now the step, a move of
    more than 100 m at a speed no multirotor flies, and the altitude, more than 1000 m from
    the origin, are warnings naming their fields; so is a fast 400 m move."""
    path = write(tmp_path, BASE.replace("z = -3.0", """\
x = { type = "steps", times = [1.0], values = [1000.0] }
z = -3000.0"""))
    sc = load_scenario(path)
    assert sc.warnings == (
        f"{path}: field 'reference.position.x': a step of 1000 m (from 0 to 1000 m at t = 1 s): "
        "a move of more than 100 m faster than a multirotor flies (50 m/s); is this the "
        "intended unit (m)? In millimetres it would be 1 m",
        f"{path}: field 'reference.position.z': the reference is -3000 m at t = 0 s, more "
        "than 1000 m from the origin; is this the intended unit (m)? In millimetres it would "
        "be -3 m")
    fast = load_scenario(write(tmp_path, BASE.replace("z = -3.0", """\
x = { type = "waypoints", times = [0.0, 10.0], values = [0.0, 400.0] }
y = { type = "sine", amplitude = 20.0, omega = 0.5 }
z = -30.0""")))
    (warning,) = fast.warnings
    assert "field 'reference.position.x': an excursion of 400 m" in warning
    assert "at up to 75 m/s" in warning and "faster than a multirotor flies" in warning
    slow = load_scenario(write(tmp_path, BASE.replace("z = -3.0", """\
x = { type = "ramp", from = 0.0, to = 300.0, t0 = 0.0, t1 = 10.0 }
z = -999.0""")))
    assert slow.warnings == ()  # 30 m/s, and within a kilometre


@pytest.mark.parametrize(("body", "field", "what"), [
    ('x = { type = "sine", amplitude = 1e308, omega = 1e308 }', "reference.position.x",
     "its value overflows"),
    ('x = { type = "sine", amplitude = 1e290, omega = 1e10 }', "reference.position.x",
     "its second derivative overflows"),
    ('x = { type = "ramp", from = -1e308, to = 1e308, t0 = 0.0, t1 = 1.0 }',
     "reference.position.x", "its value overflows at t = 0 s"),
    ('y = { type = "waypoints", times = [0.0, 1e-300], values = [0.0, 1e10] }',
     "reference.position.y", "its second derivative overflows at t = 0 s"),
    ('[reference.attitude_deg]\nyaw = { type = "sine", amplitude = 300.0, omega = 1e308 }',
     "reference.attitude_deg.yaw", "its value overflows at t = 1.798 s"),
    ('[disturbance.force]\nz = [1.7e308, 1.7e308]', "disturbance.force.z", "its value"),
])
def test_signals_that_overflow_are_errors_naming_the_field(tmp_path, body, field, what):
    """Numbers a file may hold whose signal overflows a double (it ended in an
    OverflowError traceback or in NaN start values)."""
    err = _rejected(tmp_path, body + "\n")
    assert err.field == field
    assert what in str(err) and "too large for a double" in str(err), str(err)


def test_shipped_and_documented_scenarios_have_no_warnings(tmp_path):
    for sc in list_scenarios():
        assert sc.warnings == (), sc.name
    text = (ROOT / "docs" / "scenarios.md").read_text()
    block = re.search(r"```toml\n(.*?)```", text, re.S)
    assert block is not None
    assert load_scenario(write(tmp_path, block.group(1))).warnings == ()


def test_value_range_bounds_the_samples():
    t = np.linspace(0.0, 400.0, 400001)
    for name, (signal, _) in SIGNALS.items():
        ends = value_range(signal)
        v = signal.value(t)
        if name == "sum":  # a sine and a ramp: two varying terms, no closed form
            assert ends is None
            continue
        assert ends is not None, name
        assert ends[0] <= v.min() + 1e-12 and v.max() <= ends[1] + 1e-12, name
        assert v.min() == pytest.approx(ends[0], abs=1e-6), name
        assert v.max() == pytest.approx(ends[1], abs=1e-6), name
    assert value_range(Sum((Constant(0.5), Sine(0.7, 1.0)))) == (pytest.approx(-0.2), 1.2)
