"""Our WLS solver against DAQP (an independent dual active-set solver) on the very QPs the
controller solves in closed loop.

The guidance and inner-allocation QPs are recorded from the FullPoseController FMU's state
(controller.qp_record) while it flies the paper's first scenario with the plant FMU, and
handed to DAQP as 1/2 x'Hx + f'x with H = 2 A'A, f = -2 A'b, the bounds as DAQP's simple
bounds (fixed variables as equalities) and C x <= d as its general rows.  A has full column
rank in both QPs (the W_u rows of the guidance, the preference rows of the allocation), so
the optimum is unique and both solvers must find it.

Tolerances come from each problem's conditioning, not from today's output: with
kappa = cond(A) (2-norm), a backward-stable solve of a QP whose Hessian has condition
kappa^2 leaves a relative error of order kappa^2 eps in x and in the objective.  The
check allows SAFETY kappa^2 eps (eps the float64 unit roundoff) relative to
max(1, ||x||) for x and to max(f, eps ||b||^2) for the objective f = ||A x - b||^2;
constraint violations of either solution must stay within VIOL_RTOL of the data's scale.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller import controller_fmu
from controller.qp_record import ALLOCATION, GUIDANCE, RecordedQP, dense_form, qp_from_state
from orchestrator.sim.fmu import FmuInstance
from plant import plant_fmu

daqp = pytest.importorskip("daqp", reason="daqp is a test extra: pip install '.[test]'")

H = 0.002
EPS = float(np.finfo(float).eps)
SAFETY = 100.0  # constant of the kappa^2 eps bound
VIOL_RTOL = 1e-9  # constraint violation, relative to max(1, |d|, |bound|)
MEAS = ["pos", "vel", "acc", "euler", "rate", "omega", "alpha", "beta"]
CMDS = ["omega_cmd", "alpha_cmd", "beta_cmd"]
REFS = ["pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref"]


def scenario1(t: float) -> np.ndarray:
    e = [0.7 * math.sin(0.2 * t), -0.7 * math.sin(0.5 * t), -0.35 * math.sin(0.5 * t)]
    ed = [0.14 * math.cos(0.2 * t), -0.35 * math.cos(0.5 * t), -0.175 * math.cos(0.5 * t)]
    return np.concatenate([[0.0, 0.0, -3.0], e, np.zeros(6), ed])


@pytest.fixture(scope="module")
def recorded() -> dict[int, list[RecordedQP]]:
    """Every 10th sample's guidance and allocation QP over 10 s of scenario 1 (from ~6 s its
    attitude reference leaves the feasible set: active force-set rows and bounds)."""
    plant = FmuInstance(plant_fmu(), "plant")
    ctrl = FmuInstance(controller_fmu(), "controller")
    plant.initialize(parameters={"pos0[3]": -3.0})
    y_p, u_p = plant.signal(MEAS), plant.signal(CMDS)
    y_c, u_c, ref = ctrl.signal(MEAS), ctrl.signal(CMDS), ctrl.signal(REFS)
    ctrl.slave.setupExperiment(startTime=0.0)
    ctrl.slave.enterInitializationMode()
    ctrl.write(y_c, plant.read(y_p))
    ctrl.write(ref, scenario1(0.0))
    ctrl.slave.exitInitializationMode()
    out: dict[int, list[RecordedQP]] = {GUIDANCE: [], ALLOCATION: []}
    try:
        for k in range(round(10.0 / H)):
            ctrl.write(ref, scenario1(k * H))
            ctrl.write(y_c, plant.read(y_p))
            ctrl.step(H)
            plant.write(u_p, ctrl.read(u_c))
            plant.step(H)
            if k % 10 == 0:
                state = bytes(ctrl.slave.serializeFMUstate(ctrl.slave.getFMUstate()))
                for which in (GUIDANCE, ALLOCATION):
                    out[which].append(qp_from_state(state, which))
    finally:
        plant.close()
        ctrl.close()
    return out


def daqp_solve(qp: RecordedQP) -> np.ndarray:
    Hm, f, C, bu, bl, sense = dense_form(qp)
    x, _, flag, _ = daqp.solve(Hm, f, C, bu, bl, sense, primal_tol=1e-12, dual_tol=1e-12)
    assert flag == 1, f"DAQP exit flag {flag}"
    return np.asarray(x)


def violation(qp: RecordedQP, x: np.ndarray) -> float:
    lo = np.where(np.isfinite(qp.lb), qp.lb - x, 0.0) / np.maximum(1.0, np.abs(
        np.where(np.isfinite(qp.lb), qp.lb, 0.0)))
    hi = np.where(np.isfinite(qp.ub), x - qp.ub, 0.0) / np.maximum(1.0, np.abs(
        np.where(np.isfinite(qp.ub), qp.ub, 0.0)))
    rows = (qp.C @ x - qp.d) / np.maximum(1.0, np.abs(qp.d)) if qp.C.size else np.zeros(1)
    return float(max(0.0, lo.max(), hi.max(), rows.max()))


@pytest.mark.parametrize("which", [GUIDANCE, ALLOCATION], ids=["guidance", "allocation"])
def test_recorded_qps_match_daqp(recorded, which):
    qps = recorded[which]
    assert len(qps) >= 500
    active = 0
    for i, qp in enumerate(qps):
        x_daqp = daqp_solve(qp)
        s = np.linalg.svd(qp.A, compute_uv=False)
        assert s[-1] > 0.0, "A has full column rank in the controller's QPs"
        tol = SAFETY * (s[0] / s[-1]) ** 2 * EPS
        f_ours = float(np.sum((qp.A @ qp.x - qp.b) ** 2))
        f_daqp = float(np.sum((qp.A @ x_daqp - qp.b) ** 2))
        f_scale = max(f_daqp, EPS * float(qp.b @ qp.b))
        assert violation(qp, qp.x) <= VIOL_RTOL, f"QP {i}: ours infeasible"
        assert violation(qp, x_daqp) <= VIOL_RTOL, f"QP {i}: DAQP infeasible"
        assert abs(f_ours - f_daqp) <= tol * f_scale, (
            f"QP {i}: objective ours {f_ours:.17g}, DAQP {f_daqp:.17g}, tolerance {tol:.2e}")
        err = float(np.max(np.abs(qp.x - x_daqp)))
        assert err <= tol * max(1.0, float(np.max(np.abs(x_daqp)))), (
            f"QP {i}: |x_ours - x_daqp| = {err:.3e}, tolerance {tol:.2e}")
        at_bound = (np.abs(qp.x - qp.lb) < 1e-9) | (np.abs(qp.x - qp.ub) < 1e-9)
        rows = qp.C @ qp.x >= qp.d - 1e-9 if qp.C.size else np.zeros(1, bool)
        active += int(at_bound[qp.lb < qp.ub].any() or rows.any())
    # the recording must exercise constraints, not only interior optima
    assert active >= 50, f"only {active} recorded QPs had an active constraint"
