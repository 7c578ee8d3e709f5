"""The controller FMU configures itself for any airframe: the force sets it derives in C at
initialization against the scipy design tool, refusals with their causes, and the FMU
alone (only airframe parameters set) flying the closed loop of ``fullpose run``.

Oracles: controller.force_sets / controller.failures (scipy HiGHS LPs on a finer servo grid,
independent code), scipy's LP for support functions, the shipped design-time sets, statics.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from helpers import problems
from helpers.airframe_kinds import KINDS, load_kind, write_kind

import plant
from controller import controller_fmu
from controller.derived_sets import controller_sets, derive_force_set
from controller.failures import airframe_without
from controller.force_sets import feasible_force_set
from controller.polytope import set_support
from controller.polytope_cache import design_set_parameters, shipped
from orchestrator.master import run
from orchestrator.runner import prepare
from orchestrator.sim.fmu import FmuInstance

H = 0.002
SHIPPED = plant.list_airframes()


def _agree(derived, A, b, inner_points, gap, scale):
    """The controller's set against the design tool's {A f <= b}: it contains every force the
    design tool found attainable (inner points, to round-off), and the two reach beyond each
    other by no more than the design tool's own approximation gap (the Hausdorff distance
    between its inner and outer hulls: the true set lies between them)."""
    tol = 1e-9 * scale
    assert np.max(inner_points @ derived.A.T - derived.b) <= tol
    beyond_design = max(set_support(derived.A, derived.b, a) - bb for a, bb in zip(A, b,
                                                                                     strict=True))
    beyond_derived = max(set_support(A, b, a) - bb for a, bb in zip(derived.A, derived.b,
                                                                       strict=True))
    assert beyond_design <= gap + tol, (beyond_design, gap)
    assert beyond_derived <= gap + tol, (beyond_derived, gap)
    return beyond_design, beyond_derived


@pytest.mark.parametrize("name", SHIPPED)
def test_derived_s0_agrees_with_the_shipped_design_sets(name):
    af = plant.load_airframe(name)
    doc = shipped(af)
    assert doc is not None
    from controller.polytope_cache import polytope_from_doc

    s0 = polytope_from_doc(doc["s0"])
    sets = controller_sets(af)
    assert sets.s0.dimension == s0.dimension
    _agree(sets.s0, s0.A, s0.b, s0.inner_points, s0.gap, s0.scale)


@pytest.mark.parametrize("name", SHIPPED)
def test_derived_failure_sets_agree_with_the_shipped_ones(name):
    """Each rotor's failure set against the design tool's (shipped parameters): the same
    emptiness, and hover possible in the same cases; the sets agree within the design tool's
    gap, taken from its S(0) without that rotor (oracle: controller.force_sets)."""
    af = plant.load_airframe(name)
    params = design_set_parameters(af)
    sets = controller_sets(af)
    hover = np.array([0.0, 0.0, -af.mass * af.gravity])
    for i, derived in enumerate(sets.failures):
        n = int(params[f"fail_poly_n[{i + 1}]"])
        assert (derived is None) == (n == 0), i
        if derived is None:
            continue
        rows = range(32 * i + 1, 32 * i + n + 1)
        A = np.array([[params[f"fail_poly_A[{r},{j}]"] for j in (1, 2, 3)] for r in rows])
        b = np.array([params[f"fail_poly_b[{r}]"] for r in rows])
        assert np.all(derived.A @ hover <= derived.b + 1e-9) == np.all(A @ hover <= b + 1e-9)
        if af.tilting and i > 0:
            continue  # (one scipy oracle per tilting airframe keeps the fast tier fast)
        design = feasible_force_set(airframe_without(af, [i]), n_directions=32)
        _agree(derived, A, b, design.inner_points, design.gap, design.scale)


@pytest.mark.heavy
@pytest.mark.parametrize("kind", ["tilting_quadrotor", "canted_hexarotor"])
def test_derived_s0_agrees_with_the_design_tool_on_other_kinds(kind, tmp_path):
    af = load_kind(kind, tmp_path)
    design = feasible_force_set(af)
    derived = controller_sets(af).s0
    assert derived.dimension == design.dimension == 3
    _agree(derived, design.A, design.b, design.inner_points, design.gap, design.scale)


@pytest.mark.heavy
@pytest.mark.parametrize("kind", ["tilting_octocopter", "heavy_tilting_hexacopter"])
def test_derived_s0_agrees_with_the_design_tool_on_large_kinds(kind, tmp_path):
    af = load_kind(kind, tmp_path)
    design = feasible_force_set(af)
    sets = controller_sets(af)
    _agree(sets.s0, design.A, design.b, design.inner_points, design.gap, design.scale)
    assert all(f is not None for f in sets.failures)


def test_a_vertical_rotor_set_is_the_exact_thrust_segment():
    """X8 (vertical rotors): S(0) is the segment [0, 0, -sum T_max] .. 0 (statics: zero
    torque at equal thrusts of coaxial pairs, every thrust from 0 to T_max); losing a rotor
    halves what its arm's pair gives, so the segment ends at -(n - 1) T_max... limited by the
    arm balance: the opposite arm's pair cannot exceed the damaged arm's single rotor."""
    af = plant.load_airframe("x8_coaxial")
    t_max = af.k_t * af.omega_max ** 2
    sets = controller_sets(af)
    assert sets.s0.dimension == 1
    down = np.array([0.0, 0.0, 1.0])
    assert set_support(sets.s0.A, sets.s0.b, -down) == pytest.approx(8 * t_max, rel=1e-9)
    assert set_support(sets.s0.A, sets.s0.b, down) == pytest.approx(0.0, abs=1e-9)
    for f in sets.failures:
        assert f is not None and f.dimension == 1
        up = set_support(f.A, f.b, -down)
        assert 4 * t_max - 1e-9 <= up <= 7 * t_max + 1e-9


# -- the controller FMU derives them itself ---------------------------------------------------


def _airframe_params(af, inst: FmuInstance) -> dict[str, float | int | bool]:
    names = {v.name for v in inst.md.modelVariables if v.causality == "parameter"}
    return {k: v for k, v in af.fmu_parameters().items() if k in names}


def _init_ctrl(af, extra=None, pos_ref=(0.0, 0.0, -3.0)):
    c = FmuInstance(controller_fmu(), "ctrl")
    c.slave.setupExperiment(startTime=0.0)
    c.set_many({**_airframe_params(af, c), **(extra or {})})
    alpha, beta, omega = af.hover_trim()
    n = af.n_rotors
    c.write(c.signal("omega"), np.concatenate([omega, np.zeros(8 - n)]))
    c.write(c.signal("alpha"), np.concatenate([alpha, np.zeros(8 - n)]))
    c.write(c.signal("beta"), np.concatenate([beta, np.zeros(8 - n)]))
    c.write(c.signal("pos_ref"), pos_ref)
    c.write(c.signal("pos"), pos_ref)
    c.slave.enterInitializationMode()
    return c


@pytest.mark.parametrize("name", ["x8_coaxial", "y6", "quadrotor"])
def test_the_fmu_with_only_airframe_parameters_hovers_without_false_warnings(name):
    af = plant.load_airframe(name)
    c = _init_ctrl(af)
    try:
        c.slave.exitInitializationMode()
        log = problems(c)
        assert "leaves no hover force" not in log or name == "quadrotor", log
        for _ in range(50):
            c.step(H)
        _, _, omega = af.hover_trim()
        cmd = np.array(c.read(c.signal("omega_cmd")))[: af.n_rotors]
        # statics: the commanded rotor speeds hold the weight (sum k_t w^2 = m g)
        assert af.k_t * np.sum(cmd ** 2) == pytest.approx(af.mass * af.gravity, rel=2e-3)
        assert np.allclose(cmd, omega, rtol=2e-3)
    finally:
        c.close()


def test_a_quadrotor_warns_once_that_no_single_loss_can_hover():
    af = plant.load_airframe("quadrotor")
    c = _init_ctrl(af)
    try:
        c.slave.exitInitializationMode()
        warnings = [m for s, _, m in c.messages if s == "WARNING" and "hover force" in m]
        # losing one rotor of a quadrotor leaves no zero-torque force at all: no set, no
        # warning per rotor
        assert len(warnings) <= 1, warnings
    finally:
        c.close()


def test_another_vehicles_sets_are_refused():
    """The paper hexacopter's S(0) given to an X8: it claims lateral force an X8 has none of."""
    hexa = plant.load_airframe("paper_hexacopter")
    sets = design_set_parameters(hexa)
    s0 = {k: v for k, v in sets.items() if k.startswith("poly_")}
    c = _init_ctrl(plant.load_airframe("x8_coaxial"), s0)
    try:
        with pytest.raises(FMICallException):
            c.slave.exitInitializationMode()
        log = problems(c)
        assert "poly_A, poly_b" in log and "another vehicle" in log, log
    finally:
        c.close()


def test_given_sets_of_this_vehicle_are_used_as_given():
    """The design tool's S(0) for the paper hexacopter passes the check (it differs from the
    derived one by less than the 10 % tolerance); a smaller one (a margin: offsets shrunk
    about the hover force) passes too and is the one flown: the shaping's vertical
    acceleration limit the FMU reports is the one that set's f_z range gives (oracle:
    scipy's LP for the range, the documented formula of docs/controller.md)."""
    from scipy.optimize import linprog

    af = plant.load_airframe("paper_hexacopter")
    params = design_set_parameters(af)
    n = int(params["poly_n"])
    A = np.array([[params[f"poly_A[{i},{j}]"] for j in (1, 2, 3)] for i in range(1, n + 1)])
    b = np.array([params[f"poly_b[{i}]"] for i in range(1, n + 1)])
    hover = np.array([0.0, 0.0, -af.mass * af.gravity])
    small = A @ hover + 0.6 * (b - A @ hover)
    given = {**{k: v for k, v in params.items() if k.startswith("poly_")},
             **{f"poly_b[{i + 1}]": float(v) for i, v in enumerate(small)}}
    limits = []
    for extra in ({}, given):
        c = _init_ctrl(af, extra)
        try:
            c.slave.exitInitializationMode()
            assert "another vehicle" not in problems(c)
            limits.append(np.array(c.read(c.signal("ref_acc_limit"))))
        finally:
            c.close()
    z = [linprog(sign * np.array([0.0, 0.0, 1.0]), A_ub=A, b_ub=small,
                 bounds=[(None, None)] * 3).fun * sign for sign in (1.0, -1.0)]
    margin, g, tilt = 0.9, af.gravity, math.radians(15.0)
    fz_min, fz_max = (hover[2] + margin * (v - hover[2]) for v in z)
    up, least = -fz_min / af.mass, -fz_max / af.mass
    a_z = 0.5 * min(up * math.cos(tilt) - g, g - least)
    assert limits[1][1] == pytest.approx(max(a_z, 0.05 * g), rel=1e-9)
    assert limits[1][1] < limits[0][1]  # the smaller set is the one in use


def _refused(fmu, af) -> str:
    """The log of an FMU given only ``af``'s parameters, which must refuse to initialize."""
    inst = FmuInstance(fmu, "refused")
    try:
        inst.slave.setupExperiment(startTime=0.0)
        inst.set_many(_airframe_params(af, inst))
        inst.slave.enterInitializationMode()
        with pytest.raises(FMICallException):
            inst.slave.exitInitializationMode()
        return problems(inst)
    finally:
        inst.close()


def test_too_heavy_a_vehicle_is_refused_with_its_cause():
    af = plant.load_airframe("x8_coaxial")
    heavy = dataclasses.replace(af, mass=af.k_t * af.omega_max ** 2 * 8 / af.gravity * 1.2)
    log = _refused(controller_fmu(), heavy)
    assert "derived from the airframe" in log and "cannot hold" in log, log


def _no_authority(af, kind):
    pos = af.positions.copy()
    if kind == "centre":
        pos[:] = 0.0
    elif kind == "coincident":
        pos[1] = pos[0]
    else:  # all on the x axis (through the centre)
        pos[:, 1] = 0.0
        pos[:, 2] = 0.0
        pos[:, 0] = np.linspace(-0.2, 0.2, af.n_rotors)
    return dataclasses.replace(af, positions=pos)


@pytest.mark.parametrize("kind,expect", [("centre", "same position"),
                                         ("coincident", "same position"),
                                         ("line", "moment arms")])
@pytest.mark.parametrize("fmu", ["plant", "controller"])
def test_no_control_authority_is_refused_by_both_fmus(kind, expect, fmu):
    af = _no_authority(plant.load_airframe("quadrotor"), kind)
    log = _refused(plant.plant_fmu() if fmu == "plant" else controller_fmu(), af)
    assert "rotor_pos" in log and expect in log, log


def test_a_bicopter_that_tilts_keeps_its_authority():
    """Two rotors on the y axis: without servos no pitch torque (refused); with servos the
    tilt gives it (accepted by the authority check)."""
    from plant.airframe import parse_airframe

    doc = {"name": "bi", "body": {"mass": 0.5, "inertia": [0.01, 0.005, 0.01]},
           "propulsion": {"k_t": 1.14e-4, "k_d": 1.14e-6, "omega_max_rpm": 2000,
                          "time_constant": 0.02},
           "rotor": [{"position": [0.0, 0.2, 0.0], "spin": 1},
                     {"position": [0.0, -0.2, 0.0], "spin": -1}]}
    fixed = parse_airframe(doc)
    tilting = parse_airframe({**doc, "servo": {"time_constant": 0.02,
                                               "alpha_limits_deg": [-30, 30],
                                               "beta_limits_deg": [-30, 30]}})
    for af, refused in ((fixed, True), (tilting, False)):
        inst = FmuInstance(plant.plant_fmu(), "plant")
        try:
            names = {v.name for v in inst.md.modelVariables if v.causality == "parameter"}
            inst.slave.setupExperiment(startTime=0.0)
            inst.set_many({k: v for k, v in af.fmu_parameters().items() if k in names})
            inst.slave.enterInitializationMode()
            if refused:
                with pytest.raises(FMICallException):
                    inst.slave.exitInitializationMode()
            else:
                inst.slave.exitInitializationMode()
            assert ("moment arms" in problems(inst)) == refused
        finally:
            inst.close()


# -- the FMU alone flies what `fullpose run` flies ---------------------------------------------


def _fmu_alone(af, pos0, reference, duration):
    """Both FMUs in fmpy, connected by name, the controller given only the airframe's
    parameters: positions at every step (controller samples y_k, then the plant steps)."""
    p = FmuInstance(plant.plant_fmu(), "plant")
    c = FmuInstance(controller_fmu(), "ctrl")
    try:
        p_names = {v.name for v in p.md.modelVariables if v.causality == "parameter"}
        params = {k: v for k, v in af.fmu_parameters().items() if k in p_names}
        params.update({f"pos0[{i + 1}]": float(v) for i, v in enumerate(pos0)})
        p.initialize(parameters=params)
        p_out = {v.name for v in p.md.modelVariables if v.causality == "output"}
        c_in = [v.name for v in c.md.modelVariables if v.causality == "input"]
        c_out = {v.name for v in c.md.modelVariables if v.causality == "output"}
        p_in = [v.name for v in p.md.modelVariables if v.causality == "input"]
        measured = [n for n in c_in if n in p_out]
        commands = [n for n in p_in if n in c_out]
        y_p, y_c = p.signal(measured), c.signal(measured)
        u_c, u_p = c.signal(commands), p.signal(commands)
        ref = c.signal(["pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref"])
        c.slave.setupExperiment(startTime=0.0)
        c.set_many(_airframe_params(af, c))
        c.slave.enterInitializationMode()
        c.write(y_c, p.read(y_p))
        c.write(ref, reference(0.0))
        c.slave.exitInitializationMode()
        n = round(duration / H)
        pos = np.empty((n + 1, 3))
        pos[0] = p.read(p.signal("pos"))
        for k in range(n):
            c.write(ref, reference(k * H))
            c.write(y_c, p.read(y_p))
            c.step(H)
            p.write(u_p, c.read(u_c))
            p.step(H)
            pos[k + 1] = p.read(p.signal("pos"))
        return pos
    finally:
        p.close()
        c.close()


def _step_scenario(tmp_path, airframe):
    path = tmp_path / "step.toml"
    path.write_text(f'duration = 5.0\nairframe = "{airframe}"\n'
                    '[reference.position]\nx = { type = "steps", times = [1.0], '
                    'values = [1.0] }\nz = -3.0\n')
    return path


def _step_reference(t):
    return np.array([1.0 if t >= 1.0 else 0.0, 0, -3.0] + [0.0] * 12)


def test_the_fmu_alone_flies_the_run_bit_for_bit_where_both_derive(tmp_path):
    """A tilting quadrotor (no shipped sets): `fullpose run` passes no sets, the FMU alone
    gets none, both derive the same ones: the same trajectory to the bit."""
    path = write_kind("tilting_quadrotor", tmp_path)
    af = plant.load_airframe(path)
    assert design_set_parameters(af) == {}
    result = run(prepare(_step_scenario(tmp_path, path)), progress=False)
    alone = _fmu_alone(af, (0.0, 0.0, -3.0), _step_reference, 5.0)
    assert alone.shape == result.get("plant.pos").shape
    assert np.array_equal(alone, result.get("plant.pos"))
    assert abs(alone[-1, 0] - 1.0) < 0.02  # and it flew the step


def test_the_fmu_alone_flies_the_x8_like_the_run(tmp_path):
    """The X8: `fullpose run` passes the shipped design sets, the FMU alone derives its own;
    the two closed loops differ by far less than the paper's 2 cm (measured: 0 for a
    vertical-rotor vehicle, whose sets are exact segments either way)."""
    af = plant.load_airframe("x8_coaxial")
    result = run(prepare(_step_scenario(tmp_path, "x8_coaxial")), progress=False)
    alone = _fmu_alone(af, (0.0, 0.0, -3.0), _step_reference, 5.0)
    assert np.max(np.abs(alone - result.get("plant.pos"))) < 1e-6


def test_kinds_module_is_complete():
    assert set(KINDS) == {"tilting_quadrotor", "tilting_octocopter", "canted_hexarotor",
                          "heavy_tilting_hexacopter"}
    assert math.isfinite(derive_force_set(plant.load_airframe("y6")).b.sum())


@pytest.mark.parametrize("airframe", ["x8_coaxial", "y6"])
def test_run_detects_an_undeclared_loss_and_flies_the_vehicles_own_failure_set(airframe,
                                                                               tmp_path):
    """Hover, a 1 m step at 1 s, rotor 1's propeller gone at 5 s without telling the
    controller: it finds the rotor, idles its motor at the probe speed, switches to that
    vehicle's set after losing rotor 1 (the set holds the hover force: statics of the
    remaining rotors), and the step is held within the paper's 2 cm before and 5 cm after
    the loss."""
    path = tmp_path / "loss.toml"
    path.write_text(f'duration = 8.0\nairframe = "{airframe}"\nfault_detection = "none"\n'
                    '[reference.position]\nx = { type = "steps", times = [1.0], '
                    'values = [1.0] }\nz = -3.0\n'
                    "[[fault]]\ntime = 5.0\nrotor = 1\nefficiency = 0.0\n")
    result = run(prepare(path), progress=False)
    t = result.time
    pos = result.get("plant.pos")
    err = np.linalg.norm(pos - result.get("ctrl.pos_ref_s"), axis=1)
    k5 = int(np.searchsorted(t, 5.0))
    assert err[:k5].max() < 0.02
    assert err[k5:].max() < 0.05 and abs(pos[-1, 0] - 1.0) < 0.01
    detected = np.flatnonzero(result.get("ctrl.rotors_detected") > 0)
    assert detected.size and t[detected[0]] - 5.0 < 0.1
    assert result.get("ctrl.active_polytope")[-1] == 1
    assert result.get("ctrl.hover_possible")[-1] == 1
    # the lost rotor idles at the probe speed (at most 30 % of its share of the weight at
    # full efficiency: its thrust, if any, shows and restores it), far below hover
    af = plant.load_airframe(airframe)
    probe = math.sqrt(0.3 * af.mass * af.gravity / (af.n_rotors * af.k_t))
    assert 0.0 < result.get("ctrl.omega_cmd")[-1, 0] <= probe * (1 + 1e-9)
    # that set is this vehicle's (oracle: the controller's own derivation for this airframe)
    own = derive_force_set(plant.load_airframe(airframe), (1,))
    hover = np.array([0.0, 0.0, -plant.load_airframe(airframe).mass * 9.81])
    assert own is not None and np.all(own.A @ hover <= own.b + 1e-9)
