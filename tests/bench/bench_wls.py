"""Benchmark of the C allocation solver against piqp (prints figures, asserts nothing).

Two recorded-like sequences of 500 Hz problems (smoothly varying data, as the
controller sees them), each solved in order:
- guidance: the paper's eq. 17-23 QP, 5 variables [dfx, dfy, dfz, dphi, dtheta],
  rows 3 + 5 with gamma_opt * W_v^2 up to 1e7, a 24-facet lateral-force polygon,
  f_bz and Euler bounds; acceleration demands saturate the polygon in bursts;
- allocation: 24 actuator increments, 6 wrench rows + 24 preference rows, bounds.

Ours is timed inside C (clock_gettime around fp_wls_solve, fp_wls_bench_api),
each problem solved `--repeats` times from the same start: warm (the previous
problem's solution and working set) and cold (x = 0, empty working set).
piqp (defaults: eps_abs 1e-8, eps_rel 1e-9) is timed with its own
run_time: setup + solve of a fresh DenseSolver, and update + solve of one
solver kept across the sequence.

    python tests/bench/bench_wls.py [--steps 2000]            (installed package)
    PYTHONPATH=. FULLPOSE_BUILD_DIR=<cmake build dir> python tests/bench/bench_wls.py
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from controller import wls

try:
    import piqp
except ImportError:  # pragma: no cover - piqp is a test dependency
    piqp = None


def _rot(phi: float, theta: float, psi: float) -> np.ndarray:
    cf, sf, ct, st, cp, sp = (
        math.cos(phi),
        math.sin(phi),
        math.cos(theta),
        math.sin(theta),
        math.cos(psi),
        math.sin(psi),
    )
    rz = np.array([[cp, -sp, 0], [sp, cp, 0], [0, 0, 1]])
    ry = np.array([[ct, 0, st], [0, 1, 0], [-st, 0, ct]])
    rx = np.array([[1, 0, 0], [0, cf, -sf], [0, sf, cf]])
    return rz @ ry @ rx


def guidance_sequence(steps: int, seed: int = 7) -> list[dict]:
    rng = np.random.default_rng(seed)
    mass, g, gamma_opt = 3.0, 9.81, 1000.0
    wv = np.array([100.0, 100.0, 10.0])
    wu = np.array([1.0, 1.0, 1.0, 10.0, 10.0])
    k = 24
    ang = 2 * np.pi * np.arange(k) / k
    nrm = np.column_stack([np.cos(ang), np.sin(ang)])
    off = 12.0 * (1.0 + 0.2 * np.cos(3 * ang))
    mu_max = np.deg2rad(60.0)
    probs = []
    for i in range(steps):
        t = 0.002 * i
        eul = np.array([0.3 * math.sin(1.1 * t), 0.25 * math.sin(0.7 * t + 1.0), 0.2 * t])
        f_m = np.array(
            [3 * math.sin(0.9 * t), 2 * math.cos(1.3 * t), -mass * g + 4 * math.sin(0.5 * t)]
        ) + 0.2 * rng.standard_normal(3)
        burst = 6.0 if math.sin(0.8 * t) > 0.6 else 1.0
        acc = burst * np.array([4 * math.sin(2 * t), 4 * math.cos(1.5 * t), 2 * math.sin(t)])
        acc += 0.3 * rng.standard_normal(3)
        r = _rot(*eul)
        h = 1e-6
        cols = [r[:, 0], r[:, 1], r[:, 2]]
        for a in range(2):
            ep, em = eul.copy(), eul.copy()
            ep[a] += h
            em[a] -= h
            cols.append((_rot(*ep) @ f_m - _rot(*em) @ f_m) / (2 * h))
        G = np.column_stack(cols)
        du_p = np.array([0.0, 0.0, 0.0, 0.1 * math.sin(0.3 * t) - eul[0], -eul[1]])
        A = np.vstack([math.sqrt(gamma_opt) * wv[:, None] * G, np.diag(wu)])
        b = np.concatenate([math.sqrt(gamma_opt) * wv * mass * acc, wu * du_p])
        lb = np.array(
            [-np.inf, -np.inf, -4.6 * mass * g - f_m[2], -mu_max - eul[0], -mu_max - eul[1]]
        )
        ub = np.array([np.inf, np.inf, -0.2 * mass * g - f_m[2], mu_max - eul[0], mu_max - eul[1]])
        C = np.zeros((k, 5))
        C[:, :2] = nrm
        d = off - nrm @ f_m[:2]
        probs.append({"A": A, "b": b, "lb": lb, "ub": ub, "C": C, "d": d})
    return probs


def allocation_sequence(steps: int, seed: int = 11) -> list[dict]:
    rng = np.random.default_rng(seed)
    n_act = 24
    scale = np.tile([0.05, 2.0, 2.0, 1.0], 6)
    B0 = rng.standard_normal((6, n_act)) * scale
    B1 = rng.standard_normal((6, n_act)) * scale
    w_rows = np.array([1.0, 1.0, 1.0, 100.0, 100.0, 100.0])
    s_pref = math.sqrt(0.1) * np.tile([1.0 / 50.0, 1.0, 1.0, 1.0], 6)
    u_min = np.tile([10.0, -1.2, -1.2, -1.2], 6)
    u_max = np.tile([209.0, 1.2, 1.2, 1.2], 6)
    u_pref = np.tile([98.0, 0.0, 0.0, 0.0], 6)
    probs = []
    for i in range(steps):
        t = 0.002 * i
        B = B0 + 0.2 * math.sin(0.5 * t) * B1
        B[3:, :] *= 0.3
        u_m = u_pref + np.tile([40 * math.sin(t), 0.5 * math.sin(0.7 * t), 0.4, 0.0], 6)
        u_m = np.clip(u_m, u_min, u_max)
        burst = 30.0 if math.sin(0.6 * t) > 0.7 else 3.0
        dnu = burst * np.array([math.sin(2 * t), math.cos(1.7 * t), 0.5, 0.1, -0.1, 0.2])
        dnu += 0.2 * rng.standard_normal(6)
        A = np.vstack([w_rows[:, None] * B, np.diag(s_pref)])
        b = np.concatenate([w_rows * dnu, s_pref * (u_pref - u_m)])
        probs.append({"A": A, "b": b, "lb": u_min - u_m, "ub": u_max - u_m, "C": None, "d": None})
    return probs


def bench_ours(probs: list[dict], repeats: int, warm: bool, max_iter: int) -> dict:
    """Times (us, one row of `repeats` per problem), iterations and objectives."""
    p0 = probs[0]
    n, m = p0["A"].shape[1], p0["A"].shape[0]
    solver = wls.WlsSolver(n, m, 0 if p0["C"] is None else p0["C"].shape[0])
    times, iters, objs, statuses = [], [], [], []
    for pr in probs:
        solver.set_data(pr["A"], pr["b"], pr["lb"], pr["ub"], pr["C"], pr["d"])
        if not warm:
            solver.reset()
            solver.set_x(np.zeros(n))
        ns, res = solver.bench(max_iter, repeats)
        times.append(ns * 1e-3)
        iters.append(res.iterations)
        objs.append(res.objective)
        statuses.append(res.status)
    return {
        "t": np.array(times),
        "iters": np.array(iters),
        "obj": np.array(objs),
        "bad": sum(s != "optimal" for s in statuses),
    }


def _piqp_data(pr: dict) -> tuple:
    A, b = pr["A"], pr["b"]
    P = np.asfortranarray(2.0 * A.T @ A)
    c = -2.0 * A.T @ b
    G = None if pr["C"] is None else np.asfortranarray(pr["C"])
    return P, c, G, pr["d"], pr["lb"], pr["ub"]


def _piqp_setup(solver: object, data: tuple) -> None:
    P, c, G, h, lb, ub = data
    try:
        solver.setup(P, c, None, None, G, None, h, lb, ub)
    except TypeError:  # piqp < 0.6
        solver.setup(P, c, None, None, G, h, lb, ub)


def bench_piqp(probs: list[dict], repeats: int) -> dict:
    """piqp run_time (us): fresh setup + solve, and update + solve on one solver."""
    fresh, upd, objs = [], [], []
    kept = None
    for pr in probs:
        data = _piqp_data(pr)
        row = []
        for _ in range(repeats):
            s = piqp.DenseSolver()
            s.settings.compute_timings = True
            _piqp_setup(s, data)
            s.solve()
            row.append(s.result.info.run_time * 1e6)
        fresh.append(row)
        objs.append(float(np.sum((pr["A"] @ s.result.x - pr["b"]) ** 2)))
        P, c, G, h, lb, ub = data
        if kept is None:
            kept = piqp.DenseSolver()
            kept.settings.compute_timings = True
            _piqp_setup(kept, data)
            kept.solve()
            upd.append(kept.result.info.run_time * 1e6)
        else:
            kw = {"P": P, "c": c, "x_l": lb, "x_u": ub}
            if G is not None:
                kw.update({"G": G, "h_u": h})
            kept.update(**kw)
            kept.solve()
            upd.append(kept.result.info.run_time * 1e6)
    return {"fresh": np.array(fresh), "update": np.array(upd), "obj": np.array(objs)}


def _row(label: str, t: np.ndarray) -> str:
    flat = t.reshape(-1)
    med = np.median(t, axis=1) if t.ndim == 2 else flat
    return (
        f"  {label:30s} mean {flat.mean():7.2f}  p99 {np.percentile(flat, 99):7.2f}  "
        f"max {flat.max():8.2f}   (per-problem median: mean {med.mean():6.2f}, "
        f"p99 {np.percentile(med, 99):6.2f})"
    )


def report(name: str, probs: list[dict], repeats: int, max_iter: int) -> None:
    n, m = probs[0]["A"].shape[1], probs[0]["A"].shape[0]
    p = 0 if probs[0]["C"] is None else probs[0]["C"].shape[0]
    print(f"\n{name}: {len(probs)} problems, {n} variables, {m} rows, {p} constraints + bounds")
    warm = bench_ours(probs, repeats, True, max_iter)
    cold = bench_ours(probs, repeats, False, max_iter)
    for label, r in (("warm", warm), ("cold", cold)):
        it = r["iters"]
        print(
            f"  ours {label}: iterations mean {it.mean():.2f} p99 {np.percentile(it, 99):.0f} "
            f"max {it.max()}; early exits (1 iteration) {np.mean(it == 1) * 100:.0f}%; "
            f"not optimal {r['bad']}"
        )
    print("  solve time [us] (max: worst single solve, includes OS noise):")
    if piqp is not None:
        pq = bench_piqp(probs, max(1, repeats // 4))
        rel = (warm["obj"] - pq["obj"]) / np.maximum(np.abs(pq["obj"]), 1e-12)
        print(
            "  objective (ours warm - piqp defaults) / piqp: "
            f"max {rel.max():.1e} (> 0: ours worse), min {rel.min():.1e} (< 0: ours better)"
        )
        print(_row("ours, warm start (in C)", warm["t"]))
        print(_row("ours, cold start (in C)", cold["t"]))
        print(_row("piqp setup+solve (run_time)", pq["fresh"]))
        print(_row("piqp update+solve (run_time)", pq["update"]))
        wm, cm = warm["t"].mean(), cold["t"].mean()
        print(
            f"  ratio piqp/ours (means): setup+solve / warm {pq['fresh'].mean() / wm:.1f}x, "
            f"update+solve / warm {pq['update'].mean() / wm:.1f}x, "
            f"update+solve / cold {pq['update'].mean() / cm:.1f}x"
        )
    else:
        print(_row("ours, warm start (in C)", warm["t"]))
        print(_row("ours, cold start (in C)", cold["t"]))
        print("  (piqp not installed: no comparison)")


def main() -> None:
    ap = argparse.ArgumentParser(description="Benchmark of the C WLS solver against piqp.")
    ap.add_argument("--steps", type=int, default=2000, help="problems per sequence (500 Hz)")
    ap.add_argument("--repeats", type=int, default=20, help="timed solves per problem")
    ap.add_argument("--max-iter", type=int, default=100)
    args = ap.parse_args()
    t0 = time.perf_counter()
    report("guidance QP (eq. 17-23)", guidance_sequence(args.steps), args.repeats, args.max_iter)
    report(
        "inner allocation (eq. 13)", allocation_sequence(args.steps), args.repeats, args.max_iter
    )
    print(f"\n(total {time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
