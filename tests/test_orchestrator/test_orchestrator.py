"""The orchestrator end to end: the paper's scenarios, determinism, files, CLI."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from helpers import fullpose as cli

from orchestrator.master import run
from orchestrator.output.metrics import compute_metrics
from orchestrator.output.run_result import RunResult
from orchestrator.runner import prepare, run_scenario

PAPER = ["hover_varying_orientation", "translation_frequency_sweep", "full_pose_with_disturbances"]


def check_paper_bounds(name, m, full):
    """Bounds: the paper's claims where it makes one, our measured level with margin else."""
    pos = m["position_error"]["max"]
    assert m["nonfinite_rows"] == 0
    if name == "hover_varying_orientation":
        assert pos <= 0.02  # paper: within 0.02 m
        assert 0.0 < m["infeasible_fraction"] < 0.5  # infeasible windows occur
        assert m["attitude_error_vs_mu_c"]["max"] < 2.0  # deg, mu_m tracks mu_c
    elif name == "translation_frequency_sweep":
        assert m["attitude_error_vs_mu_ref"]["max"] <= 0.6  # paper: within +-0.6 deg
        assert pos <= 0.005  # prototype with feed-forward: 5 mm
    else:
        assert pos <= 0.035
        if full:  # the disturbance steps saturate the servos at some point
            assert m["saturation"]["any_alpha"] > 0 or m["saturation"]["any_beta"] > 0


@pytest.mark.parametrize("name", PAPER)
def test_short_paper_scenarios(name):
    result = run(prepare(name, duration=20.0))
    check_paper_bounds(name, compute_metrics(result), full=False)


@pytest.mark.slow
@pytest.mark.parametrize("name", PAPER)
def test_full_paper_scenarios(name, tmp_path):
    out = run_scenario(prepare(name), tmp_path, timing=True, csv=False)
    check_paper_bounds(name, out.metrics, full=True)
    assert (tmp_path / "tracking.png").is_file()


def test_runs_are_bit_identical_and_engines_agree():
    sc = prepare("full_pose_with_disturbances", duration=12.0)  # includes disturbance steps
    a = run(sc)
    b = run(sc)
    c = run(sc, engine="python")
    assert a.columns == b.columns == c.columns
    assert np.array_equal(a.data, b.data)
    assert np.array_equal(a.data, c.data)


def test_jacobi_coupling_delays_the_command_by_one_sample():
    sc = prepare("position_step", duration=5.0)  # the shaped 1 m step takes ~3 s
    gs = run(sc)
    jac = run(dataclasses.replace(sc, coupling="jacobi"))
    assert jac.meta["coupling"] == "jacobi"
    assert not np.array_equal(gs.data, jac.data)
    # both fly the step; the one-sample delay changes the response only slightly
    for r in (gs, jac):
        x = r.get("plant.pos")[:, 0]
        assert abs(x[-1] - 1.0) < 0.05 and x.max() < 1.1
    # the step starts at t = 1 s: Jacobi's response is the Gauss-Seidel one, one sample later
    k1 = 500
    lag = np.abs(jac.get("plant.pos")[k1 + 60, 0] - gs.get("plant.pos")[k1 + 60, 0])
    assert 0 < lag < 0.01


def test_every_exchanged_signal_is_recorded():
    r = run(prepare("hover", duration=0.2))
    n = 101
    assert r.data.shape[0] == n and np.allclose(r.time, np.arange(n) * 0.002)
    # the hexacopter's six rotors only: no constant columns for the FMUs' rotors 7 and 8
    for group, width in [("ref.pos_ref", 3), ("ref.rotor_health", 6), ("dist.efficiency", 6),
                         ("plant.pos", 3), ("plant.omega", 6), ("plant.alpha", 6),
                         ("ctrl.omega_cmd", 6), ("ctrl.beta_cmd", 6), ("ctrl.mu_c", 3)]:
        assert r.get(group).shape == (n, width)
    assert not [c for c in r.columns if c.endswith(("[7]", "[8]"))]
    for scalar in ("ctrl.feasible", "ctrl.guid_iter", "ctrl.sat_flags", "plant.sat_flags"):
        assert r.get(scalar).shape == (n,)
    # what the plant was commanded at step k is what the controller output at step k
    np.testing.assert_allclose(r.get("plant.omega")[1, :6],
                               r.get("plant.omega")[0, :6]
                               + (r.get("ctrl.omega_cmd")[0, :6] - r.get("plant.omega")[0, :6])
                               * (1 - np.exp(-0.002 * 53.94)), rtol=0, atol=1e-6)


def test_result_files_read_back(tmp_path):
    out = run_scenario(prepare("hover", duration=1.0), tmp_path, timing=False, plots=False,
                       csv=True)
    from_parquet = RunResult.read(tmp_path)  # the folder: its results.parquet
    from_csv = RunResult.read(tmp_path / "results.csv")
    assert from_parquet.columns == out.result.columns == from_csv.columns
    assert np.array_equal(from_csv.data, out.result.data)  # shortest repr round-trips
    for i, name in enumerate(out.result.columns):  # each column exactly as it claims
        assert np.array_equal(from_parquet.data[:, i], out.result.stored(name)), name
    assert from_parquet.integer == out.result.integer and "ctrl.guid_iter" in out.result.integer
    assert from_parquet.meta["scenario"] == "hover"
    doc = json.loads((tmp_path / "metrics.json").read_text())
    assert doc["metrics"]["position_error"]["max"] < 1e-3


def test_cli_run_writes_metrics_and_figures(tmp_path):
    res = cli("run", "hover_varying_orientation", "--duration", "4", "--out", str(tmp_path))
    assert res.returncode == 0, res.stderr
    assert "max position error" in res.stdout
    for name in ("results.parquet", "metrics.json", "tracking.png", "actuators.png",
                 "forces.png", "disturbance_timing.png", "force_set.png"):
        path = tmp_path / name
        assert path.is_file() and path.stat().st_size > 1000, name
    assert (tmp_path / "tracking.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    metrics = json.loads((tmp_path / "metrics.json").read_text())["metrics"]
    assert metrics["timing"]["t_guid"]["max"] > 0  # the CLI measures compute times


def test_cli_lists_and_checks_scenarios(tmp_path):
    res = cli("scenarios")
    assert res.returncode == 0
    for name in PAPER:
        assert name in res.stdout
    assert cli("check", "translation_frequency_sweep").returncode == 0


def test_cli_rejects_invalid_scenario_without_running(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('duration = 10.0\nairframe = "paper_hexacopter"\n'
                   '[reference.position]\nx = { type = "sine", amplitude = "big", omega = 1.0 }\n')
    out = tmp_path / "out"
    for cmd in (("check", str(bad)), ("run", str(bad), "--out", str(out))):
        res = cli(*cmd)
        assert res.returncode == 2
        assert str(bad) in res.stderr and "reference.position.x.amplitude" in res.stderr
    assert not out.exists()  # nothing ran half-way


def test_cli_parameter_overrides(tmp_path):
    res = cli("run", "position_step", "--duration", "3", "--no-plots", "--no-csv", "--out",
              str(tmp_path / "slow"), "--set", "controller.K_pos_D[1]=1.0")
    assert res.returncode == 0, res.stderr
    assert not (tmp_path / "slow" / "results.csv").exists()  # CSV only with --csv

    def lag(r: RunResult) -> float:  # behind the (shaped) step the controller flies
        return float(np.abs(r.get("plant.pos")[:, 0] - r.get("ctrl.pos_ref_s")[:, 0]).max())

    slow = RunResult.read(tmp_path / "slow")
    fast = run(prepare("position_step", duration=3.0))
    assert lag(slow) > lag(fast)  # a softer position gain follows the step less closely
    bad = cli("run", "position_step", "--set", "controller.no_such=1", "--out",
              str(tmp_path / "x"))
    assert bad.returncode == 2 and "no_such" in bad.stderr


@pytest.mark.parametrize("heading", [0.3, 3.0])
def test_heading_steps_keep_position(tmp_path, heading):
    # yaw is the weakest axis: its rate is limited (yaw_rate_max) and its torque ranks with
    # the forces in the inner allocation, so a heading step must not cost the position
    scenario = tmp_path / "yaw.toml"
    scenario.write_text('duration = 10.0\nairframe = "paper_hexacopter"\n'
                        "[reference.position]\nz = -3.0\n[reference.attitude]\n"
                        f"yaw = {{ type = \"steps\", times = [1.0], values = [{heading}] }}\n")
    r = run(prepare(scenario))
    err = np.linalg.norm(r.get("plant.pos") - r.get("ref.pos_ref"), axis=1)
    assert err.max() < 0.05  # measured 1.2 cm (0.3 rad) and 4.1 cm (3 rad)
    assert r.get("plant.euler")[-1, 2] == pytest.approx(heading, abs=0.01)
