"""Structured H-infinity design: our norm vs independent methods, the shipped design's gamma,
stability and margins, and the freshness of the shipped gains header."""

from __future__ import annotations

import inspect
import json
import math

import numpy as np
import pytest
from scipy import optimize, signal

from controller import baseline, gains_defaults, hinf
from controller.lti import SS, hinf_norm, loop_margins

TS = hinf.TS


# -- independent oracles of the synthesis' own routines (brute force on grids) --


def hinf_norm_grid(sys: SS, n_grid: int = 4000, w_min: float = 1e-3) -> tuple[float, float]:
    """Independent check of :func:`hinf_norm`: a dense log grid of the largest singular value
    of G(e^{j w Ts}) up to Nyquist, refined around the best few points by bounded scalar
    minimization (scipy.optimize.minimize_scalar)."""
    wn = np.pi / sys.Ts
    w = np.concatenate([[0.0], np.logspace(np.log10(w_min), np.log10(wn), n_grid)])

    def smax(x: float) -> float:
        return float(np.linalg.norm(sys.freqresp(np.array([x]))[0], 2))

    g = np.linalg.norm(sys.freqresp(w), ord=2, axis=(1, 2))
    best, wbest = float(g.max()), float(w[int(g.argmax())])
    for i in np.argsort(g)[-5:]:
        lo, hi = w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)]
        if hi <= lo:
            continue
        r = optimize.minimize_scalar(lambda x: -smax(x), bounds=(lo, hi), method="bounded",
                                     options={"xatol": 1e-10 * max(hi, 1.0)})
        if -r.fun > best:
            best, wbest = float(-r.fun), float(r.x)
    return best, wbest


def grid_gains(spec: hinf.LoopSpec, k1: hinf.Block, k2: hinf.Block,
               w: np.ndarray) -> np.ndarray | None:
    """|weighted channels| on a grid for every model: (n_models, len(w), 6), or None when a
    model's closed loop is unstable."""
    out = []
    for kk, tau in hinf.models(spec):
        cl = hinf.interconnection(spec, k1, k2, kk, tau)
        ci = hinf.inner_loop(spec, k2, kk, tau)
        if max(cl.spectral_radius(), ci.spectral_radius()) >= 1.0 - 1e-9:
            return None
        g = np.abs(cl.freqresp(w)[:, np.arange(len(hinf.CHANNELS)), list(hinf.CHANNEL_INPUT)])
        g[:, 1] = np.abs(ci.freqresp(w)[:, 0, 0])
        out.append(g)
    return np.array(out)


def _random_stable(rng: np.random.Generator, n: int, ny: int, nu: int) -> SS:
    A = rng.normal(size=(n, n))
    A *= rng.uniform(0.5, 0.995) / max(abs(np.linalg.eigvals(A)))
    return SS.make(A, rng.normal(size=(n, nu)), rng.normal(size=(ny, n)),
                   rng.normal(size=(ny, nu)), TS)


@pytest.mark.parametrize("seed", range(4))
def test_hinf_norm_matches_dense_grid(seed):
    sys = _random_stable(np.random.default_rng(seed), 6, 2, 2)
    g, _ = hinf_norm(sys)
    g_ref, _ = hinf_norm_grid(sys)
    assert g == pytest.approx(g_ref, rel=1e-6)


def test_hinf_norm_lightly_damped_resonance_vs_scipy():
    # a sharp resonance (zeta = 0.002) that a coarse grid would miss
    num, den = [100.0], [1.0, 2 * 0.002 * 10.0, 100.0]
    d = signal.cont2discrete((num, den), TS, method="bilinear")
    sys = SS.make(*signal.tf2ss(np.squeeze(d[0]), d[1]), TS)
    g, wp = hinf_norm(sys)
    w = np.linspace(9.9, 10.1, 200001)
    _, h = signal.dfreqresp(signal.dlti(np.squeeze(d[0]), d[1], dt=TS), w * TS)
    assert g == pytest.approx(np.abs(h).max(), rel=1e-5)
    assert wp == pytest.approx(w[np.abs(h).argmax()], abs=2e-3)


def test_fast_objective_matches_state_space():
    w = hinf.default_grid(60)
    k1, k2 = hinf.Block(0.99, 0.01, 0.8), hinf.Block(0.998, -0.01, 11.0)
    spec = hinf.replace(hinf.TRANSLATION, u1_max=3.0)  # weight KS_outer visibly
    fast = hinf.FastEval(spec, w).responses(k1, k2)
    ref = grid_gains(spec, k1, k2, w)
    assert fast is not None and ref is not None
    np.testing.assert_allclose(fast[..., :4], ref[..., :4], rtol=1e-5)
    np.testing.assert_allclose(fast[..., 4], ref[..., 4], rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(fast[..., 5], ref[..., 5], rtol=1e-5)


def _shipped() -> dict:
    return json.loads(gains_defaults.CACHE.read_text())


@pytest.fixture(scope="module")
def designs() -> dict[str, hinf.Design]:
    blocks = _shipped()["blocks"]
    out = {}
    for spec, (o, i) in ((hinf.TRANSLATION, ("pos", "vel")), (hinf.ROTATION, ("att", "rate"))):
        out[spec.name] = hinf.analyse(spec, hinf.Block.from_fmu(*blocks[o]),
                                      hinf.Block.from_fmu(*blocks[i]))
    return out


def test_shipped_design_is_stable_on_all_models(designs):
    for d in designs.values():
        assert d.spectral_radius < 1.0
        for kk, tau in hinf.models(d.spec):
            cl = hinf.interconnection(d.spec, d.outer, d.inner, kk, tau, weighted=False)
            assert np.max(np.abs(np.linalg.eigvals(cl.A))) < 1.0


def test_shipped_gamma(designs):
    """gamma is certified by the exact norm; recorded in the header."""
    rep = _shipped()["report"]
    for name, d in designs.items():
        assert d.gamma == pytest.approx(rep[name]["gamma"], rel=1e-6)
    assert designs["translation"].gamma < 1.0
    assert designs["rotation"].gamma < 1.0


def test_model_sets_cover_the_campaign():
    """The multi-model sets span the certified ranges: mass +-30 %, inertia +-50 %, tau +-30 %."""
    assert hinf.TRANSLATION.k_range == pytest.approx((1 / 1.3, 1 / 0.7))
    assert hinf.ROTATION.k_range == pytest.approx((1 / 1.5, 1 / 0.5))
    for spec in hinf.SPECS:
        assert spec.tau_scale == pytest.approx((0.7, 1.3))


def test_velocity_block_has_no_lag_tail(designs):
    """K_vel is restricted to C >= 0 (DC gain >= D): no slow lag tail after a disturbance."""
    k2 = designs["translation"].inner
    assert k2.g >= 0.0 and k2.dc_gain() >= k2.d


def test_rotation_tolerates_one_sample_delay(designs):
    """Rotation is designed with n = 0; with the Jacobi/hardware sample of delay every model
    stays stable (the weights are then not all met: see docs/robust_design.md)."""
    d = designs["rotation"]
    spec = hinf.replace(d.spec, delay=1)
    for kk, tau in hinf.models(spec):
        cl = hinf.interconnection(spec, d.outer, d.inner, kk, tau, weighted=False)
        assert np.max(np.abs(np.linalg.eigvals(cl.A))) < 1.0


def _loops_from_pieces(spec: hinf.LoopSpec, k1: hinf.Block, k2: hinf.Block, w: np.ndarray):
    """The nominal loop transfers rebuilt from low-order pieces with scipy.signal (ZOH of
    A(s)/s and A(s)/s^2, the filter, z^-n, the blocks) - independent of the state-space
    interconnection code."""
    tau = spec.tau
    z = np.exp(1j * w * TS)

    def zoh(num, den):
        n, d, _ = signal.cont2discrete((num, den), TS, method="zoh")
        return np.polyval(np.squeeze(n), z) / np.polyval(d, z)

    Pv = zoh([1.0], [tau, 1.0, 0.0])
    Pp = zoh([1.0], [tau, 1.0, 0.0, 0.0])
    f = hinf.measurement_filter()
    hn, hd = signal.ss2tf(f.A, f.B, f.C, f.D)
    Hf = np.polyval(hn[0], z) / np.polyval(hd, z)
    Dl = z ** (-spec.delay)

    def blk(b):
        return b.d + b.g / (z - b.a)

    K1, K2 = blk(k1), blk(k2)
    inner = Dl * K2 * Hf * Pv
    return {"input": Dl * K2 * Hf * (Pv + K1 * Pp), "inner": inner,
            "outer": K1 * Hf * Pp * Dl * K2 / (1.0 + inner)}


def test_margins_vs_scipy_dense_grid(designs):
    w = np.logspace(-2, np.log10(0.999 * math.pi / TS), 200000)
    for d in designs.values():
        ref = _loops_from_pieces(d.spec, d.outer, d.inner, w)
        for where, L in hinf.loops(d.spec, d.outer, d.inner).items():
            m = loop_margins(L)
            h = ref[where]
            np.testing.assert_allclose(L.freqresp(w[::1000])[:, 0, 0], h[::1000], rtol=1e-4)
            cross = np.nonzero(np.diff(np.sign(np.abs(h) - 1.0)))[0]
            i = cross[-1]
            assert m.crossover == pytest.approx(w[i], rel=1e-4)
            pm = 180.0 + np.degrees(np.angle(h[i]))
            assert m.phase_margin == pytest.approx(pm, abs=0.05)
            # symmetric disk margin: 1 / max |S - 1/2|
            alpha = 1.0 / np.max(np.abs(1.0 / (1.0 + h) - 0.5))
            assert m.disk_margin == pytest.approx(alpha, rel=1e-4)
            if np.isfinite(m.gain_margin):
                pc = np.nonzero((np.diff(np.sign(h.imag)) != 0) & (h.real[:-1] < 0))[0]
                assert m.gain_margin == pytest.approx(1 / np.abs(h[pc]).max(), rel=1e-3)


def test_shipped_header_is_fresh():
    # run from the checkout: an installed package has no fmu_src/ to compare against
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "-m", "controller.gains_defaults", "--check"],
                         cwd=root, capture_output=True, text=True, check=False)
    assert res.returncode == 0, res.stdout + res.stderr


def _spec(which: str, **change: object) -> tuple[hinf.LoopSpec, ...]:
    return tuple(hinf.replace(s, **change) if s.name == which else s for s in hinf.SPECS)


INPUT_CHANGES = {
    "sample time": lambda: ("TS", 0.0025),
    "filter frequency": lambda: ("FILT_WN", 55.0),
    "filter damping": lambda: ("FILT_ZETA", 0.6),
    "actuator constant": lambda: ("TAU_ACT", 1.0 / 50.0),
    "actuator tau of a spec": lambda: ("SPECS", _spec("translation",
                                                      tau=1.1 * hinf.TRANSLATION.tau)),
    "a weight": lambda: ("SPECS", _spec("rotation", u_max=80.0)),
    "a model set": lambda: ("SPECS", _spec("translation", k_range=(0.8, 1.4))),
    "the computational delay": lambda: ("SPECS", _spec("rotation", delay=1)),
}


@pytest.mark.parametrize("change", sorted(INPUT_CHANGES))
def test_inputs_hash_covers_every_synthesis_number(change, monkeypatch):
    """Each number the synthesis reads, changed at run time (the sources unchanged), changes
    the hash: the quick --check then says the shipped gains are stale."""
    shipped = _shipped()["hash"]
    assert gains_defaults.inputs_hash() == shipped
    name, value = INPUT_CHANGES[change]()
    monkeypatch.setattr(hinf, name, value)
    assert gains_defaults.inputs_hash() != shipped
    ok, msg = gains_defaults.check()
    assert not ok and "synthesis inputs changed" in msg


@pytest.mark.parametrize(("func", "param", "value"), [
    (hinf.synthesize, "seed", 1), (hinf.synthesize, "maxiter", 1000),
    (hinf.default_grid, "n", 200), (hinf.hinf_norm, "rtol", 1e-6),
])
def test_inputs_hash_covers_default_arguments(func, param, value, monkeypatch):
    shipped = _shipped()["hash"]
    names = [p.name for p in inspect.signature(func).parameters.values()
             if p.default is not inspect.Parameter.empty]
    defaults = list(func.__defaults__)
    defaults[names.index(param)] = value
    monkeypatch.setattr(func, "__defaults__", tuple(defaults))
    assert gains_defaults.inputs_hash() != shipped


def test_inputs_hash_ignores_last_digit_round_off(monkeypatch):
    """A last-digit (1e-15 relative) difference, e.g. another platform's libm in the specs'
    start points, is no input change: inputs are hashed to 12 significant digits."""
    shipped = _shipped()["hash"]
    monkeypatch.setattr(hinf, "FILT_WN", hinf.FILT_WN * (1.0 + 2e-15))
    monkeypatch.setattr(hinf, "SPECS", _spec("rotation", start=tuple(
        tuple(x * (1.0 + 2e-15) for x in s) for s in hinf.ROTATION.start)))
    assert gains_defaults.inputs_hash() == shipped


@pytest.mark.slow
def test_fresh_synthesis_reproduces_the_shipped_gains():
    """Reruns the whole synthesis (~30 s): the shipped numbers within 1e-6 (opt-in, since
    another scipy/numpy build may move the simplex path in the last digits)."""
    ok, msg = gains_defaults.check(full=True)
    assert ok, msg


def test_baseline_matches_hinf_bandwidths():
    bw = baseline.shipped_bandwidths()
    g = baseline.compute_gains()
    for spec, (o, i) in ((hinf.TRANSLATION, ("pos", "vel")), (hinf.ROTATION, ("att", "rate"))):
        L = hinf.loops(spec, hinf.Block.p(g[o]), hinf.Block.p(g[i]))
        assert loop_margins(L["inner"]).crossover == pytest.approx(bw[i], rel=1e-4)
        assert loop_margins(L["outer"]).crossover == pytest.approx(bw[o], rel=1e-4)


def test_controller_fmu_ships_the_synthesized_gains():
    """The FMU's declared start values (written by mdgen from the C defaults) are the
    synthesis result, read back through fmpy as any importer would."""
    from fmpy import read_model_description

    from controller import controller_fmu

    md = read_model_description(str(controller_fmu()))
    start = {v.name: v.start for v in md.modelVariables}
    for name, value in gains_defaults.controller_parameters().items():
        assert float(start[name]) == value, name


def test_velocity_loop_stays_slower_than_attitude_loop(designs):
    """An under-actuated vehicle (quadrotor, or any vehicle at an infeasible attitude) gets
    its lateral force through its attitude: the prototype's lesson (docs/architecture.md) that the
    velocity loop must not outrun the attitude loop, which the translation's robustness
    weight (w_T at the attitude bandwidth) enforces."""
    vel = designs["translation"].bandwidth["vel"]
    att = designs["rotation"].bandwidth["att"]
    assert vel < att
    assert hinf.TRANSLATION.wT <= 1.5 * att


def test_the_controller_fmu_runs_the_filter_and_sample_time_the_synthesis_designed_for():
    """The synthesis' H(z) (``hinf._filter``, scipy's ZOH at ``hinf.TS``) against the FMU's
    own: with K_pos = 0 and K_vel = 1 the commanded acceleration is -H[vel], so a unit step
    on the measured velocity returns the FMU's filter step response in ``acc_c``."""
    from controller import controller_fmu
    from orchestrator.sim.fmu import FmuInstance

    zero = {f"K_{loop}_{n}[{i}]": 0.0 for loop in ("pos", "vel") for n in "ABCD"
            for i in (1, 2, 3)}
    zero.update({f"K_vel_D[{i}]": 1.0 for i in (1, 2, 3)})
    with FmuInstance(controller_fmu(), "ctrl") as c:
        c.initialize(parameters=zero)
        assert c.get("Ts") == hinf.TS
        vel, acc_c = c.signal("vel"), c.signal("acc_c")
        steps = 500
        got = np.empty(steps)
        c.write(vel, [1.0, 0.0, 0.0])
        for k in range(steps):
            c.step(hinf.TS)
            got[k] = -c.read(acc_c)[0]
    H = hinf.measurement_filter()
    x = np.zeros((H.A.shape[0], 1))
    want = np.empty(steps)
    for k in range(steps):  # y_k = C x_k + D u_k (the FMU's output after its update)
        want[k] = (H.C @ x + H.D * 1.0).item()
        x = H.A @ x + H.B * 1.0
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert want[-1] == pytest.approx(1.0, abs=1e-6)  # unit DC gain: H(1) = 1
