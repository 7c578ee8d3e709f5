"""Closed loop: the controller FMU flying the plant FMU under a minimal fmpy master.

The master below is deliberately plain (written here, independent of the
orchestrator): both FMUs through fmpy's low-level API, connected by matching
variable names, the controller sampling y_k and the plant integrating u_k.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller import controller_fmu
from controller.force_sets import feasible_force_set
from orchestrator.sim.fmu import FmuInstance
from plant import load_airframe, plant_fmu

H = 0.002
D2R = math.pi / 180
HOVER = np.array([0.0, 0.0, -3.0])


class Loop:
    def __init__(self, plant_params=None, ctrl_params=None, pos0=HOVER):
        self.plant = FmuInstance(plant_fmu(), "plant")
        self.ctrl = FmuInstance(controller_fmu(), "controller")
        params = {f"pos0[{i + 1}]": float(v) for i, v in enumerate(pos0)}
        params.update(plant_params or {})
        self.plant.initialize(parameters=params)
        p_out = {v.name for v in self.plant.md.modelVariables if v.causality == "output"}
        c_in = [v.name for v in self.ctrl.md.modelVariables if v.causality == "input"]
        c_out = {v.name for v in self.ctrl.md.modelVariables if v.causality == "output"}
        p_in = [v.name for v in self.plant.md.modelVariables if v.causality == "input"]
        measured = [n for n in c_in if n in p_out]
        commands = [n for n in p_in if n in c_out]
        self.y_plant = self.plant.signal(measured)
        self.y_ctrl = self.ctrl.signal(measured)
        self.u_ctrl = self.ctrl.signal(commands)
        self.u_plant = self.plant.signal(commands)
        self.ref = self.ctrl.signal(["pos_ref", "euler_ref", "vel_ref", "acc_ref",
                                     "euler_rate_ref"])
        self.diag = self.ctrl.signal(["mu_c", "f_b_ref", "f_b_c"])
        self.state = self.plant.signal(["pos", "euler", "alpha", "beta", "omega"])
        ctrl = self.ctrl
        ctrl.slave.setupExperiment(startTime=0.0)
        ctrl.set_many(ctrl_params or {})
        ctrl.slave.enterInitializationMode()
        ctrl.write(self.y_ctrl, self.plant.read(self.y_plant))
        ctrl.write(self.ref, np.concatenate([pos0, np.zeros(12)]))
        ctrl.slave.exitInitializationMode()
        self.t = 0.0

    def run(self, duration, reference):
        """reference(t) -> 15 values [pos, euler, vel, acc, euler_rate]."""
        n = round(duration / H)
        out = {k: np.empty((n, 3)) for k in ("pos", "euler", "mu_c", "mu_ref")}
        out["feasible"] = np.empty(n, dtype=bool)
        out["alpha"] = np.empty((n, 8))
        for k in range(n):
            r = np.asarray(reference(self.t), dtype=float)
            self.ctrl.write(self.ref, r)
            self.ctrl.write(self.y_ctrl, self.plant.read(self.y_plant))
            self.ctrl.step(H)
            self.plant.write(self.u_plant, self.ctrl.read(self.u_ctrl))
            self.plant.step(H)
            self.t += H
            s = self.plant.read(self.state)
            out["pos"][k], out["euler"][k], out["alpha"][k] = s[0:3], s[3:6], s[6:14]
            out["mu_c"][k] = self.ctrl.read(self.diag)[0:3]
            out["mu_ref"][k] = r[3:6]
            out["feasible"][k] = bool(self.ctrl.get("feasible"))
        return out

    def close(self):
        self.plant.close()
        self.ctrl.close()


@pytest.fixture
def loop_factory():
    made = []

    def make(**kw):
        lp = Loop(**kw)
        made.append(lp)
        return lp

    yield make
    for lp in made:
        lp.close()


def constant(pos=HOVER, euler=(0.0, 0.0, 0.0)):
    r = np.concatenate([pos, euler, np.zeros(9)])
    return lambda t: r


def smooth_attitude(target, duration):
    """Attitude ramp with a smoothstep profile and its analytic derivative."""
    target = np.asarray(target, dtype=float)

    def ref(t):
        s = min(max(t / duration, 0.0), 1.0)
        shape = 3 * s**2 - 2 * s**3
        dshape = (6 * s - 6 * s**2) / duration if 0 < s < 1 else 0.0
        return np.concatenate([HOVER, target * shape, np.zeros(6), target * dshape])

    return ref


def test_signal_names_match_between_fmus(loop_factory):
    lp = loop_factory()
    assert set(lp.y_ctrl.names) >= {"pos[1]", "vel[1]", "acc[1]", "euler[1]", "rate[1]",
                                     "omega[1]", "alpha[1]", "beta[1]"}
    assert len(lp.u_ctrl.names) == 24  # omega_cmd, alpha_cmd, beta_cmd for 8 slots


def test_hover_holds_within_1mm(loop_factory):
    out = loop_factory().run(5.0, constant())
    err = np.linalg.norm(out["pos"] - HOVER, axis=1)
    assert err.max() < 1e-3
    assert np.isfinite(out["pos"]).all()


@pytest.mark.parametrize("axis", [0, 2])
def test_position_step_settles_without_big_overshoot(loop_factory, axis):
    target = HOVER.copy()
    target[axis] += 1.0
    out = loop_factory().run(6.0, constant(pos=target))
    x = out["pos"][:, axis] - HOVER[axis]
    overshoot = x.max() - 1.0
    assert overshoot < 0.10  # a well-damped position loop: at most 10 % overshoot
    assert abs(x[-1] - 1.0) < 0.01  # settled
    others = [i for i in range(3) if i != axis]
    assert np.abs(out["pos"][:, others] - HOVER[others]).max() < 0.02


def test_hover_at_feasible_25_deg_roll(loop_factory):
    lp = loop_factory()
    out = lp.run(5.0, smooth_attitude([25 * D2R, 0, 0], 2.0))
    err = np.linalg.norm(out["pos"] - HOVER, axis=1)
    assert err.max() < 0.02
    assert out["euler"][-1, 0] == pytest.approx(25 * D2R, abs=0.1 * D2R)
    assert out["feasible"][-500:].all()
    # started at that roll (plant trimmed there), the position holds as well
    lp2 = loop_factory(plant_params={"euler0[1]": 25 * D2R})
    out2 = lp2.run(3.0, constant(euler=(25 * D2R, 0, 0)))
    assert np.linalg.norm(out2["pos"] - HOVER, axis=1).max() < 0.02


def test_infeasible_attitude_departs_from_reference_and_keeps_position(loop_factory):
    out = loop_factory().run(6.0, smooth_attitude([60 * D2R, 0, 0], 2.0))
    assert np.isfinite(out["pos"]).all() and np.isfinite(out["mu_c"]).all()
    late = slice(-1000, None)  # the last 2 s, reference held at 60 deg
    assert not out["feasible"][late].any()
    gap = np.abs(out["mu_c"][late, 0] - out["mu_ref"][late, 0])
    assert gap.min() > 5 * D2R  # mu_c departs from mu_ref
    assert np.linalg.norm(out["pos"] - HOVER, axis=1).max() < 0.05
    # the servos are at their 40 deg limit while the vehicle holds its best roll
    assert np.abs(out["alpha"][late, :6]).max() > 39 * D2R


def test_mu_c_equals_mu_ref_whenever_feasible(loop_factory):
    def scenario1(t):  # the paper's first scenario, 20 s of it
        e = [0.7 * math.sin(0.2 * t), -0.7 * math.sin(0.5 * t), -0.35 * math.sin(0.5 * t)]
        ed = [0.14 * math.cos(0.2 * t), -0.35 * math.cos(0.5 * t), -0.175 * math.cos(0.5 * t)]
        return np.concatenate([HOVER, e, np.zeros(6), ed])

    out = loop_factory().run(20.0, scenario1)
    feasible = out["feasible"]
    assert 0.2 < feasible.mean() < 1.0  # both regimes occur
    gap = np.abs(out["mu_c"][:, :2] - out["mu_ref"][:, :2]).max(axis=1)
    assert gap[feasible].max() < 0.1 * D2R
    assert gap[~feasible].max() > 1 * D2R
    assert np.linalg.norm(out["pos"] - HOVER, axis=1).max() < 0.02


def test_other_airframes_hover(loop_factory):
    for name in ("fixed_tilt_hexarotor", "quadrotor"):
        af = load_airframe(name)
        params = af.fmu_parameters()
        ctrl = {k: v for k, v in params.items() if not k.startswith("tau_")}
        poly = feasible_force_set(af)
        ctrl["poly_n"] = len(poly.b)
        for i in range(len(poly.b)):
            for j in range(3):
                ctrl[f"poly_A[{i + 1},{j + 1}]"] = float(poly.A[i, j])
            ctrl[f"poly_b[{i + 1}]"] = float(poly.b[i])
        out = loop_factory(plant_params=params, ctrl_params=ctrl).run(3.0, constant())
        assert np.linalg.norm(out["pos"] - HOVER, axis=1).max() < 1e-3, name
