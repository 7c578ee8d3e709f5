"""Benchmark: FullPoseController cost inside the FMU, old build against new, and its QPs
against DAQP and piqp.

Flies the paper's first scenario (hover with varying orientation, infeasible stretches
included) in closed loop with the plant FMU, the controller timing itself (parameter
``timing``: clock_gettime around the sample and around each QP solve).  With ``--old-fmu``
a second controller, built from an earlier commit (tests/bench/build_old_controller.sh),
is timed two ways: alone, each build flying the scenario by itself with the plant as in a
user's co-simulation, in ``--rounds`` rounds (default 6) whose order alternates (new-old,
old-new, ...) so that the machine's drift falls on both alike; and in turn, both in the
same loop on the very same inputs, called in alternating order at every sample (each sample
then runs right after the other build's, whose code and data have just passed through the
caches).
Prints, from one run:
  - the controller sample time inside the FMU, old and new side by side (mean, p50, p99,
    max, ratio new/old), alone (pooled over the rounds, per round and the rounds' median)
    and in turn, and
    whether the two builds gave the same commands; like for like, the samples where the
    new build's reference twin solved no QP (the old build has no twin) apart from those
    where it did;
  - guidance and inner-allocation QP solve times in the loop (warm) and iterations;
  - the very same QPs (read back from the new controller's FMU state) re-solved by our
    solver, cold (empty working set, x = 0) and warm (the optimal working set), by DAQP
    cold and warm (the optimal active set as its start), timed by DAQP's own C clock, and
    by piqp, with the ratios and the objective agreement.

Usage:
    bash tests/bench/build_old_controller.sh 06d7094 /tmp/old
    python tests/bench/bench_controller.py --old-fmu /tmp/old/FullPoseController.fmu
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import piqp

from controller import controller_fmu
from controller.qp_record import ALLOCATION, GUIDANCE, RecordedQP, dense_form, qp_from_state
from controller.wls import WlsSolver
from orchestrator.sim.fmu import FmuInstance
from plant import plant_fmu

try:
    import daqp  # type: ignore[import-not-found]
except ImportError:  # a test extra: pip install ".[test]"
    daqp = None

H = 0.002
MEAS = ["pos", "vel", "acc", "euler", "rate", "omega", "alpha", "beta"]
CMDS = ["omega_cmd", "alpha_cmd", "beta_cmd"]
REFS = ["pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref"]
REPEATS = 5  # solves per recorded QP, the median kept


def scenario1(t: float) -> np.ndarray:
    e = [0.7 * math.sin(0.2 * t), -0.7 * math.sin(0.5 * t), -0.35 * math.sin(0.5 * t)]
    ed = [0.14 * math.cos(0.2 * t), -0.35 * math.cos(0.5 * t), -0.175 * math.cos(0.5 * t)]
    return np.concatenate([[0.0, 0.0, -3.0], e, np.zeros(6), ed])


def summary(us: np.ndarray) -> dict[str, float]:
    return {"mean": float(us.mean()), "p50": float(np.percentile(us, 50)),
            "p99": float(np.percentile(us, 99)), "max": float(us.max())}


def stats(label: str, us: np.ndarray) -> dict[str, float]:
    row = summary(us)
    print(f"  {label:40s} mean {row['mean']:7.2f}  p50 {row['p50']:7.2f}  "
          f"p99 {row['p99']:7.2f}  max {row['max']:8.2f} us  (n={us.size})")
    return row


def ratio_line(label: str, num: dict[str, float], den: dict[str, float]) -> None:
    print(f"  {label:40s} " + "  ".join(f"{k} {num[k] / den[k]:5.2f}x"
                                         for k in ("mean", "p50", "p99", "max")))


class Controller:
    """One controller instance in the loop, timing itself."""

    def __init__(self, fmu: Path, name: str) -> None:
        self.fmu = FmuInstance(fmu, name)
        self.y = self.fmu.signal(MEAS)
        self.u = self.fmu.signal(CMDS)
        self.ref = self.fmu.signal(REFS)
        self.timing = self.fmu.signal(["t_step", "t_guid", "t_alloc"])

    def start(self, meas: np.ndarray, ref: np.ndarray) -> None:
        self.fmu.slave.setupExperiment(startTime=0.0)
        self.fmu.set("timing", True)
        self.fmu.slave.enterInitializationMode()
        self.fmu.write(self.y, meas)
        self.fmu.write(self.ref, ref)
        self.fmu.slave.exitInitializationMode()

    def sample(self, meas: np.ndarray, ref: np.ndarray) -> np.ndarray:
        self.fmu.write(self.ref, ref)
        self.fmu.write(self.y, meas)
        self.fmu.step(H)
        return self.fmu.read(self.timing) * 1e6


def fly(seconds: float, every: int | None, old_fmu: Path | None) -> dict:
    """One closed-loop flight.  ``every``: record every N-th sample's QPs (an FMU state
    snapshot after it, which costs the next sample a cold cache: never in the timed flight);
    None: none recorded."""
    plant = FmuInstance(plant_fmu(), "plant")
    plant.initialize(parameters={"pos0[3]": -3.0})
    y_p, u_p = plant.signal(MEAS), plant.signal(CMDS)
    new = Controller(controller_fmu(), "controller")
    old = Controller(old_fmu, "controller_old") if old_fmu is not None else None
    for c in (new, old):
        if c is not None:
            c.start(plant.read(y_p), scenario1(0.0))
    n = round(seconds / H)
    out: dict = {k: np.empty((n, 3)) for k in ("new", "old")}
    out["guid_iter"] = np.empty(n, dtype=int)
    out["alloc_iter"] = np.empty(n, dtype=int)
    out["cmd_diff"] = 0.0
    out["commands"] = np.empty((n, len(new.fmu.read(new.u))))
    out["guid_qps"], out["alloc_qps"] = [], []
    out["twin"] = np.zeros(n, dtype=bool)
    twin = new.fmu.signal(["mu_ff", "euler_ref_s"]) if every is not None else None
    for k in range(n):
        meas, ref = plant.read(y_p), scenario1(k * H)
        if old is None:
            out["new"][k] = new.sample(meas, ref)
        elif k % 2 == 0:  # alternate who goes first: caches and load fall on both alike
            out["new"][k] = new.sample(meas, ref)
            out["old"][k] = old.sample(meas, ref)
        else:
            out["old"][k] = old.sample(meas, ref)
            out["new"][k] = new.sample(meas, ref)
        cmd = new.fmu.read(new.u)
        out["commands"][k] = cmd
        if old is not None:
            out["cmd_diff"] = max(out["cmd_diff"],
                                  float(np.abs(old.fmu.read(old.u) - cmd).max()))
        plant.write(u_p, cmd)
        plant.step(H)
        out["guid_iter"][k] = new.fmu.get("guid_iter")
        out["alloc_iter"][k] = new.fmu.get("alloc_iter")
        if twin is not None:  # the twin's attitude departs from the reference: its QP ran
            v = new.fmu.read(twin)
            out["twin"][k] = bool(np.any(v[:3] != v[3:]))
        if every is not None and k % every == 0:
            state = bytes(new.fmu.slave.serializeFMUstate(new.fmu.slave.getFMUstate()))
            out["guid_qps"].append(qp_from_state(state, GUIDANCE))
            out["alloc_qps"].append(qp_from_state(state, ALLOCATION))
    for inst in (plant, new.fmu, old.fmu if old is not None else None):
        if inst is not None:
            inst.close()
    if old is None:
        del out["old"]
    return out


def fly_alone(fmu: Path, seconds: float) -> np.ndarray:
    """One closed-loop flight of one controller by itself with the plant (the master and
    the plant run between its samples, as in a user's co-simulation): its sample times, us."""
    plant = FmuInstance(plant_fmu(), "plant")
    plant.initialize(parameters={"pos0[3]": -3.0})
    y_p, u_p = plant.signal(MEAS), plant.signal(CMDS)
    ctrl = Controller(fmu, "controller")
    ctrl.start(plant.read(y_p), scenario1(0.0))
    us = np.empty(round(seconds / H))
    for k in range(us.size):
        us[k] = ctrl.sample(plant.read(y_p), scenario1(k * H))[0]
        plant.write(u_p, ctrl.fmu.read(ctrl.u))
        plant.step(H)
    plant.close()
    ctrl.fmu.close()
    return us


def alone(new_fmu: Path, old_fmu: Path, seconds: float, rounds: int,
          twin: np.ndarray) -> dict[str, float]:
    """Each build flown alone, ``rounds`` times in alternating order; prints the pooled
    figures, the per-round ratios, and like for like on ``twin`` (the samples where the new
    build's twin solved its QP: a function of the reference alone, the same samples in
    every flight); returns the pooled sample summaries' ratio new/old, and as ``round
    mean`` and ``round p99`` the median over the rounds of each round's ratio (a round
    that the host's interruptions hit weighs one vote, not its share of the pooled tail)."""
    runs: dict[str, list[np.ndarray]] = {"new": [], "old": []}
    for r in range(rounds):
        order = (("new", new_fmu), ("old", old_fmu))
        for who, fmu in order if r % 2 == 0 else order[::-1]:
            runs[who].append(fly_alone(fmu, seconds))
    new, old = np.concatenate(runs["new"]), np.concatenate(runs["old"])
    print(f"alone (each build flown by itself with the plant, {rounds} rounds of "
          f"{seconds:g} s, the order alternating), pooled:")
    o, nw = stats("OLD controller sample", old), stats("NEW controller sample", new)
    ratio_line("new / old, controller sample", nw, o)
    by_round = {who: [summary(x) for x in xs] for who, xs in runs.items()}
    per = [(a["mean"] / b["mean"], a["p99"] / b["p99"])
           for a, b in zip(by_round["new"], by_round["old"], strict=True)]
    med = {"mean": float(np.median([m for m, _ in per])),
           "p99": float(np.median([q for _, q in per]))}
    print("  new / old per round: mean " + " ".join(f"{m:.2f}" for m, _ in per)
          + ", p99 " + " ".join(f"{q:.2f}" for _, q in per)
          + f"; median over the rounds: mean {med['mean']:.2f}, p99 {med['p99']:.2f}")
    mask = np.tile(twin, rounds)
    if mask.any() and (~mask).any():
        same_o, same_n = summary(old[~mask]), summary(new[~mask])
        print(f"  like for like, the {100 * (~mask).mean():.0f} % of samples where the twin "
              f"solved no QP: new / old mean {same_n['mean'] / same_o['mean']:.2f}, "
              f"p99 {same_n['p99'] / same_o['p99']:.2f}")
        tw = summary(new[mask])
        print(f"  the twin's {100 * mask.mean():.0f} % (a second guidance QP the old build "
              f"does not solve): NEW mean {tw['mean']:.2f} p99 {tw['p99']:.2f} us; "
              f"new / old mean {tw['mean'] / summary(old[mask])['mean']:.2f}, "
              f"p99 {tw['p99'] / summary(old[mask])['p99']:.2f}")
    return {**{k: nw[k] / o[k] for k in nw}, **{f"round {k}": v for k, v in med.items()}}


# --------------------------------------------------------------------------- #
# the recorded QPs in other solvers


def active_set(qp: RecordedQP) -> tuple[np.ndarray, np.ndarray]:
    """The working set at the recorded optimum: bounds (-1 lower, +1 upper, 0 free) and rows
    of C held at equality."""
    tol = 1e-9
    lb = np.where(np.isfinite(qp.lb), qp.lb, -np.inf)
    ub = np.where(np.isfinite(qp.ub), qp.ub, np.inf)
    with np.errstate(invalid="ignore"):  # inf - inf at the infinite bounds: not active
        at_lb = qp.x <= lb + tol * (1 + np.abs(lb))
        at_ub = qp.x >= ub - tol * (1 + np.abs(ub))
    bounds = np.where(at_lb & (qp.lb < qp.ub), -1, np.where(at_ub & (qp.lb < qp.ub), 1, 0))
    rows = (qp.C @ qp.x >= qp.d - tol * (1 + np.abs(qp.d))) if qp.C.size else np.zeros(0, bool)
    return bounds.astype(np.int8), rows.astype(np.int8)


def ours_time(qp: RecordedQP, warm: bool) -> tuple[float, int]:
    """Our solve time (C clock, median of REPEATS) and iterations."""
    nv, nr, nc = qp.A.shape[1], qp.A.shape[0], qp.C.shape[0]
    solver = WlsSolver(nv, nr, nc)
    solver.set_data(qp.A, qp.b, qp.lb, qp.ub, qp.C if nc else None, qp.d if nc else None)
    if warm:
        bounds, rows = active_set(qp)
        solver.set_x(qp.x)
        solver.working_set = np.concatenate([bounds, rows])
    ns, res = solver.bench(100, REPEATS)
    return float(np.median(ns)) / 1e3, res.iterations


def daqp_problem(qp: RecordedQP) -> tuple:
    """DAQP's form of the QP (:func:`controller.qp_record.dense_form`)."""
    return dense_form(qp)


def daqp_time(qp: RecordedQP, warm: bool) -> tuple[float, float, int, float]:
    """DAQP's solve and setup times (its own C clock, median of REPEATS), iterations, and
    the relative objective difference ours minus DAQP (0 if DAQP failed)."""
    Hm, f, C, bu, bl, sense = daqp_problem(qp)
    if warm:
        bounds, rows = active_set(qp)
        nv = qp.A.shape[1]
        free = sense[:nv] != 5
        sense[:nv][free & (bounds == 1)] = 1  # ACTIVE (upper)
        sense[:nv][free & (bounds == -1)] = 3  # ACTIVE | LOWER
        sense[nv:][rows == 1] = 1
    runs = []
    for _ in range(REPEATS):
        x, _, flag, info = daqp.solve(Hm, f, C, bu, bl, sense.copy())
        runs.append((info["solve_time"], info["setup_time"], info["iterations"]))
    diff = 0.0
    if flag == 1:
        ours = np.sum((qp.A @ qp.x - qp.b) ** 2)
        theirs = np.sum((qp.A @ x - qp.b) ** 2)
        diff = float((ours - theirs) / max(1.0, abs(theirs)))
    return (float(np.median([r[0] for r in runs])) * 1e6,
            float(np.median([r[1] for r in runs])) * 1e6, int(runs[-1][2]), diff)


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


def compare_qps(label: str, qps: list[RecordedQP], in_loop: dict[str, float]) -> None:
    nv, nr, nc = qps[0].A.shape[1], qps[0].A.shape[0], qps[0].C.shape[0]
    print(f"{label} QP ({nv} variables, {nr} rows, {nc} constraint rows; {len(qps)} recorded):")
    # one QP at a time through every solver, so that load changes fall on all of them
    t = {k: np.empty(len(qps)) for k in ("oc", "ow", "dcs", "dcu", "dws", "dwu")}
    it = {k: np.empty(len(qps), dtype=int) for k in ("oc", "ow", "dc", "dw")}
    worst = {"dc": 0.0, "dw": 0.0}
    for i, qp in enumerate(qps):
        t["oc"][i], it["oc"][i] = ours_time(qp, warm=False)
        t["ow"][i], it["ow"][i] = ours_time(qp, warm=True)
        if daqp is not None:
            t["dcs"][i], t["dcu"][i], it["dc"][i], d = daqp_time(qp, warm=False)
            worst["dc"] = max(worst["dc"], d)
            t["dws"][i], t["dwu"][i], it["dw"][i], d = daqp_time(qp, warm=True)
            worst["dw"] = max(worst["dw"], d)
    oc = stats("ours cold (C clock)", t["oc"])
    ow = stats("ours warm (C clock)", t["ow"])
    if daqp is None:
        print("  DAQP: not installed (pip install daqp, a test extra): comparison skipped")
    else:
        dc = stats("DAQP cold, solve (its C clock)", t["dcs"])
        dcu = stats("DAQP cold, setup + solve", t["dcs"] + t["dcu"])
        dw = stats("DAQP warm, solve (its C clock)", t["dws"])
        dwu = stats("DAQP warm, setup + solve", t["dws"] + t["dwu"])
        ratio_line("ours cold / DAQP cold solve", oc, dc)
        ratio_line("ours cold / DAQP cold setup + solve", oc, dcu)
        ratio_line("ours warm / DAQP warm solve", ow, dw)
        ratio_line("ours warm / DAQP warm setup + solve", ow, dwu)
        print(f"  iterations: ours cold {it['oc'].mean():.2f} warm {it['ow'].mean():.2f}, "
              f"DAQP cold {it['dc'].mean():.2f} warm {it['dw'].mean():.2f}")
        print("  (like for like: DAQP's setup + solve.  Its setup factors H and transforms the "
              "constraints,\n   which change every sample with B'' and the measured force; "
              "its solve alone reuses\n   them.  H = 2 A'A itself is formed in numpy, outside "
              "DAQP's clock; ours starts from A.)")
        print(f"  objective, ours minus DAQP, worst relative: cold {worst['dc']:.1e}, "
              f"warm {worst['dw']:.1e}")
    pq, wp = piqp_times(qps)
    pr = stats("piqp (solve, Python clock)", pq)
    ratio_line("ours cold / piqp", oc, pr)
    print(f"  objective, ours minus piqp, worst relative: {wp:.1e}; in the loop (warm) ours "
          f"mean {in_loop['mean']:.2f} us, p99 {in_loop['p99']:.2f} us")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--every", type=int, default=10, help="record every N-th QP")
    parser.add_argument("--rounds", type=int, default=6,
                        help="flights of each build alone, the order alternating (default 6)")
    parser.add_argument("--old-fmu", type=Path, default=None,
                        help="FullPoseController.fmu of an earlier commit "
                             "(tests/bench/build_old_controller.sh COMMIT OUTDIR)")
    args = parser.parse_args()
    if args.old_fmu is not None and not args.old_fmu.is_file():
        parser.error(f"--old-fmu {args.old_fmu}: no such file")
    # two flights of the same deterministic loop: one timed, with no snapshot in it, and
    # one that records the QPs (a snapshot leaves the next sample's caches cold)
    rec = fly(args.seconds, None, args.old_fmu)
    recorded = fly(args.seconds, args.every, None)
    same = np.array_equal(rec["commands"], recorded["commands"])
    n = rec["new"].shape[0]
    print(f"FullPoseController, paper hexacopter, scenario 1 for {args.seconds:g} s "
          f"({n} samples of 2 ms)")
    print("inside the FMU (clock_gettime around the work), microseconds:")
    new = {what: rec["new"][:, i] for i, what in enumerate(("step", "guid", "alloc"))}
    if "old" in rec:
        by_alone = alone(controller_fmu(), args.old_fmu, args.seconds, args.rounds,
                         recorded["twin"])
        print("in turn (both in one loop on the same inputs, alternating who goes first):")
        old = {what: rec["old"][:, i] for i, what in enumerate(("step", "guid", "alloc"))}
        for what, label in (("step", "controller sample"), ("guid", "guidance QP (warm)"),
                            ("alloc", "inner allocation QP (warm)")):
            o = stats(f"OLD {label}", old[what])
            nw = stats(f"NEW {label}", new[what])
            ratio_line(f"new / old, {label}", nw, o)
        print(f"  old and new commands, largest difference over the run: {rec['cmd_diff']:.3g}")
        step_new, step_old = summary(new["step"]), summary(old["step"])
        print(f"target: new/old <= 0.5 at mean and p99: alone, median over the rounds "
              f"mean {by_alone['round mean']:.2f}, p99 {by_alone['round p99']:.2f}, pooled "
              f"mean {by_alone['mean']:.2f}, p99 {by_alone['p99']:.2f}; in turn mean "
              f"{step_new['mean'] / step_old['mean']:.2f}, p99 "
              f"{step_new['p99'] / step_old['p99']:.2f}")
    else:
        print("  (no --old-fmu: the old-against-new comparison is skipped; build one with "
              "tests/bench/build_old_controller.sh COMMIT OUTDIR)")
        stats("controller sample", new["step"])
        stats("guidance QP (warm)", new["guid"])
        stats("inner allocation QP (warm)", new["alloc"])
    gi, ai = rec["guid_iter"], rec["alloc_iter"]
    print(f"iterations in the loop: guidance mean {gi.mean():.2f} max {gi.max()}; "
          f"allocation mean {ai.mean():.2f} max {ai.max()}")
    print(f"QPs recorded in a second flight (every {args.every}th sample), its commands "
          f"{'bit-identical to' if same else 'DIFFERENT from'} the timed flight's")
    compare_qps("guidance", recorded["guid_qps"], summary(new["guid"]))
    compare_qps("inner allocation", recorded["alloc_qps"], summary(new["alloc"]))


if __name__ == "__main__":
    main()
