"""Structured H-infinity synthesis of the controller FMU's first-order blocks.

Design model (one axis; translation and rotation have the same structure after INDI)
-----------------------------------------------------------------------------------
INDI (paper eq. 14-15 and its reference [12]) commands the *increment*
``u_eff = k (u - H[a_m]) + H[a_act]``, where ``u`` is the commanded acceleration (the inner
block's output), ``a_m = a_act + d`` the measured acceleration (d: external acceleration
disturbance), ``a_act`` the acceleration the actuators produce (known from the measured
actuator states), ``H`` the measurement filter and ``k = m_nom / m`` (``I_nom / I`` for the
rotation) the model mismatch.  The actuator is ``a_act = A(s) u_eff``,
``A(s) = 1/(tau s + 1)``.  With ``k = 1`` this gives exactly ``u_eff = u - H[d]``: the
achieved acceleration is ``A(s) u`` whatever the filter (the filtered actuator feedback cancels
the filtered acceleration), and the disturbance reaches the vehicle through
``1 - A(s) H(s)`` (zero at DC).  This is the standard INDI design model; the simpler
"A(s)-only" model is its k = 1, d = 0 case.  We keep k and the filter in the model because the
multi-model synthesis uses k != 1 (then the filter does not cancel:
``a_act = k A / (1 + (k - 1) A H) (u - H d)``).

Discretization at Ts = 2 ms, exactly as the FMU runs:

* the continuous chain (actuator, velocity, position) with inputs [u_eff, d] is discretized
  by zero-order hold (the FMU holds its commands over a step; the scenario's disturbance steps
  change at sample instants);
* one extra sample of computational delay z^-1 on u_eff.  The default Gauss-Seidel coupling has
  none (controller samples y_k, plant integrates with u_k), the Jacobi option and real hardware
  have one: the design is made for the worse case and the margins are reported for it;
* H(s) (the FMU's filt_wn = 80 rad/s, filt_zeta = 0.55) discretized as controller.c does
  (exact ZOH of the 2-state filter, output taken after the update, i.e. with a direct
  feed-through), on the outer and inner measurements, on d (the INDI's measured acceleration)
  and on a_act (actuator feedback).

Loops: outer block K1 (position -> velocity command, or attitude -> rate command),
inner block K2 (velocity -> acceleration, or rate -> angular acceleration).  Each block is
``K(z) = D + C B / (z - A)`` (the FMU's x+ = A x + B e, y = C x + D e); we use B = 1.

Requirements (each a SISO closed-loop channel; gamma = the largest weighted H-infinity norm
over all channels and all plant models; gamma < 1 meets every requirement):

1. outer sensitivity  |W_S1 S_o| (output disturbance at the outer measured output);
   W_S1(s) = (s / M_S + w_1) / (s + eps w_1): |S_o| <= eps at DC, bandwidth ~ w_1, peak <= M_S;
2. inner sensitivity  |W_S2 S_i| likewise with w_2 (inner loop, outer loop closed);
3. robustness  |W_T T_u|: complementary sensitivity at the actuator input (loop broken at u),
   W_T(s) = (s / w_T + r_0) / (s / (r_inf w_T) + 1): relative plant error r_0 at low
   frequency (actuator time constant +-30 %, mass +-30 %, inertia +-50 % in the INDI loop),
   growing to r_inf beyond w_T (unmodeled dynamics: servo/attitude lag, further delays);
4. control effort  |W_U K_2 S| from inner measurement noise to the command u:
   W_U = 1 / U_max, the largest admissible noise gain (limits the high-frequency gain);
5. disturbance rejection  |W_D G_d|: acceleration disturbance d -> outer output (the INDI
   residual (1 - A H) d through the closed loop, the quantity the campaign measures),
   W_D = 1/d_max, or with ``wd > 0`` W_D(s) = (s + wd) / (d_max (s + eps wd)), which grows as
   wd/s below wd: gamma <= 1 bounds the position (attitude) error per unit disturbance and,
   below wd, forces it to fall off fast (short recovery, no slow tail);
6. outer control effort  |W_U1 K_1 H S_o| from outer measurement noise (or a reference step)
   to the outer command (velocity / rate command): W_U1 = 1 / U1_max.

Performance scaling ``perf_scales_with_k``: on a model with loop gain k < 1 the sensitivity
bandwidths w1, w2 are required at k w1, k w2 (a vehicle heavier than the controller believes
is allowed to be proportionally slower); robustness, effort and stability are required on every
model unchanged.  Without it the k_lo corner forces a nominal gain the k_hi corner cannot carry.

Structure option ``inner_no_lag``: the inner block is restricted to C >= 0 (P or PI, DC gain
>= D).  Without it the translation optimum put a slow lag (pole 0.8 rad/s, DC gain 40 % of D)
in K_vel, which left a slow tail after each disturbance step in the campaign.

Multi-model: the norms are evaluated on the nominal model and the corners
k in {k_lo, k_hi} x tau in {0.7, 1.3} tau_0 (stability enforced on all of them).

Synthesis: six parameters per cascade (both loops together): for each block the pole
``a = exp(-p Ts)`` (p > 0, so |a| < 1 as the FMU requires), the residue ``g = C B`` and ``D``.
Objective: max over a log frequency grid (+ points added at the exact peaks found by
:func:`controller.lti.hinf_norm` in previous rounds) of |weighted channel|, minimized by
multi-start Nelder-Mead (non-smooth tolerant, deterministic starts), with an infinite
penalty on any unstable model.  The final gamma is certified by the exact norm.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import optimize, signal

from controller.lti import SS, Diagram, Margins, hinf_norm, loop_margins
from plant import load_airframe

# The design constants.  The sample time and the measurement filter are defined here, once:
# ``python -m controller.gains_defaults`` writes them into the controller FMU's generated header
# (fmu_src/controller/default_gains.h: FP_DESIGN_TS, FP_DESIGN_FILT_WN, FP_DESIGN_FILT_ZETA),
# whose values are the FMU's defaults, so the synthesis designs for the loop the FMU runs and
# nothing here reads a built FMU.  The actuator time constant is the shipped design airframe's.
DESIGN_AIRFRAME = "paper_hexacopter"
TS = 0.002  # s, the controller's sample time
FILT_WN = 80.0  # rad/s, natural frequency of the measurement filter H(s)
FILT_ZETA = 0.55  # damping ratio of H(s)
TAU_ACT = load_airframe(DESIGN_AIRFRAME).tau_motor

CHANNELS = ("S_outer", "S_inner", "T_input", "KS_noise", "disturbance", "KS_outer")
# the closed-loop input of each channel in :func:`interconnection` ([do1, do2, di, n2, d])
CHANNEL_INPUT = (0, 1, 2, 3, 4, 0)


@dataclass(frozen=True)
class Block:
    """One first-order block K(z) = d + g / (z - a)."""

    a: float
    g: float
    d: float

    @staticmethod
    def p(gain: float) -> Block:
        """A pure gain block (no state)."""
        return Block(0.0, 0.0, float(gain))

    @staticmethod
    def from_fmu(A: float, B: float, C: float, D: float) -> Block:
        """The block of the FMU parameters (A, B, C, D): the inverse of :meth:`fmu`."""
        return Block(float(A), float(B) * float(C), float(D))

    def fmu(self) -> tuple[float, float, float, float]:
        """(A, B, C, D) for the FMU (B = 1; a P block is A = B = C = 0)."""
        if self.g == 0.0:
            return 0.0, 0.0, 0.0, self.d
        return self.a, 1.0, self.g, self.d

    def ss(self, Ts: float = TS) -> SS:
        """The block as a discrete state space at Ts."""
        A, B, C, D = self.fmu()
        if B == 0.0:
            return SS.gain(D, Ts)
        return SS.make([[A]], [[B]], [[C]], [[D]], Ts)

    def dc_gain(self) -> float:
        """Gain at z = 1."""
        return self.d + self.g / (1.0 - self.a)

    def hf_gain(self) -> float:
        """Gain at Nyquist (z = -1)."""
        return self.d + self.g / (-1.0 - self.a)


@dataclass(frozen=True)
class LoopSpec:
    """Weights and model set of one cascade."""

    name: str
    outer: str
    inner: str
    w1: float            # outer sensitivity bandwidth (rad/s)
    w2: float            # inner sensitivity bandwidth (rad/s)
    ms: float = 2.0      # sensitivity peak bound
    eps: float = 1e-3    # low-frequency sensitivity
    r0: float = 0.35     # low-frequency relative uncertainty
    r_inf: float = 2.0   # high-frequency relative uncertainty
    wT: float = 60.0     # rad/s where the uncertainty reaches ~100 %
    u_max: float = 60.0  # noise -> command gain bound
    u1_max: float = 1e3  # outer noise -> outer command (velocity/rate) gain bound
    d_max: float = 0.01  # disturbance -> outer output bound (outer unit per (unit/s^2))
    wd: float = 0.0      # > 0: W_D grows as ~wd/s below wd (fast recovery, integral action)
    inner_no_lag: bool = False  # inner block restricted to C >= 0 (PI-like, no slow lag tail)
    perf_scales_with_k: bool = False  # performance bandwidths w1, w2 required x min(1, k)
    k_range: tuple[float, float] = (0.77, 1.43)
    tau_scale: tuple[float, float] = (0.7, 1.3)
    delay: int = 1
    tau: float = TAU_ACT
    start: tuple[tuple[float, ...], ...] = field(default_factory=tuple)


TRANSLATION = LoopSpec(
    name="translation", outer="pos", inner="vel",
    w1=2.0, w2=6.0, u_max=30.0, u1_max=3.0, d_max=0.016, wd=3.0, wT=9.0, r0=0.35,
    k_range=(1 / 1.3, 1 / 0.7), inner_no_lag=True, perf_scales_with_k=True,
    # an extra deterministic start: the optimum of an earlier run of these loops
    start=((math.log(-math.log(0.991444) / TS), 0.000895218, 2.07276,
            math.log(-math.log(0.994308) / TS), math.sqrt(0.000741974), 6.32727),))
ROTATION = LoopSpec(
    name="rotation", outer="att", inner="rate",
    w1=8.0, w2=18.0, ms=5.0, u_max=90.0, u1_max=25.0, d_max=0.015, wT=150.0, r0=0.1, r_inf=1.8,
    k_range=(1 / 1.5, 1 / 0.5), delay=0, perf_scales_with_k=True,
    # an extra deterministic start: the optimum of an earlier run of these loops
    start=((math.log(-math.log(0.9977) / TS), 5.59941e-05, 7.65094,
            math.log(-math.log(0.941519) / TS), -0.264554, 18.6923),))
SPECS = (TRANSLATION, ROTATION)


@functools.lru_cache(maxsize=64)
def measurement_filter(Ts: float = TS) -> SS:
    """H(s) as controller.c discretizes it (exact ZOH; output after the update)."""
    a = np.array([[0.0, 1.0], [-FILT_WN ** 2, -2 * FILT_ZETA * FILT_WN]])
    b = np.array([[0.0], [FILT_WN ** 2]])
    d = SS.from_continuous(a, b, np.eye(2), np.zeros((2, 1)), Ts, "zoh")
    Phi, Gam = d.A, d.B
    return SS.make(Phi, Gam, Phi[:1, :], Gam[:1, :], Ts)


@functools.lru_cache(maxsize=64)
def _plant(tau: float, Ts: float = TS, position: bool = True) -> SS:
    """Inputs [u_eff, d]; outputs [a_act, v, p] (or [a_act, v]); ZOH."""
    n = 3 if position else 2
    A = np.array([[-1 / tau, 0, 0], [1, 0, 0], [0, 1, 0]])[:n, :n]
    B = np.array([[1 / tau, 0], [0, 1], [0, 0]])[:n]
    return SS.from_continuous(A, B, np.eye(n), np.zeros((n, 2)), Ts, "zoh")


@functools.lru_cache(maxsize=64)
def _delay(n: int, Ts: float = TS) -> SS:
    if n == 0:
        return SS.gain(1.0, Ts)
    A = np.eye(n, k=-1)
    B = np.zeros((n, 1))
    B[0, 0] = 1.0
    C = np.zeros((1, n))
    C[0, -1] = 1.0
    return SS.make(A, B, C, [[0.0]], Ts)


def perf_scale(spec: LoopSpec, k: float) -> float:
    """Factor on the sensitivity bandwidths required of the model with gain k."""
    return min(1.0, k) if spec.perf_scales_with_k else 1.0


@functools.lru_cache(maxsize=64)
def weights(spec: LoopSpec, k: float = 1.0, Ts: float = TS) -> dict[str, SS]:
    """The weighting functions (continuous, Tustin-discretized) for the model with gain k."""
    c = perf_scale(spec, k)
    w1, w2 = c * spec.w1, c * spec.w2
    ws1 = SS.from_tf([1 / spec.ms, w1], [1, spec.eps * w1], Ts)
    ws2 = SS.from_tf([1 / spec.ms, w2], [1, spec.eps * w2], Ts)
    wt = SS.from_tf([1 / spec.wT, spec.r0], [1 / (spec.r_inf * spec.wT), 1], Ts)
    wd = (SS.from_tf([1 / spec.d_max, spec.wd / spec.d_max], [1, spec.eps * spec.wd], Ts)
          if spec.wd > 0 else SS.gain(1 / spec.d_max, Ts))
    return {"S_outer": ws1, "S_inner": ws2, "T_input": wt,
            "KS_noise": SS.gain(1 / spec.u_max, Ts), "disturbance": wd,
            "KS_outer": SS.gain(1 / spec.u1_max, Ts)}


def interconnection(spec: LoopSpec, k1: Block, k2: Block, k: float = 1.0,
                    tau: float | None = None, weighted: bool = True) -> SS:
    """Closed loop, inputs [do1, do2, di, n2, d], outputs the six requirement channels
    (weighted, or unweighted with ``weighted=False``); requirement i is output i from input
    ``CHANNEL_INPUT[i]``.  Channel 2 (inner sensitivity) is taken with the outer loop open
    (see :func:`channels`); here its pair is the inner sensitivity with both loops closed
    (for information)."""
    tau = spec.tau if tau is None else tau
    dg = Diagram(TS)
    dg.add(_plant(tau), ["udel", "d"], ["a_act", "v", "p"])
    dg.add(_delay(spec.delay), [{"u": k, "Hd": -k, "Ha": 1.0 - k}], ["udel"])
    dg.add(measurement_filter(), [{"p": 1.0, "do1": 1.0}], ["Hp"])
    dg.add(measurement_filter(), [{"v": 1.0, "do2": 1.0, "n2": 1.0}], ["Hv"])
    dg.add(measurement_filter(), ["d"], ["Hd"])
    dg.add(measurement_filter(), ["a_act"], ["Ha"])
    dg.add(k1.ss(), [{"Hp": -1.0}], ["vc"])
    dg.add(k2.ss(), [{"vc": 1.0, "Hv": -1.0}], ["uk"])
    dg.add(SS.gain(1.0, TS), [{"uk": 1.0, "di": 1.0}], ["u"])
    outs: list[str | dict[str, float]] = [
        {"p": 1.0, "do1": 1.0}, {"v": 1.0, "do2": 1.0}, {"uk": -1.0}, {"uk": 1.0}, {"p": 1.0},
        {"vc": 1.0}]
    if weighted:
        w = weights(spec, k)
        for name, o in zip(CHANNELS, outs, strict=True):
            dg.add(w[name], [o], ["z_" + name])
        outs = ["z_" + n for n in CHANNELS]
    return dg.build(["do1", "do2", "di", "n2", "d"], outs)


def inner_loop(spec: LoopSpec, k2: Block, k: float = 1.0, tau: float | None = None,
               weighted: bool = True) -> SS:
    """Inner sensitivity with the outer loop open: do2 -> v + do2 (weighted by W_S2)."""
    tau = spec.tau if tau is None else tau
    dg = Diagram(TS)
    dg.add(_plant(tau, position=False), ["udel", "d"], ["a_act", "v"])
    dg.add(_delay(spec.delay), [{"u": k, "Ha": 1.0 - k}], ["udel"])
    dg.add(measurement_filter(), [{"v": 1.0, "do2": 1.0}], ["Hv"])
    dg.add(measurement_filter(), ["a_act"], ["Ha"])
    dg.add(k2.ss(), [{"Hv": -1.0}], ["u"])
    out: str | dict[str, float] = {"v": 1.0, "do2": 1.0}
    if weighted:
        dg.add(weights(spec, k)["S_inner"], [out], ["z"])
        out = "z"
    return dg.build(["do2", "d"], [out]).sub([0], [0])


def channels(spec: LoopSpec, k1: Block, k2: Block, k: float = 1.0,
             tau: float | None = None) -> list[SS] | None:
    """The six weighted requirement channels (SISO) of one model, None if unstable."""
    cl = interconnection(spec, k1, k2, k, tau)
    ci = inner_loop(spec, k2, k, tau)
    if max(cl.spectral_radius(), ci.spectral_radius()) >= 1.0 - 1e-9:
        return None
    out = [cl.sub([i], [j]) for i, j in enumerate(CHANNEL_INPUT)]
    out[1] = ci
    return out


def models(spec: LoopSpec) -> list[tuple[float, float]]:
    """(k, tau) of the nominal model and the corners."""
    out = [(1.0, spec.tau)]
    for kk in spec.k_range:
        for ts in spec.tau_scale:
            out.append((kk, ts * spec.tau))
    return out


def _unpack(x: np.ndarray, no_lag: bool = False) -> tuple[Block, Block]:
    """Blocks from the search variables; with ``no_lag`` the inner residue is x[4]^2 >= 0
    (a smooth parametrization: a barrier at C = 0 stalls the simplex on its edge)."""
    p1, g1, d1, p2, g2, d2 = x
    a1 = math.exp(-math.exp(p1) * TS)
    a2 = math.exp(-math.exp(p2) * TS)
    return Block(a1, g1, d1), Block(a2, g2 * g2 if no_lag else g2, d2)


def _pack(k1: Block, k2: Block, no_lag: bool = False) -> np.ndarray:
    def lp(a: float) -> float:
        return math.log(-math.log(a) / TS) if 0 < a < 1 else math.log(1.0)
    g2 = math.sqrt(max(k2.g, 0.0)) if no_lag else k2.g
    return np.array([lp(k1.a), k1.g, k1.d, lp(k2.a), g2, k2.d])


def _tf(sys: SS, out: int, inp: int) -> tuple[np.ndarray, np.ndarray]:
    num, den = signal.ss2tf(sys.A, sys.B, sys.C, sys.D, input=inp)
    return np.trim_zeros(num[out], "f") if np.any(num[out]) else np.zeros(1), den


class FastEval:
    """The synthesis objective in the frequency domain: SISO loop algebra on precomputed
    responses (the same model as :func:`interconnection`; tests compare the two), and the
    closed-loop characteristic polynomials for stability:
    ``char = dK1 dK2 cE + k nK2 nH (nV dK1 + nK1 nP)`` with
    ``cE = z^n dPlant dH - (1 - k) nA nH`` (the INDI loop through the actuator feedback), and
    ``dK2 cE2 + k nK2 nH nV2`` for the inner loop alone."""

    def __init__(self, spec: LoopSpec, w: np.ndarray) -> None:
        self.spec, self.w = spec, np.asarray(w, float)
        z = np.exp(1j * self.w * TS)
        self.z = z
        h = measurement_filter()
        self.nh, self.dh = _tf(h, 0, 0)
        self.H = np.polyval(self.nh, z) / np.polyval(self.dh, z)
        self.W = {}
        for kk, _ in models(spec):
            wts = weights(spec, kk)
            self.W[kk] = [wts[c].freqresp(self.w)[:, 0, 0] for c in CHANNELS]
        self.models = []
        zn = np.zeros(spec.delay + 1)
        zn[0] = 1.0
        one = np.array([1.0, -1.0])          # z - 1, kept exact
        for kk, tau in models(spec):
            e = math.exp(-TS / tau)
            # ZOH of A(s)/s (exact): [(Ts - tau(1-e)) z + tau(1-e) - Ts e] / ((z-1)(z-e))
            nv = np.array([TS - tau * (1 - e), tau * (1 - e) - TS * e])
            np_, den = _tf(_plant(tau), 2, 0)            # ZOH of A(s)/s^2
            np_ = np_ / den[0]
            cEp = np.polysub(np.polymul(np.polymul(zn, [1.0, -e]), self.dh),
                             (1 - kk) * (1 - e) * self.nh)   # cE / (z-1)^2
            cE = np.polymul(np.polymul(one, one), cEp)
            cE2 = np.polymul(one, cEp)
            dh, c1 = np.polyval(self.dh, z), np.polyval(cEp, z) * (z - 1.0)
            Gv = kk * np.polyval(nv, z) * dh / c1
            Gp = kk * np.polyval(np_, z) * dh / (c1 * (z - 1.0))
            Pvd = TS / (z - 1.0)
            Ppd = TS * TS * (z + 1.0) / (2.0 * (z - 1.0) ** 2)
            self.models.append(dict(k=kk, nv=np.polymul(nv, one), np=np_, nv2=nv, cE=cE,
                                    cE2=cE2, Gv=Gv, Gp=Gp, Dv=Pvd - Gv * self.H,
                                    Dp=Ppd - Gp * self.H))

    def responses(self, k1: Block, k2: Block) -> np.ndarray | None:
        """|weighted channel| (n_models, len(w), 6), None if a model is unstable."""
        z = self.z
        nk1, dk1 = _block_poly(k1)
        nk2, dk2 = _block_poly(k2)
        K1 = np.polyval(nk1, z) / np.polyval(dk1, z)
        K2 = np.polyval(nk2, z) / np.polyval(dk2, z)
        out = np.empty((len(self.models), len(z), len(CHANNELS)))
        for i, m in enumerate(self.models):
            char = np.polyadd(np.polymul(np.polymul(dk1, dk2), m["cE"]),
                              m["k"] * np.polymul(np.polymul(nk2, self.nh),
                                                  np.polyadd(np.polymul(m["nv"], dk1),
                                                             np.polymul(nk1, m["np"]))))
            char2 = np.polyadd(np.polymul(dk2, m["cE2"]),
                               m["k"] * np.polymul(np.polymul(nk2, self.nh), m["nv2"]))
            if _max_root(char) >= 1.0 - 1e-9 or _max_root(char2) >= 1.0 - 1e-9:
                return None
            W = self.W[m["k"]]
            KH2 = K2 * self.H
            L = KH2 * (m["Gv"] + K1 * m["Gp"])
            S = 1.0 / (1.0 + L)
            So = 1.0 - m["Gp"] * K1 * KH2 * S
            out[i, :, 0] = np.abs(W[0] * So)
            out[i, :, 1] = np.abs(W[1] / (1.0 + KH2 * m["Gv"]))
            out[i, :, 2] = np.abs(W[2] * L * S)
            out[i, :, 3] = np.abs(W[3] * KH2 * S)
            out[i, :, 4] = np.abs(W[4] * (m["Dp"] - m["Gp"] * KH2 * (m["Dv"] + K1 * m["Dp"])
                                               * S))
            out[i, :, 5] = np.abs(W[5] * K1 * self.H * So)
        return out


def _block_poly(b: Block) -> tuple[np.ndarray, np.ndarray]:
    if b.g == 0.0:
        return np.array([b.d]), np.array([1.0])
    return np.array([b.d, b.g - b.d * b.a]), np.array([1.0, -b.a])


def _max_root(p: np.ndarray) -> float:
    p = np.trim_zeros(p, "f")
    return float(np.max(np.abs(np.roots(p)))) if len(p) > 1 else 0.0


def _objective(x: np.ndarray, ev: FastEval) -> float:
    if not np.all(np.isfinite(x)) or np.any(np.abs(x) > 1e4) or max(x[0], x[3]) > 12.0:
        return 1e6
    k1, k2 = _unpack(x, ev.spec.inner_no_lag)
    g = ev.responses(k1, k2)
    if g is None:
        return 1e6
    return float(g.max())


@dataclass(frozen=True)
class ChannelNorm:
    """One requirement channel's weighted H-infinity norm on one model (k, tau) and the frequency
    of its peak."""
    channel: str
    model: tuple[float, float]
    gamma: float
    w_peak: float


@dataclass(frozen=True)
class Design:
    """A cascade's synthesized (or given) blocks with their certified gamma, the norms of every
    channel and model, the margins of the three loops, the crossovers and the closed loop's
    largest spectral radius."""
    spec: LoopSpec
    outer: Block
    inner: Block
    gamma: float
    norms: tuple[ChannelNorm, ...]
    margins: dict[str, Margins]
    bandwidth: dict[str, float]
    spectral_radius: float


def exact_gamma(spec: LoopSpec, k1: Block, k2: Block) -> tuple[float, list[ChannelNorm]]:
    """The certified gamma: exact H-infinity norms of every channel on every model."""
    norms = []
    for kk, tau in models(spec):
        chs = channels(spec, k1, k2, kk, tau)
        if chs is None:
            return math.inf, []
        for ch, sys in zip(CHANNELS, chs, strict=True):
            g, wp = hinf_norm(sys)
            norms.append(ChannelNorm(ch, (kk, tau), g, wp))
    return max(n.gamma for n in norms), norms


def loops(spec: LoopSpec, k1: Block, k2: Block) -> dict[str, SS]:
    """Loop transfers of the nominal model, broken at the actuator input (both loops closed),
    at the inner block's input with the outer loop open, and at the outer block's output with
    the inner loop closed (negative-feedback convention L = -(return))."""
    out: dict[str, SS] = {}
    for where in ("input", "inner", "outer"):
        dg = Diagram(TS)
        if where == "inner":
            dg.add(_plant(spec.tau, position=False), ["udel", "d"], ["a_act", "v"])
        else:
            dg.add(_plant(spec.tau), ["udel", "d"], ["a_act", "v", "p"])
            dg.add(measurement_filter(), ["p"], ["Hp"])
        dg.add(_delay(spec.delay), ["u"], ["udel"])
        dg.add(measurement_filter(), ["v"], ["Hv"])
        if where == "input":
            dg.add(k1.ss(), [{"Hp": -1.0}], ["vc"])
            dg.add(k2.ss(), [{"vc": 1.0, "Hv": -1.0}], ["uk"])
            dg.add(SS.gain(1.0, TS), ["x"], ["u"])
            out[where] = dg.build(["x", "d"], [{"uk": -1.0}]).sub([0], [0])
        elif where == "inner":
            dg.add(k2.ss(), [{"Hv": -1.0}], ["uk"])
            dg.add(SS.gain(1.0, TS), ["x"], ["u"])
            out[where] = dg.build(["x", "d"], [{"uk": -1.0}]).sub([0], [0])
        else:
            dg.add(k1.ss(), [{"Hp": -1.0}], ["vc"])
            dg.add(k2.ss(), [{"x": 1.0, "Hv": -1.0}], ["u"])
            out[where] = dg.build(["x", "d"], [{"vc": -1.0}]).sub([0], [0])
    return out


def analyse(spec: LoopSpec, k1: Block, k2: Block) -> Design:
    """The design of the blocks k1, k2 on spec: exact gamma, margins, crossovers and the
    closed loop's spectral radius."""
    gamma, norms = exact_gamma(spec, k1, k2)
    L = loops(spec, k1, k2)
    margins = {name: loop_margins(Ls) for name, Ls in L.items()}
    bw = {spec.inner: margins["inner"].crossover, spec.outer: margins["outer"].crossover}
    rho = max(max(interconnection(spec, k1, k2, kk, tau, weighted=False).spectral_radius(),
                  inner_loop(spec, k2, kk, tau, weighted=False).spectral_radius())
              for kk, tau in models(spec))
    return Design(spec, k1, k2, gamma, tuple(norms), margins, bw, rho)


def default_grid(n: int = 160) -> np.ndarray:
    """Frequencies (rad/s) of the synthesis objective: n log-spaced from 0.01 to just below
    Nyquist."""
    return np.logspace(-2, np.log10(0.999 * math.pi / TS), n)


def synthesize(spec: LoopSpec, starts: Sequence[Sequence[float] | np.ndarray] | None = None,
               rounds: int = 3, maxiter: int = 1500, seed: int = 0) -> Design:
    """Multi-start Nelder-Mead on the grid objective, the grid refined with the exact peak
    frequencies between rounds.  Deterministic (fixed starts + seeded extra starts)."""
    w = default_grid()
    ev = FastEval(spec, w)
    if starts is None:
        rng = np.random.default_rng(seed)
        base = _pack(Block.p(spec.w1), Block.p(spec.w2), spec.inner_no_lag)
        starts = [base, _pack(Block(math.exp(-spec.w1 / 5 * TS), spec.w1 * spec.w1 / 5 * TS,
                                    spec.w1),
                              Block(math.exp(-spec.w2 / 5 * TS), spec.w2 * spec.w2 / 5 * TS,
                                    spec.w2), spec.inner_no_lag)]
        starts += [base * (1 + 0.3 * rng.standard_normal(6)) for _ in range(2)]
        starts += [np.array(x) for x in spec.start]
    best_x, best_f = None, math.inf
    for start in starts:
        x0 = np.asarray(start, float)
        if _objective(x0, ev) >= 1e6:
            continue
        r = optimize.minimize(_objective, x0, args=(ev,), method="Nelder-Mead",
                              options={"maxiter": maxiter, "xatol": 1e-6, "fatol": 1e-7,
                                       "adaptive": True})
        if r.fun < best_f:
            best_x, best_f = r.x, float(r.fun)
    if best_x is None:
        raise RuntimeError(f"{spec.name}: no stabilizing start")
    for _ in range(rounds):
        k1, k2 = _unpack(best_x, spec.inner_no_lag)
        _, norms = exact_gamma(spec, k1, k2)
        extra = sorted({n.w_peak for n in norms if n.gamma > 0.9 * best_f and n.w_peak > 0})
        w = np.unique(np.concatenate([w, extra]))
        ev = FastEval(spec, w)
        r = optimize.minimize(_objective, best_x, args=(ev,), method="Nelder-Mead",
                              options={"maxiter": maxiter // 2, "xatol": 1e-7, "fatol": 1e-8,
                                       "adaptive": True})
        best_x, best_f = r.x, float(r.fun)
    k1, k2 = _unpack(best_x, spec.inner_no_lag)
    return analyse(spec, k1, k2)


def design_all() -> dict[str, Design]:
    """The synthesis of both cascades (translation, rotation)."""
    return {s.name: synthesize(s) for s in SPECS}


def summary(d: Design) -> str:
    """A design as text: gamma, the blocks, the worst norm per channel, the loops' margins."""
    lines = [f"{d.spec.name}: gamma = {d.gamma:.4f} (spectral radius {d.spectral_radius:.5f})"]
    for name, blk in ((d.spec.outer, d.outer), (d.spec.inner, d.inner)):
        A, B, C, D = blk.fmu()
        lines.append(f"  K_{name}: A = {A:.6g}, B = {B:g}, C = {C:.6g}, D = {D:.6g} "
                     f"(DC gain {blk.dc_gain():.4g}, Nyquist gain {blk.hf_gain():.4g})")
    worst: dict[str, ChannelNorm] = {}
    for n in d.norms:
        if n.channel not in worst or n.gamma > worst[n.channel].gamma:
            worst[n.channel] = n
    for ch, n in worst.items():
        lines.append(f"  {ch:12s} {n.gamma:.4f} at {n.w_peak:.3g} rad/s (k={n.model[0]:.3g}, "
                     f"tau={n.model[1]:.4g})")
    for where, m in d.margins.items():
        lines.append(f"  loop@{where:6s} wc {m.crossover:.3g} rad/s, GM {_db(m.gain_margin)} dB,"
                     f" PM {m.phase_margin:.1f} deg, disk alpha {m.disk_margin:.3f} "
                     f"(gain {m.disk_gain[0]:.2f}..{m.disk_gain[1]:.2f}, "
                     f"phase +-{m.disk_phase:.1f} deg)")
    return "\n".join(lines)


def _db(x: float) -> str:
    return "inf" if not np.isfinite(x) else f"{20 * math.log10(x):.1f}"


__all__ = ["CHANNELS", "ROTATION", "SPECS", "TRANSLATION", "Block", "Design", "LoopSpec",
           "analyse", "design_all", "exact_gamma", "interconnection", "loops", "models",
           "replace", "summary", "synthesize", "weights"]
