"""Benchmark: FullPoseController cost inside the FMU, and its QPs against piqp.

Flies the paper's first scenario (hover with varying orientation, infeasible
stretches included) in closed loop with the plant FMU, the controller timing
itself (parameter ``timing``).  Prints, side by side from the same run:
  - controller sample time inside the FMU (mean, p99, max) and the doStep call
    as seen from Python;
  - guidance and inner-allocation QP solve times and iteration counts;
  - piqp solving the very same QPs (read back from the controller's FMU state),
    and our solver re-solving them cold, with the ratios.

Usage: python tests/bench/bench_controller.py [--seconds 20] [--every 10]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
import piqp

from controller import controller_fmu
from controller.qp_record import ALLOCATION, GUIDANCE, RecordedQP, qp_from_state
from controller.wls import WlsSolver
from orchestrator.fmu import FmuInstance
from plant import plant_fmu

H = 0.002
MEAS = ["pos", "vel", "acc", "euler", "rate", "omega", "alpha", "beta"]
CMDS = ["omega_cmd", "alpha_cmd", "beta_cmd"]


def scenario1(t: float) -> np.ndarray:
    e = [0.7 * math.sin(0.2 * t), -0.7 * math.sin(0.5 * t), -0.35 * math.sin(0.5 * t)]
    ed = [0.14 * math.cos(0.2 * t), -0.35 * math.cos(0.5 * t), -0.175 * math.cos(0.5 * t)]
    return np.concatenate([[0.0, 0.0, -3.0], e, np.zeros(6), ed])


def stats(label: str, us: np.ndarray) -> dict[str, float]:
    row = {"mean": float(us.mean()), "p99": float(np.percentile(us, 99)), "max": float(us.max())}
    print(f"  {label:34s} mean {row['mean']:8.2f} us  p99 {row['p99']:8.2f} us  "
          f"max {row['max']:9.2f} us  (n={us.size})")
    return row


def fly(seconds: float, every: int) -> tuple[dict[str, np.ndarray], list[RecordedQP],
                                              list[RecordedQP]]:
    plant = FmuInstance(plant_fmu(), "plant")
    ctrl = FmuInstance(controller_fmu(), "controller")
    plant.initialize(parameters={"pos0[3]": -3.0})
    y_p, y_c = plant.signal(MEAS), ctrl.signal(MEAS)
    u_c, u_p = ctrl.signal(CMDS), plant.signal(CMDS)
    ref = ctrl.signal(["pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref"])
    timing = ctrl.signal(["t_step", "t_guid", "t_alloc"])
    ctrl.slave.setupExperiment(startTime=0.0)
    ctrl.set("timing", True)
    ctrl.slave.enterInitializationMode()
    ctrl.write(y_c, plant.read(y_p))
    ctrl.write(ref, scenario1(0.0))
    ctrl.slave.exitInitializationMode()
    n = round(seconds / H)
    rec = {k: np.empty(n) for k in ("step", "guid", "alloc", "call")}
    iters = {k: np.empty(n, dtype=int) for k in ("guid", "alloc")}
    guid_qps: list[RecordedQP] = []
    alloc_qps: list[RecordedQP] = []
    clock = time.perf_counter_ns
    for k in range(n):
        ctrl.write(ref, scenario1(k * H))
        ctrl.write(y_c, plant.read(y_p))
        t0 = clock()
        ctrl.step(H)
        rec["call"][k] = (clock() - t0) / 1e3
        plant.write(u_p, ctrl.read(u_c))
        plant.step(H)
        rec["step"][k], rec["guid"][k], rec["alloc"][k] = ctrl.read(timing) * 1e6
        iters["guid"][k] = ctrl.get("guid_iter")
        iters["alloc"][k] = ctrl.get("alloc_iter")
        if k % every == 0:
            state = bytes(ctrl.slave.serializeFMUstate(ctrl.slave.getFMUstate()))
            guid_qps.append(qp_from_state(state, GUIDANCE))
            alloc_qps.append(qp_from_state(state, ALLOCATION))
    plant.close()
    ctrl.close()
    rec["guid_iter"] = iters["guid"]
    rec["alloc_iter"] = iters["alloc"]
    return rec, guid_qps, alloc_qps


def piqp_times(qps: list[RecordedQP]) -> tuple[np.ndarray, float]:
    """piqp solve time per QP (setup excluded) and the worst objective mismatch."""
    out = np.empty(len(qps))
    worst = 0.0
    for i, qp in enumerate(qps):
        n = qp.A.shape[1]
        solver = piqp.DenseSolver()
        solver.settings.eps_abs = 1e-9
        solver.settings.eps_rel = 1e-9
        eq = qp.lb == qp.ub
        lb = np.where(eq, -np.inf, qp.lb)
        ub = np.where(eq, np.inf, qp.ub)
        solver.setup(P=np.asfortranarray(2 * qp.A.T @ qp.A), c=-2 * qp.A.T @ qp.b,
                     A=np.asfortranarray(np.eye(n)[eq]) if eq.any() else None,
                     b=qp.lb[eq] if eq.any() else None,
                     G=np.asfortranarray(qp.C) if qp.C.size else None,
                     h_u=qp.d if qp.C.size else None, x_l=lb, x_u=ub)
        t0 = time.perf_counter_ns()
        solver.solve()
        out[i] = (time.perf_counter_ns() - t0) / 1e3
        ours = np.sum((qp.A @ qp.x - qp.b) ** 2)
        theirs = np.sum((qp.A @ solver.result.x - qp.b) ** 2)
        worst = max(worst, (ours - theirs) / max(1.0, abs(theirs)))
    return out, worst


def cold_times(qps: list[RecordedQP]) -> np.ndarray:
    out = np.empty(len(qps))
    for i, qp in enumerate(qps):
        nv, nr, nc = qp.A.shape[1], qp.A.shape[0], qp.C.shape[0]
        solver = WlsSolver(nv, nr, nc)
        solver.set_data(qp.A, qp.b, qp.lb, qp.ub, qp.C if nc else None, qp.d if nc else None)
        ns, _ = solver.bench(100, 5)
        out[i] = float(np.median(ns)) / 1e3
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--every", type=int, default=10, help="record every N-th QP")
    args = parser.parse_args()
    rec, gq, aq = fly(args.seconds, args.every)
    print(f"FullPoseController, paper hexacopter, scenario 1 for {args.seconds:g} s "
          f"({rec['step'].size} samples of 2 ms)")
    print("inside the FMU (clock_gettime around the work):")
    step = stats("controller sample", rec["step"])
    guid = stats("guidance QP solve (warm)", rec["guid"])
    alloc = stats("inner allocation QP solve (warm)", rec["alloc"])
    print("from Python:")
    stats("fmi2DoStep call (fmpy low-level)", rec["call"])
    gi, ai = rec["guid_iter"], rec["alloc_iter"]
    print(f"iterations: guidance mean {gi.mean():.2f} max {gi.max()}; "
          f"allocation mean {ai.mean():.2f} max {ai.max()}")
    print(f"the same recorded QPs ({len(gq)} of each), re-solved now:")
    pg, wg = piqp_times(gq)
    pa, wa = piqp_times(aq)
    cg = cold_times(gq)
    ca = cold_times(aq)
    pgs = stats("piqp, guidance QP", pg)
    pas = stats("piqp, allocation QP", pa)
    stats("ours cold, guidance QP", cg)
    stats("ours cold, allocation QP", ca)
    print(f"ratio piqp/ours (mean, ours warm in the loop): "
          f"guidance {pgs['mean'] / guid['mean']:.1f}x, "
          f"allocation {pas['mean'] / alloc['mean']:.1f}x")
    print(f"objective: ours minus piqp, worst relative: guidance {wg:.1e}, allocation {wa:.1e}")
    print(f"targets: controller p99 {step['p99']:.1f} us (<= 20), "
          f"guidance QP p99 {guid['p99']:.1f} us (<= 5)")


if __name__ == "__main__":
    main()
