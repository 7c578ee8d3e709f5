"""Small discrete-time LTI toolkit for the robust design (numpy/scipy only).

* :class:`SS` - a discrete state-space system (A, B, C, D) at sample time ``Ts``.
* :class:`Diagram` - block-diagram interconnection by signal names ("connect"): blocks are
  appended block-diagonally and their inputs are linear combinations of named signals.
* :func:`hinf_norm` - the H-infinity norm of a stable discrete system, by the
  Boyd-Balakrishnan / Bruinsma-Steinbuch bisection on the Hamiltonian of the bilinear-
  transformed system (the bilinear map z = (alpha + s) / (alpha - s) maps the unit circle onto
  the imaginary axis one-to-one, so the peak gain is unchanged) - quadratically convergent.
  (tests/test_controller/test_hinf.py checks it against a dense log-frequency grid of
  |G(e^{jwTs})| refined
  near the peak with scipy.optimize.minimize_scalar).
* :func:`loop_margins` - gain, phase and (symmetric) disk margins of a SISO loop.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg, optimize, signal


@dataclass(frozen=True)
class SS:
    """Discrete-time state space x+ = A x + B u, y = C x + D u (sample time Ts)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    Ts: float

    @staticmethod
    def make(A: ArrayLike, B: ArrayLike, C: ArrayLike, D: ArrayLike, Ts: float) -> SS:
        """A discrete state space (A, B, C, D) with sample time Ts, matrices as float arrays."""
        D = np.atleast_2d(np.asarray(D, dtype=float))
        ny, nu = D.shape
        A = np.asarray(A, dtype=float).reshape(-1, int(np.sqrt(np.size(A))) or 0) \
            if np.size(A) else np.zeros((0, 0))
        n = A.shape[0]
        B = np.asarray(B, dtype=float).reshape(n, nu)
        C = np.asarray(C, dtype=float).reshape(ny, n)
        return SS(A, B, C, D, float(Ts))

    @staticmethod
    def gain(k: float | np.ndarray, Ts: float) -> SS:
        """A static gain k (scalar or matrix) as a state space without states."""
        D = np.atleast_2d(np.asarray(k, dtype=float))
        return SS(np.zeros((0, 0)), np.zeros((0, D.shape[1])), np.zeros((D.shape[0], 0)), D, Ts)

    @staticmethod
    def from_continuous(A: ArrayLike, B: ArrayLike, C: ArrayLike, D: ArrayLike, Ts: float,
                        method: str = "zoh") -> SS:
        """The continuous (A, B, C, D) discretized at Ts by scipy's cont2discrete (method: zoh,
        tustin, ...)."""
        Ad, Bd, Cd, Dd, _ = signal.cont2discrete(
            (np.atleast_2d(A), np.atleast_2d(B), np.atleast_2d(C), np.atleast_2d(D)), Ts,
            method=method)
        return SS.make(Ad, Bd, Cd, Dd, Ts)

    @staticmethod
    def from_tf(num: Sequence[float], den: Sequence[float], Ts: float,
                method: str = "bilinear") -> SS:
        """A continuous transfer function num(s)/den(s), discretized."""
        A, B, C, D = signal.tf2ss(num, den)
        if A.size == 0:
            return SS.gain(D, Ts)
        return SS.from_continuous(A, B, C, D, Ts, method)

    @property
    def n(self) -> int:
        """Number of states."""
        return self.A.shape[0]

    def sub(self, outputs: Sequence[int], inputs: Sequence[int]) -> SS:
        """The subsystem from the given inputs to the given outputs (indices)."""
        return SS(self.A, self.B[:, list(inputs)], self.C[list(outputs), :],
                  self.D[np.ix_(list(outputs), list(inputs))], self.Ts)

    def freqresp(self, w: np.ndarray) -> np.ndarray:
        """G(e^{j w Ts}) for angular frequencies w (rad/s): array (len(w), ny, nu)."""
        w = np.atleast_1d(np.asarray(w, dtype=float))
        z = np.exp(1j * w * self.Ts)
        if self.n == 0:
            return np.broadcast_to(self.D, (len(w), *self.D.shape)).astype(complex)
        M = z[:, None, None] * np.eye(self.n)[None] - self.A[None]
        X = np.linalg.solve(M, np.broadcast_to(self.B, (len(w), *self.B.shape)))
        return self.C[None] @ X + self.D[None]

    def spectral_radius(self) -> float:
        """Largest eigenvalue magnitude of A (below 1: stable); 0 without states."""
        return float(np.max(np.abs(np.linalg.eigvals(self.A)))) if self.n else 0.0

    def dlti(self) -> signal.dlti:
        """The system as scipy.signal.dlti."""
        return signal.dlti(self.A, self.B, self.C, self.D, dt=self.Ts)


def append(systems: Sequence[SS]) -> SS:
    """Block-diagonal (parallel, independent) combination."""
    Ts = systems[0].Ts
    return SS(linalg.block_diag(*[s.A for s in systems]) if any(s.n for s in systems)
              else np.zeros((0, 0)),
              _bdiag([s.B for s in systems]), _bdiag([s.C for s in systems]),
              _bdiag([s.D for s in systems]), Ts)


def _bdiag(mats: Sequence[np.ndarray]) -> np.ndarray:
    rows = sum(m.shape[0] for m in mats)
    cols = sum(m.shape[1] for m in mats)
    out = np.zeros((rows, cols))
    r = c = 0
    for m in mats:
        out[r:r + m.shape[0], c:c + m.shape[1]] = m
        r += m.shape[0]
        c += m.shape[1]
    return out


Combo = str | Mapping[str, float]


@dataclass
class Diagram:
    """Interconnect named blocks.  ``add(sys, inputs, outputs)``: each block input is a signal
    name or a {signal: coefficient} combination; signals are block outputs or the external
    inputs named in :meth:`build`.  Algebraic loops are solved (I - D M)^-1."""

    Ts: float
    blocks: list[tuple[SS, list[dict[str, float]], list[str]]] = field(default_factory=list)

    def add(self, sys: SS, inputs: Sequence[Combo], outputs: Sequence[str]) -> None:
        """Add sys, its inputs each a signal name or a weighted sum of names, its outputs named."""
        if sys.D.shape != (len(outputs), len(inputs)):
            raise ValueError(f"block {outputs}: shape {sys.D.shape} vs {len(outputs)}x"
                             f"{len(inputs)}")
        self.blocks.append((sys, [_combo(c) for c in inputs], list(outputs)))

    def build(self, inputs: Sequence[str], outputs: Sequence[Combo]) -> SS:
        """The interconnection from the named inputs to the outputs (names or weighted sums) as one
        state space."""
        big = append([b[0] for b in self.blocks])
        names = [o for b in self.blocks for o in b[2]]
        if len(set(names)) != len(names):
            raise ValueError("duplicate signal names")
        index = {n: i for i, n in enumerate(names)}
        ext = {n: i for i, n in enumerate(inputs)}
        ny, nw = len(names), len(inputs)

        def row(c: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
            m1, m2 = np.zeros(ny), np.zeros(nw)
            for k, v in c.items():
                if k in index:
                    m1[index[k]] += v
                elif k in ext:
                    m2[ext[k]] += v
                else:
                    raise KeyError(f"unknown signal {k!r}")
            return m1, m2

        rows = [row(c) for b in self.blocks for c in b[1]]
        M1 = np.array([r[0] for r in rows]).reshape(-1, ny)
        M2 = np.array([r[1] for r in rows]).reshape(-1, nw)
        outs = [row(_combo(c)) for c in outputs]
        N1 = np.array([r[0] for r in outs]).reshape(-1, ny)
        N2 = np.array([r[1] for r in outs]).reshape(-1, nw)
        F = np.linalg.inv(np.eye(ny) - big.D @ M1)
        Fy, Gy = F @ big.C, F @ big.D @ M2
        A = big.A + big.B @ M1 @ Fy
        B = big.B @ (M1 @ Gy + M2)
        return SS(A, B, N1 @ Fy, N1 @ Gy + N2, self.Ts)


def _combo(c: Combo) -> dict[str, float]:
    return {c: 1.0} if isinstance(c, str) else dict(c)


# ---------------------------------------------------------------------------------------
# H-infinity norm


def to_continuous_bilinear(sys: SS) -> tuple[np.ndarray, ...]:
    """(Ac, Bc, Cc, Dc) with Gc(s) = Gd(z) for z = (alpha + s)/(alpha - s), alpha = 2/Ts.
    Frequencies map as w_c = alpha tan(w Ts / 2), so sup over w of |G| is the same."""
    a = 2.0 / sys.Ts
    n = sys.n
    E = np.linalg.inv(sys.A + np.eye(n))
    Ac = a * E @ (sys.A - np.eye(n))
    Bc = np.sqrt(2 * a) * E @ sys.B
    Cc = np.sqrt(2 * a) * sys.C @ E
    Dc = sys.D - sys.C @ E @ sys.B
    return Ac, Bc, Cc, Dc


def _sigma_max_c(Ac: np.ndarray, Bc: np.ndarray, Cc: np.ndarray, Dc: np.ndarray,
                 w: float) -> float:
    G = Cc @ np.linalg.solve(1j * w * np.eye(Ac.shape[0]) - Ac, Bc) + Dc
    return float(np.linalg.norm(G, 2))


def hinf_norm(sys: SS, rtol: float = 1e-9, max_iter: int = 60) -> tuple[float, float]:
    """(||G||_inf, peak frequency in rad/s) of a stable discrete system.

    Bruinsma-Steinbuch: with a lower bound gamma_lb from candidate frequencies, the Hamiltonian
    H(gamma) of the bilinear-transformed system has imaginary-axis eigenvalues iff
    gamma < ||G||; at gamma = (1 + 2 rtol) gamma_lb we take them, evaluate sigma_max at the
    midpoints of the intervals they bound, and raise gamma_lb until none remain.
    Raises ValueError if the system is unstable (the norm is then infinite)."""
    if sys.n and sys.spectral_radius() >= 1.0:
        raise ValueError("system is not stable (spectral radius >= 1)")
    if sys.n == 0:
        return float(np.linalg.norm(sys.D, 2)), 0.0
    Ac, Bc, Cc, Dc = to_continuous_bilinear(sys)
    alpha = 2.0 / sys.Ts
    # initial candidates: DC, Nyquist (w_c -> inf, i.e. Dc), and pole-related frequencies
    poles = np.linalg.eigvals(Ac)
    cands = [0.0] + [abs(p) for p in poles if abs(p) > 0]
    cands += [abs(p.imag) for p in poles if abs(p.imag) > 0]
    gl, wpk = float(np.linalg.norm(Dc, 2)), np.inf
    for w in cands:
        s = _sigma_max_c(Ac, Bc, Cc, Dc, w)
        if s > gl:
            gl, wpk = s, w
    for _ in range(max_iter):
        g = (1.0 + 2.0 * rtol) * gl
        R = g * g * np.eye(Dc.shape[1]) - Dc.T @ Dc
        S = g * g * np.eye(Dc.shape[0]) - Dc @ Dc.T
        Ri = np.linalg.inv(R)
        H = np.block([
            [Ac + Bc @ Ri @ Dc.T @ Cc, g * Bc @ Ri @ Bc.T],
            [-g * Cc.T @ np.linalg.inv(S) @ Cc, -(Ac + Bc @ Ri @ Dc.T @ Cc).T]])
        ev = np.linalg.eigvals(H)
        scale = max(1.0, float(np.max(np.abs(ev))))
        im = np.sort(np.abs(ev[np.abs(ev.real) < 1e-8 * scale].imag))
        im = np.unique(np.round(im, 12))
        if len(im) == 0:
            break
        mids = [0.5 * (im[i] + im[i + 1]) for i in range(len(im) - 1)] or [im[0]]
        improved = False
        for w in mids:
            s = _sigma_max_c(Ac, Bc, Cc, Dc, w)
            if s > gl:
                gl, wpk, improved = s, w, True
        if not improved:
            break
    w_d = 2.0 / sys.Ts * np.arctan(wpk / alpha) if np.isfinite(wpk) else np.pi / sys.Ts
    return gl, float(w_d)


# ---------------------------------------------------------------------------------------
# Margins of a SISO loop L(z) (negative feedback)


@dataclass(frozen=True)
class Margins:
    """Margins of a SISO loop L(z) in negative feedback: crossover, gain and phase margins, the
    symmetric disk margin and the sensitivity peaks."""
    crossover: float           # rad/s, |L| = 1 (the highest crossing)
    gain_margin: float         # factor (inf if the phase never crosses -180 deg)
    phase_crossover: float     # rad/s
    phase_margin: float        # deg (smallest over all gain crossings)
    disk_margin: float         # alpha of the symmetric (balanced) disk margin
    disk_gain: tuple[float, float]   # gain range that disk covers
    disk_phase: float          # deg
    peak_S: float
    peak_T: float


def loop_margins(L: SS, n_grid: int = 6000) -> Margins:
    """Gain/phase margins from a dense grid with crossings refined by brentq; symmetric disk
    margin alpha = 1 / ||(S - T)/2||_inf (Seiler, Packard, Gahinet 2020), with S, T exact via
    :func:`hinf_norm` of the closed-loop state spaces."""
    wn = np.pi / L.Ts
    w = np.logspace(-3, np.log10(wn * 0.9999), n_grid)
    g = L.freqresp(w)[:, 0, 0]

    def mag(x: float) -> float:
        return float(np.abs(L.freqresp(np.array([x]))[0, 0, 0])) - 1.0

    def ph(x: float) -> float:
        return float(np.imag(L.freqresp(np.array([x]))[0, 0, 0]))

    wc_list = []
    m = np.abs(g) - 1.0
    for i in np.nonzero(np.sign(m[:-1]) != np.sign(m[1:]))[0]:
        wc_list.append(optimize.brentq(mag, w[i], w[i + 1], xtol=1e-12))
    pm = np.inf
    for wc in wc_list:
        phase = np.degrees(np.angle(L.freqresp(np.array([wc]))[0, 0, 0]))
        pm = min(pm, 180.0 + phase if phase <= 0 else phase - 180.0)
        pm = min(pm, (180.0 + phase) % 360.0)
    gm, wpc = np.inf, np.nan
    neg = (g.real < 0)
    im = g.imag
    for i in np.nonzero((np.sign(im[:-1]) != np.sign(im[1:])) & neg[:-1] & neg[1:])[0]:
        x = optimize.brentq(ph, w[i], w[i + 1], xtol=1e-12)
        v = L.freqresp(np.array([x]))[0, 0, 0]
        if v.real < 0 and 1.0 / abs(v) < gm:
            gm, wpc = 1.0 / abs(v), x
    S = feedback_sensitivity(L)
    T = _complementary(L)
    diff = SS(S.A, S.B, S.C, S.D - 0.5, L.Ts)   # S - 1/2 = (S - T)/2
    alpha = 1.0 / hinf_norm(diff)[0]
    lo = (1 - alpha / 2) / (1 + alpha / 2) if alpha < 2 else 0.0
    hi = (1 + alpha / 2) / (1 - alpha / 2) if alpha < 2 else np.inf
    return Margins(max(wc_list) if wc_list else np.nan, gm, wpc, pm, alpha, (lo, hi),
                   float(np.degrees(2 * np.arctan(alpha / 2))), hinf_norm(S)[0],
                   hinf_norm(T)[0])


def feedback_sensitivity(L: SS) -> SS:
    """S = 1/(1 + L) as a state space (SISO)."""
    d = Diagram(L.Ts)
    d.add(L, [{"r": 1.0, "y": -1.0}], ["y"])
    return d.build(["r"], [{"r": 1.0, "y": -1.0}])


def _complementary(L: SS) -> SS:
    d = Diagram(L.Ts)
    d.add(L, [{"r": 1.0, "y": -1.0}], ["y"])
    return d.build(["r"], ["y"])
