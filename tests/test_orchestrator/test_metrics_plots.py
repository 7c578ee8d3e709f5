"""Metrics and plots of a recorded run, on synthetic RunResults with known answers."""

from __future__ import annotations

import json
import math
import threading
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from orchestrator.output.metrics import (
    PAPER_MAX_GUIDANCE_TIME,
    compare_with_paper,
    compute_metrics,
    saturation_fractions,
    wrap_deg,
)
from orchestrator.output.plot_style import envelope, envelope_indices, false_intervals
from orchestrator.output.plots import force_sets, plot_run, resolve_airframe
from orchestrator.output.run_result import RunResult

STEP = 0.002

GROUPS = {
    "ref.pos_ref": 3, "ref.euler_ref": 3, "ref.vel_ref": 3, "ref.acc_ref": 3,
    "ref.euler_rate_ref": 3,
    "dist.f_d": 3, "dist.tau_d": 3, "dist.a_d": 3, "dist.efficiency": 8,
    "plant.pos": 3, "plant.vel": 3, "plant.acc": 3, "plant.euler": 3, "plant.quat": 4,
    "plant.rate": 3, "plant.ang_acc": 3, "plant.omega": 8, "plant.alpha": 8, "plant.beta": 8,
    "plant.f_b": 3, "plant.tau_b": 3, "plant.sat_flags": 1,
    "ctrl.omega_cmd": 8, "ctrl.alpha_cmd": 8, "ctrl.beta_cmd": 8, "ctrl.mu_c": 3,
    "ctrl.f_b_ref": 3, "ctrl.f_b_c": 3, "ctrl.feasible": 1, "ctrl.guid_status": 1,
    "ctrl.guid_iter": 1, "ctrl.alloc_status": 1, "ctrl.alloc_iter": 1, "ctrl.sat_flags": 1,
    "ctrl.guid_flags": 1, "ctrl.acc_c": 3, "ctrl.rate_c": 3, "ctrl.dnu_c": 6,
    "ctrl.alloc_residual": 6, "ctrl.t_step": 1, "ctrl.t_guid": 1, "ctrl.t_alloc": 1,
}


def make_result(n: int, meta: dict | None = None, **signals: np.ndarray) -> RunResult:
    """A RunResult with every recorded column (zeros, efficiency 1, feasible 1) and the given
    signals (keyword = group name with '.' -> '__', e.g. plant__pos)."""
    columns = ["time"]
    blocks = [np.arange(n) * STEP]
    for group, width in GROUPS.items():
        if width == 1:
            columns.append(group)
        else:
            columns += [f"{group}[{i + 1}]" for i in range(width)]
        value = signals.pop(group.replace(".", "__"), None)
        if value is None:
            fill = 1.0 if group in ("dist.efficiency", "ctrl.feasible") else 0.0
            value = np.full((n, width), fill)
        value = np.asarray(value, dtype=float).reshape(n, width)
        blocks.append(value)
    assert not signals, f"unknown signals {list(signals)}"
    data = np.column_stack([b.reshape(n, -1) for b in blocks])
    base = {"scenario": "synthetic", "airframe": "paper_hexacopter", "n_rotors": 6,
            "step": STEP, "duration": (n - 1) * STEP, "wall_time": 2.0,
            "fmu_time": {"plant": 0.5, "controller": 1.0},
            "alpha_limits": [-math.radians(40), math.radians(40)],
            "beta_limits": [-math.radians(40), math.radians(40)],
            "omega_max": 2000 * 2 * math.pi / 60}
    base.update(meta or {})
    return RunResult(columns=columns, data=data, meta=base)


def _no_nan(obj) -> None:
    if isinstance(obj, float):
        assert math.isfinite(obj)
    elif isinstance(obj, dict):
        for v in obj.values():
            _no_nan(v)
    elif isinstance(obj, list):
        for v in obj:
            _no_nan(v)
    else:
        assert obj is None or isinstance(obj, (int, str, bool)), type(obj)


# ---------------------------------------------------------------------------
# metrics


def test_position_error_known_sine():
    n = 10_001
    t = np.arange(n) * STEP
    ref = np.column_stack([np.sin(t), 2 * np.cos(t), np.full(n, -3.0)])
    err = np.column_stack([0.01 * np.sin(2 * np.pi * t), -0.02 * np.cos(np.pi * t),
                           np.full(n, 0.005)])
    m = compute_metrics(make_result(n, ref__pos_ref=ref, plant__pos=ref + err))
    pe = m["position_error"]
    norm = np.linalg.norm(err, axis=1)
    assert pe["max"] == pytest.approx(norm.max(), rel=1e-12)
    assert pe["rms"] == pytest.approx(np.sqrt(np.mean(norm**2)), rel=1e-12)
    assert pe["x"]["max"] == pytest.approx(0.01, rel=1e-6)
    assert pe["x"]["rms"] == pytest.approx(0.01 / math.sqrt(2), rel=1e-3)
    assert pe["y"]["max"] == pytest.approx(0.02, rel=1e-12)
    assert pe["z"]["max"] == pytest.approx(0.005, rel=1e-12)
    assert pe["z"]["rms"] == pytest.approx(0.005, rel=1e-12)
    assert m["nonfinite_rows"] == 0
    assert m["n_samples"] == n


def test_attitude_error_wraps_at_180_deg():
    n = 4
    mu_ref = np.radians([[179.0, 0.0, 170.0],
                         [-179.0, 10.0, 0.0],
                         [0.0, 0.0, -175.0],
                         [90.0, 0.0, 0.0]])
    mu_m = np.radians([[-179.0, 1.0, -170.0],   # +2, +1, +20 (wrapped)
                       [179.0, 10.0, 0.0],      # -2, 0, 0
                       [0.0, -0.5, 175.0],      # 0, -0.5, -10
                       [90.0, 0.0, 180.0]])     # 0, 0, -180 (wrap to [-180, 180))
    mu_c = mu_m - np.radians([[0.1, 0.0, 0.0], [0.0, -0.2, 0.0], [0.0, 0.0, 0.3],
                              [0.0, 0.0, 0.0]])
    res = make_result(n, ref__euler_ref=mu_ref, plant__euler=mu_m, ctrl__mu_c=mu_c)
    m = compute_metrics(res)
    expected = np.array([[2.0, 1.0, 20.0], [-2.0, 0.0, 0.0], [0.0, -0.5, -10.0],
                         [0.0, 0.0, -180.0]])
    np.testing.assert_allclose(wrap_deg(np.degrees(mu_m - mu_ref)), expected, atol=1e-9)
    a = m["attitude_error_vs_mu_ref"]
    assert a["phi"]["max"] == pytest.approx(2.0)
    assert a["theta"]["max"] == pytest.approx(1.0)
    assert a["psi"]["max"] == pytest.approx(180.0)
    assert a["psi"]["rms"] == pytest.approx(np.sqrt(np.mean(expected[:, 2] ** 2)))
    assert a["max_axis"] == pytest.approx(180.0)
    norm = np.linalg.norm(expected, axis=1)
    assert a["max"] == pytest.approx(norm.max())
    assert a["rms"] == pytest.approx(np.sqrt(np.mean(norm**2)))
    c = m["attitude_error_vs_mu_c"]
    assert c["phi"]["max"] == pytest.approx(0.1)
    assert c["theta"]["max"] == pytest.approx(0.2)
    assert c["psi"]["max"] == pytest.approx(0.3)
    assert c["max_axis"] == pytest.approx(0.3)


def test_wrap_deg_range():
    x = np.array([-540.0, -180.0, -179.999, 0.0, 179.999, 180.0, 359.0, 720.5])
    w = wrap_deg(x)
    assert np.all(w >= -180.0) and np.all(w < 180.0)
    np.testing.assert_allclose(w, [-180.0, -180.0, -179.999, 0.0, 179.999, -180.0, -1.0, 0.5],
                               atol=1e-9)


def test_saturation_fractions_from_bit_patterns():
    motor = lambda i: 1 << (i - 1)  # noqa: E731
    alpha = lambda i: 1 << (7 + i)  # noqa: E731
    beta = lambda i: 1 << (15 + i)  # noqa: E731
    flags = np.array([
        0,
        motor(1),
        motor(1) | motor(6) | alpha(2),
        alpha(2) | alpha(3) | beta(6),
        beta(1),
        motor(7) | alpha(8) | beta(7),  # padding rotors of a hexacopter: ignored
        0,
        0,
    ], dtype=float)
    n = flags.size
    m = compute_metrics(make_result(n, ctrl__sat_flags=flags))
    s = m["saturation"]
    assert s["any_motor"] == pytest.approx(2 / n)
    assert s["any_alpha"] == pytest.approx(2 / n)
    assert s["any_beta"] == pytest.approx(2 / n)
    assert s["any"] == pytest.approx(4 / n)
    assert s["motor"] == pytest.approx(3 / (6 * n))
    assert s["alpha"] == pytest.approx(3 / (6 * n))
    assert s["beta"] == pytest.approx(2 / (6 * n))
    # the same flags on an 8-rotor airframe count the last row too
    s8 = saturation_fractions(flags, 8)
    assert s8["any_motor"] == pytest.approx(3 / n)
    assert s8["any"] == pytest.approx(5 / n)


def test_feasibility_qp_counts_and_iterations():
    n = 1000
    rng = np.random.default_rng(3)
    feasible = (rng.random(n) > 0.27).astype(float)
    g_status = rng.integers(0, 4, n).astype(float)
    a_status = np.zeros(n)
    a_status[:7] = 1
    g_iter = rng.integers(0, 12, n).astype(float)
    a_iter = rng.integers(1, 30, n).astype(float)
    m = compute_metrics(make_result(n, ctrl__feasible=feasible, ctrl__guid_status=g_status,
                                    ctrl__alloc_status=a_status, ctrl__guid_iter=g_iter,
                                    ctrl__alloc_iter=a_iter))
    assert m["infeasible_fraction"] == pytest.approx(1 - feasible.mean())
    g = m["guidance_qp"]
    assert g["status_counts"] == {name: int(np.sum(g_status == k)) for k, name in
                                  enumerate(("optimal", "max_iter", "infeasible", "bad_input"))}
    assert g["iter_mean"] == pytest.approx(g_iter.mean())
    assert g["iter_max"] == int(g_iter.max()) and isinstance(g["iter_max"], int)
    a = m["allocation_qp"]
    assert a["status_counts"] == {"optimal": n - 7, "max_iter": 7, "infeasible": 0,
                                  "bad_input": 0}
    assert a["iter_max"] == int(a_iter.max())


def test_timing_and_real_time_factor():
    n = 5001
    rng = np.random.default_rng(7)
    t_guid = rng.uniform(1e-5, 5e-5, n)
    t_guid[1234] = 3e-4
    m = compute_metrics(make_result(n, ctrl__t_guid=t_guid))
    tg = m["timing"]["t_guid"]
    assert tg["max"] == pytest.approx(3e-4)
    assert tg["mean"] == pytest.approx(t_guid.mean())
    assert tg["p99"] == pytest.approx(np.percentile(t_guid, 99))
    assert m["timing"]["t_alloc"] is None and m["timing"]["t_step"] is None
    duration = (n - 1) * STEP
    assert m["duration"] == pytest.approx(duration)
    assert m["real_time_factor"] == pytest.approx(duration / 2.0)
    assert m["master_overhead_fraction"] == pytest.approx((2.0 - 0.5 - 1.0) / 2.0)
    lines = compare_with_paper(m, "full_pose_with_disturbances")
    assert any("EXCEEDS" in ln and f"{PAPER_MAX_GUIDANCE_TIME:.1e}" in ln for ln in lines)


def test_absent_values_are_none_and_json_round_trips():
    n = 50
    res = make_result(n, meta={"wall_time": None, "fmu_time": None})
    m = compute_metrics(res)
    assert m["timing"] == {"t_guid": None, "t_alloc": None, "t_step": None}
    assert m["real_time_factor"] is None and m["master_overhead_fraction"] is None
    # a run without the controller: no attitude-vs-mu_c, QP or saturation metrics
    keep = [i for i, c in enumerate(res.columns) if not c.startswith("ctrl.")]
    bare = RunResult([res.columns[i] for i in keep], res.data[:, keep], dict(res.meta))
    mb = compute_metrics(bare)
    assert mb["attitude_error_vs_mu_c"] is None and mb["guidance_qp"] is None
    assert mb["saturation"] is None and mb["infeasible_fraction"] is None
    for metrics in (m, mb):
        text = json.dumps(metrics, allow_nan=False)
        assert json.loads(text) == metrics
        _no_nan(metrics)


def test_diverged_run_gives_none_not_nan():
    n = 20
    pos = np.zeros((n, 3))
    pos[10:] = np.nan
    m = compute_metrics(make_result(n, plant__pos=pos))
    assert m["nonfinite_rows"] == 10
    assert m["position_error"]["max"] is None
    json.dumps(m, allow_nan=False)


def test_compare_with_paper_lines():
    n = 101
    pos_err = np.zeros((n, 3))
    pos_err[50, 0] = 0.015
    m = compute_metrics(make_result(n, plant__pos=pos_err))
    lines = compare_with_paper(m, "hover_varying_orientation")
    assert "0.02" in lines[0] and "0.0150" in lines[0] and "meets" in lines[0]
    euler = np.zeros((n, 3))
    euler[3, 1] = math.radians(0.8)
    m2 = compute_metrics(make_result(n, plant__euler=euler))
    lines2 = compare_with_paper(m2, "scenarios/translation_frequency_sweep.toml")
    assert "0.6" in lines2[0] and "0.800" in lines2[0] and "EXCEEDS" in lines2[0]
    m3 = compute_metrics(make_result(n))
    assert "not measured" in compare_with_paper(m3, "full_pose_with_disturbances")[0]
    assert compare_with_paper(m3, "my_own_scenario") == []


# ---------------------------------------------------------------------------
# decimation


def test_envelope_keeps_a_one_sample_spike():
    n = 50_001
    t = np.arange(n) * STEP
    rng = np.random.default_rng(1)
    y = 0.001 * rng.standard_normal(n)
    y[31_337] = 0.5
    y[4_242] = -0.25
    td, yd = envelope(t, y, max_points=4000)
    assert td.size <= 4000 + 2
    assert 0.5 in yd and -0.25 in yd
    assert t[31_337] in td
    assert np.all(np.diff(td) > 0)  # time order kept
    assert td[0] == t[0] and td[-1] == t[-1]
    # every bucket's extrema: the decimated envelope's range equals the data's per bucket
    idx = envelope_indices(y, 4000)
    assert idx.dtype.kind == "i"
    short = np.arange(10.0)
    np.testing.assert_array_equal(envelope_indices(short, 4000), np.arange(10))


def test_false_intervals():
    t = np.arange(10) * 1.0
    ok = np.array([1, 0, 0, 1, 1, 0, 1, 0, 0, 0])
    assert false_intervals(t, ok) == [(1.0, 3.0), (5.0, 6.0), (7.0, 10.0)]
    assert false_intervals(t, ok, min_gap=1.5) == [(1.0, 3.0), (5.0, 10.0)]
    assert false_intervals(t, np.ones(10)) == []


# ---------------------------------------------------------------------------
# plots


def scenario_like(n: int = 50_001) -> RunResult:
    """A 100 s, 500 Hz run shaped like scenario 3 (disturbance steps, saturation, timing)."""
    t = np.arange(n) * STEP
    rng = np.random.default_rng(0)
    pos_ref = np.column_stack([3 * np.sin(0.3 * t), 2 * np.sin(0.5 * t), np.full(n, -3.0)])
    pos = pos_ref + 0.003 * rng.standard_normal((n, 3))
    pos[n // 3, 2] += 0.05  # one-sample spike
    mu_ref = np.column_stack([0.53 * np.sin(0.2 * t), -0.35 * np.sin(0.5 * t), np.zeros(n)])
    feasible = (np.abs(mu_ref[:, 0]) < 0.45).astype(float)
    mu_c = np.where(feasible[:, None] > 0, mu_ref, np.clip(mu_ref, -0.45, 0.45))
    mu_m = mu_c + np.radians(0.2) * rng.standard_normal((n, 3))
    a_d = np.zeros((n, 3))
    a_d[(t >= 40) & (t < 50), 0] = 1.0
    a_d[(t >= 70) & (t < 75), 1] = -2.0
    alpha = np.zeros((n, 8))
    beta = np.zeros((n, 8))
    omega = np.zeros((n, 8))
    for i in range(6):
        alpha[:, i] = np.clip(0.9 * np.sin(0.2 * t + i), -0.698, 0.698)
        beta[:, i] = np.clip(0.8 * np.cos(0.5 * t + i), -0.698, 0.698)
        omega[:, i] = 98 + 10 * np.sin(t + i)
    sat = np.where(np.abs(alpha[:, 0]) >= 0.698, 1 << 8, 0).astype(float)
    f_ref = np.column_stack([2 * np.sin(0.2 * t), 1.5 * np.cos(0.5 * t),
                             -6.5 + 0.5 * np.sin(t)])
    f_c = np.clip(f_ref, [-1.2, -1.2, -12.0], [1.2, 1.2, 0.0])
    t_guid = 2e-5 * (1 + rng.random(n))
    t_alloc = 4e-5 * (1 + rng.random(n))
    return make_result(
        n, meta={"scenario": "full_pose_with_disturbances", "duration": 100.0},
        ref__pos_ref=pos_ref, plant__pos=pos, ref__euler_ref=mu_ref, ctrl__mu_c=mu_c,
        plant__euler=mu_m, ctrl__feasible=feasible, dist__a_d=a_d, ctrl__alpha_cmd=alpha,
        ctrl__beta_cmd=beta, ctrl__omega_cmd=omega, ctrl__sat_flags=sat,
        ctrl__f_b_ref=f_ref, ctrl__f_b_c=f_c, ctrl__t_guid=t_guid, ctrl__t_alloc=t_alloc,
        ctrl__guid_iter=rng.integers(0, 5, n).astype(float),
        ctrl__alloc_iter=rng.integers(1, 9, n).astype(float))


def _check_png(path: Path, min_bytes: int = 20_000) -> None:
    assert path.is_file()
    with open(path, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > min_bytes
    img = imread(path)
    assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 500
    assert img.shape[2] in (3, 4)
    # not a blank canvas
    assert float(np.std(img[..., :3])) > 0.01


@pytest.fixture(scope="module")
def big_result() -> RunResult:
    return scenario_like()


def test_plot_run_all_figures(big_result: RunResult, tmp_path: Path):
    paths = plot_run(big_result, tmp_path)
    names = [p.name for p in paths]
    assert names == ["tracking.png", "actuators.png", "forces.png",
                     "disturbance_timing.png", "force_set.png"]
    for p in paths:
        assert p.parent == tmp_path
        _check_png(p)
    af = resolve_airframe(big_result)
    assert af is not None and af.name == "paper_hexacopter"
    afs, s0 = force_sets(af)
    assert force_sets(af)[0] is afs and force_sets(af)[1] is s0  # cached per process
    m = compute_metrics(big_result)
    json.dumps(m, allow_nan=False)
    err_z = big_result.get("plant.pos")[:, 2] - big_result.get("ref.pos_ref")[:, 2]
    assert m["position_error"]["z"]["max"] == pytest.approx(np.abs(err_z).max())


def test_plot_run_without_airframe_or_timing_in_a_thread(tmp_path: Path):
    n = 3001
    t = np.arange(n) * STEP
    res = make_result(
        n, meta={"airframe": "no_such_airframe", "alpha_limits": None, "beta_limits": None,
                 "omega_max": None},
        plant__pos=np.column_stack([np.sin(t), np.zeros(n), -3 + 0 * t]),
        ctrl__guid_iter=np.full(n, 3.0), dist__f_d=np.column_stack([0 * t, 0 * t, 1 + 0 * t]),
        ctrl__feasible=(t < 3).astype(float))
    out: dict[str, object] = {}

    def work() -> None:
        try:
            with pytest.warns(UserWarning, match="no airframe"):
                out["paths"] = plot_run(res, tmp_path / "figs", force_set_png=True)
        except BaseException as exc:  # reported in the main thread
            out["error"] = exc

    th = threading.Thread(target=work)
    th.start()
    th.join(60)
    assert "error" not in out, out.get("error")
    paths = out["paths"]
    assert [p.name for p in paths] == ["tracking.png", "actuators.png", "forces.png",
                                       "disturbance_timing.png"]
    for p in paths:
        _check_png(p, min_bytes=10_000)


def test_plots_module_does_not_import_pyplot():
    import subprocess
    import sys

    code = ("import sys, orchestrator.output.plots, orchestrator.output.metrics; "
            "assert 'matplotlib.pyplot' not in sys.modules")
    root = Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True,
                         text=True, check=False)
    assert res.returncode == 0, res.stderr
