"""The INDI + PD baseline: the same controller FMU with P blocks (A = B = C = 0).

The cascade of P blocks on position and velocity (attitude and rate) is the classical INDI
"PD" controller: v_c = k_p (xi_ref - xi), a_c = k_v (v_c - v) = k_v k_p e - k_v v, i.e. a
proportional-derivative law on the position error with measured-velocity damping.

Tuning "to the same bandwidths as the H-infinity design": each P gain is chosen so that the
loop's crossover frequency on the same design model (controller/hinf.py) equals the H-infinity
design's crossover - the inner loop (velocity / rate, outer loop open) first, then the outer
loop (position / attitude, inner loop closed).  :func:`tune` does that by root finding;
:data:`GAINS` caches the result for the shipped design (tests/test_controller/test_hinf.py
checks it).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy import optimize

from controller import hinf
from controller.fmu_parameters import block_parameters

CACHE = Path(__file__).resolve().with_name("default_gains.json")


def _crossover(spec: hinf.LoopSpec, k1: hinf.Block, k2: hinf.Block, where: str) -> float:
    """Highest frequency with |L| = 1 (grid + brentq, as controller.lti.loop_margins)."""
    L = hinf.loops(spec, k1, k2)[where]
    w = np.logspace(-3, np.log10(0.9999 * np.pi / hinf.TS), 6000)
    m = np.abs(L.freqresp(w)[:, 0, 0]) - 1.0
    idx = np.nonzero(np.sign(m[:-1]) != np.sign(m[1:]))[0]
    i = idx[-1]
    return optimize.brentq(lambda x: float(np.abs(L.freqresp(np.array([x]))[0, 0, 0])) - 1.0,
                           w[i], w[i + 1], xtol=1e-12)


def tune(spec: hinf.LoopSpec, w_inner: float, w_outer: float) -> tuple[float, float]:
    """P gains (outer, inner) with these crossover frequencies (rad/s)."""
    kv = optimize.brentq(lambda k: _crossover(spec, hinf.Block.p(1.0), hinf.Block.p(k), "inner")
                         - w_inner, 0.2 * w_inner, 5 * w_inner, xtol=1e-6)
    kp = optimize.brentq(lambda k: _crossover(spec, hinf.Block.p(k), hinf.Block.p(kv), "outer")
                         - w_outer, 0.2 * w_outer, 5 * w_outer, xtol=1e-6)
    return kp, kv


def shipped_bandwidths() -> dict[str, float]:
    """Crossovers (rad/s) of the shipped H-infinity design, from the cached synthesis."""
    rep = json.loads(CACHE.read_text())["report"]
    return {"pos": rep["translation"]["margins"]["outer"]["crossover"],
            "vel": rep["translation"]["margins"]["inner"]["crossover"],
            "att": rep["rotation"]["margins"]["outer"]["crossover"],
            "rate": rep["rotation"]["margins"]["inner"]["crossover"]}


# The hand-tuned P blocks that flew the prototype (docs/architecture.md) and were the FMU
# defaults before the synthesis: a third reference for the campaign
# (``fullpose sweep --designs prototype``).
PROTOTYPE = {"pos": 2.2, "vel": 6.0, "att": 9.0, "rate": 20.0}


def compute_gains() -> dict[str, float]:
    """The baseline's P gains per loop (pos, vel, att, rate), tuned to the shipped design's
    crossover frequencies."""
    bw = shipped_bandwidths()
    kp, kv = tune(hinf.TRANSLATION, bw["vel"], bw["pos"])
    ka, kr = tune(hinf.ROTATION, bw["rate"], bw["att"])
    return {"pos": kp, "vel": kv, "att": ka, "rate": kr}


def controller_parameters(gains: dict[str, float] | None = None) -> dict[str, float]:
    """The baseline as controller FMU parameter overrides."""
    gains = compute_gains() if gains is None else gains
    return block_parameters({loop: hinf.Block.p(k).fmu() for loop, k in gains.items()})


if __name__ == "__main__":
    print(compute_gains())
