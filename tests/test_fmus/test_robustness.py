"""The models and the solver under inputs an importer may send: no NaN with fmi2OK, no silent
loss of control, no answer the data do not support (docs/robustness.md).

Each test reproduces a finding of the robustness review; it failed on the code before the
fix: the plant integrated to NaN and answered fmi2OK, the controller answered inf with
fmi2OK and one absurd sample disabled the guidance for minutes, the solver called a
violated point optimal after a huge warm start and a tiny row a zero row.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from helpers import logged

from controller import controller_fmu
from controller.wls import solve
from orchestrator.sim.fmu import FmuInstance
from orchestrator.sim.start_values import Pose, start_values
from plant import load_airframe, plant_fmu

H = 0.002
ACTUATORS = ["omega", "alpha", "beta"]
COMMANDS = ["omega_cmd", "alpha_cmd", "beta_cmd"]


def _plant_at_trim(inst: FmuInstance) -> None:
    af = load_airframe("paper_hexacopter")
    inst.initialize(parameters={**af.fmu_parameters(), "init_trim": True})
    inst.write(inst.signal(COMMANDS), inst.read(inst.signal(ACTUATORS)))


def test_plant_refuses_a_step_that_leaves_the_physical_range_and_keeps_its_state():
    with FmuInstance(plant_fmu(), "plant") as inst:
        _plant_at_trim(inst)
        outputs = inst.signal(["pos", "vel", "euler", "rate", "acc"])
        inst.write(inst.signal("tau_d"), [1000.0, 0.0, 0.0])
        before = None
        with pytest.raises(FMICallException):
            for _ in range(50):  # 1000 N m on 0.004 kg m^2 passes 1000 rad/s within ms
                before = inst.read(outputs).copy()
                inst.step(H)
                assert np.all(np.isfinite(inst.read(outputs)))
        assert any("rate[1]" in m and "physical range" in m
                   for m in logged(inst, "ERROR", "WARNING")), inst.messages
        after = inst.read(outputs)
        assert np.all(np.isfinite(after))
        np.testing.assert_array_equal(after, before)  # the state from before the step


def test_plant_in_closed_loop_never_answers_nan_with_ok():
    """The review's closed-loop case: a 5 N m torque step; every answered step is finite,
    and the vehicle is either held or the plant refuses with a message."""
    af = load_airframe("paper_hexacopter")
    sv = start_values(af, Pose.of((0.0, 0.0, -3.0)))
    with FmuInstance(plant_fmu(), "plant") as p, FmuInstance(controller_fmu(), "ctrl") as c:
        p.initialize(parameters=sv.plant)
        c.initialize(parameters={**sv.controller, "pos_ref[3]": -3.0})
        y_names = ["pos", "vel", "acc", "euler", "rate", *ACTUATORS]
        y_p, y_c = p.signal(y_names), c.signal(y_names)
        u_c, u_p = c.signal(COMMANDS), p.signal(COMMANDS)
        c.write(c.signal("pos_ref"), [0.0, 0.0, -3.0])
        p.write(p.signal("tau_d"), [5.0, 0.0, 0.0])
        refused = False
        for _ in range(2000):
            c.write(y_c, p.read(y_p))
            c.step(H)
            u = c.read(u_c)
            assert np.all(np.isfinite(u))
            p.write(u_p, u)
            try:
                p.step(H)
            except FMICallException:
                refused = True
                break
            assert np.all(np.isfinite(p.read(y_p)))
        assert refused or np.all(np.isfinite(p.read(y_p)))
        if refused:
            assert any("physical range" in m for m in logged(p, "ERROR", "WARNING"))


def _hovering_controller(c: FmuInstance):
    af = load_airframe("paper_hexacopter")
    with FmuInstance(plant_fmu(), "plant") as p:
        _plant_at_trim(p)
        y = {n: p.read(p.signal(n)).copy() for n in ["pos", "vel", "acc", "euler", "rate",
                                                        *ACTUATORS]}
    c.enter_initialization(0.0, start_values(af, Pose.of()).controller)
    for n, v in y.items():
        c.write(c.signal(n), v)
    c.write(c.signal("pos_ref"), y["pos"])
    c.exit_initialization()
    return y


def test_one_absurd_measurement_is_held_and_control_recovers_at_once():
    with FmuInstance(controller_fmu(), "ctrl") as c:
        y = _hovering_controller(c)
        pos = c.signal("pos")
        status = c.signal(["f_b_c", "omega_cmd"])
        c.step(H)
        held = c.read(status).copy()
        assert c.get("guid_status") == 0
        c.write(pos, [1e300, y["pos"][1], y["pos"][2]])  # finite, absurd
        c.step(H)
        np.testing.assert_array_equal(c.read(status), held)  # last valid command held
        assert any("pos[1]" in m and "plausible range" in m
                   for m in logged(c, "ERROR", "WARNING")), c.messages
        c.write(pos, y["pos"])
        c.step(H)  # the next sane sample: the guidance works again, nothing poisoned
        assert c.get("guid_status") == 0
        assert np.all(np.isfinite(c.read(status)))
        np.testing.assert_allclose(c.read(status), held, rtol=1e-6, atol=1e-6)
        assert any("control resumed" in m for m in logged(c, "ERROR", "WARNING"))


def test_an_absurd_reference_is_refused_loudly_not_flown():
    """acc_ref = 1e300 is finite: it used to reach the outputs (f_b_ref ~ 7e299, inf after
    the rotation sums); now the command is held with a warning naming it."""
    with FmuInstance(controller_fmu(), "ctrl") as c:
        _hovering_controller(c)
        c.step(H)
        outputs = c.signal(["f_b_ref", "f_b_c", "acc_c", "omega_cmd", "mu_c", "dnu_c"])
        good = c.read(outputs).copy()
        c.write(c.signal("acc_ref"), [1e300, 0.0, 0.0])
        c.step(H)
        got = c.read(outputs)
        assert np.all(np.isfinite(got))
        np.testing.assert_array_equal(got, good)
        assert any("acc_ref[1]" in m and "plausible range" in m
                   for m in logged(c, "ERROR", "WARNING")), c.messages
        c.write(c.signal("acc_ref"), [0.0, 0.0, 0.0])
        c.step(H)
        assert c.get("guid_status") == 0
        np.testing.assert_allclose(c.read(outputs), good, rtol=1e-6, atol=1e-6)


def test_a_huge_warm_start_neither_widens_the_feasibility_tolerance_nor_is_trusted(piqp_solve):
    rng = np.random.default_rng(3)
    n, m, p = 4, 6, 3
    A, b = rng.normal(size=(m, n)), rng.normal(size=m)
    C, d = rng.normal(size=(p, n)), rng.uniform(0.1, 1.0, p)
    lb, ub = -np.ones(n), np.ones(n)
    _, ref = piqp_solve(A, b, lb, ub, C, d)
    res = solve(A, b, lb, ub, C, d, x0=np.full(n, 1e15))
    assert res.status == "optimal"
    assert np.max(C @ res.x - d) <= 1e-9
    np.testing.assert_allclose(res.x, ref, atol=1e-7)


@pytest.mark.parametrize("tiny", [1e-170, 1e-300])
def test_a_row_of_tiny_norm_is_a_constraint_not_a_zero_row(tiny):
    """C x <= d scaled by 1e-170 (its squares underflow) is the same constraint."""
    rng = np.random.default_rng(5)
    n, m = 3, 5
    A, b = rng.normal(size=(m, n)), rng.normal(size=m) + 3.0
    C = np.array([[1.0, 1.0, 1.0]])
    d = np.array([0.5])
    ref = solve(A, b, None, None, C, d)
    assert ref.status == "optimal"
    res = solve(A, b, None, None, C * tiny, d * tiny)
    assert res.status == "optimal", res
    np.testing.assert_allclose(res.x, ref.x, rtol=1e-9, atol=1e-12)


@contextmanager
def _ready(model: str) -> Iterator[FmuInstance]:
    """The plant at trim or the controller hovering, initialized."""
    with FmuInstance(plant_fmu() if model == "plant" else controller_fmu(), model) as inst:
        if model == "plant":
            _plant_at_trim(inst)
        else:
            _hovering_controller(inst)
        yield inst


@pytest.mark.parametrize(("model", "h", "limit"), [("plant", 600.0, " 1000000 "),
                                                   ("controller", 400.0, " 100000)")])
def test_one_dostep_has_a_bounded_cost(model, h, limit):
    """A doStep cannot be cancelled: one that would take minutes is refused at once."""
    import time

    with _ready(model) as inst:
        t0 = time.perf_counter()
        with pytest.raises(FMICallException):
            inst.step(h)
        assert time.perf_counter() - t0 < 1.0
        assert any(limit in m for m in logged(inst, "ERROR", "WARNING")), inst.messages


@pytest.mark.parametrize("model", ["plant", "controller"])
def test_a_nan_step_size_is_refused_with_a_message(model):
    with _ready(model) as inst:
        with pytest.raises(FMICallException):
            inst.step(float("nan"))
        assert logged(inst, "ERROR", "WARNING"), inst.messages
