"""The Monte-Carlo campaign: reproducible with 1 and 2 processes and on a Dask cluster, and
bit-identical whether each worker reuses its FMU instances (fmi2Reset between cases) or loads
fresh ones per case; report files exist; the CLI runs it."""

from __future__ import annotations

import multiprocessing
import os
import threading

import numpy as np
import pytest

import plant
from orchestrator import sweep, sweep_report
from orchestrator.cli import main

N, DURATION = 3, 3.0   # 3 cases x 2 designs = 6 runs of 3 s


@pytest.fixture(scope="module")
def serial():
    return sweep.run_sweep(N, seed=7, duration=DURATION, workers=1, progress=False)


def exact(rows):
    """The rows without their wall times, every metric as computed (not rounded)."""
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]


def test_sampling_is_seeded():
    assert sweep.sample_cases(5, 3) == sweep.sample_cases(5, 3)
    assert sweep.sample_cases(5, 3) != sweep.sample_cases(5, 4)
    for c in sweep.sample_cases(50, 1):
        assert 0.7 <= c["mass_scale"] <= 1.3 and 0.5 <= c["ixx_scale"] <= 1.5
        assert 0.7 <= c["tau_motor_scale"] <= 1.3 and 0.5 <= c["dist_amp"] <= 3.0


def test_torque_steps_and_delay_keep_the_other_draws():
    """A campaign with body-torque steps and the one-sample delay flies the same plants and
    acceleration steps as without (the torque has a generator of its own); each case's torque
    step is within its bounds and reaches the plant, and the delay is the Jacobi coupling."""
    plain, more = sweep.sample_cases(20, 5), sweep.sample_cases(20, 5, torque=0.3, delay=True)
    extra = ("torque_amp", "torque_x", "torque_y", "torque_z", "delay")
    for a, b in zip(plain, more, strict=True):
        assert {k: v for k, v in a.items() if k not in extra} == \
            {k: v for k, v in b.items() if k not in extra}
        assert a["torque_amp"] == 0.0 and a["delay"] == 0
        assert 0.06 <= b["torque_amp"] <= 0.3 and b["delay"] == 1
        assert abs(b["torque_x"] ** 2 + b["torque_y"] ** 2 + b["torque_z"] ** 2 - 1) < 1e-12
    from orchestrator.runner import prepare

    hover = prepare("hover", DURATION)
    params = sweep.designs()["hinf"]
    sc = sweep.perturbed(hover, more[0], "hinf", params, DURATION)
    assert sc.coupling == "jacobi"
    tau = sc.disturbances([0.5, 1.5, 2.5])["tau_d"]
    expected = [more[0]["torque_amp"] * more[0][k] for k in ("torque_x", "torque_y", "torque_z")]
    assert tau[0].tolist() == [0.0, 0.0, 0.0] and tau[2].tolist() == [0.0, 0.0, 0.0]
    assert tau[1] == pytest.approx(expected, rel=1e-12)
    assert sweep.perturbed(hover, plain[0], "hinf", params, DURATION).coupling == "gauss-seidel"
    rows = sweep.run_sweep(2, seed=5, duration=DURATION, progress=False, torque=0.3, delay=True)
    base = sweep.run_sweep(2, seed=5, duration=DURATION, progress=False)
    assert all(r["stable"] for r in rows)
    assert [r["max_err"] for r in rows] != [r["max_err"] for r in base]


def test_two_processes_give_the_same_table(serial):
    par = sweep.run_sweep(N, seed=7, duration=DURATION, workers=2, progress=False)
    assert sweep_report.table_rows(par) == sweep_report.table_rows(serial)
    assert exact(par) == exact(serial)
    assert len(serial) == 2 * N and all(r["stable"] for r in serial)


def test_reused_fmus_give_the_table_of_fresh_fmus_per_case(serial):
    """The oracle of the reused path: every case on freshly loaded FMUs (reuse=False)."""
    fresh = sweep.run_sweep(N, seed=7, duration=DURATION, workers=1, progress=False,
                            reuse=False)
    assert exact(fresh) == exact(serial)
    par = sweep.run_sweep(N, seed=7, duration=DURATION, workers=2, progress=False,
                          reuse=False)
    assert exact(par) == exact(serial)


def test_a_worker_instantiates_once_and_survives_lost_and_refused_cases(monkeypatch):
    """One worker flies a normal case, a lost one (a 300 m/s^2 disturbance), one the plant
    refuses to initialize (a negative motor time constant), then normal ones: each row is
    the row of that case on fresh FMUs, and the FMUs were instantiated once."""
    made = []
    instantiate = sweep._instantiate
    monkeypatch.setattr(sweep, "_instantiate", lambda: made.append(1) or instantiate())
    params = sweep.designs()
    c0, c1, c2 = sweep.sample_cases(3, 9)
    cases = [(c0, "hinf"), ({**c1, "dist_amp": 300.0}, "baseline"),
             ({**c1, "tau_motor_scale": -1.0}, "hinf"), (c2, "prototype_matched"),
             (c0, "hinf")]
    with sweep.Worker() as w:
        reused = [sweep.run_case(c, d, params[d], sweep.Campaign(duration=DURATION), w)
                  for c, d in cases]
    fresh = [sweep.run_case(c, d, params[d], sweep.Campaign(duration=DURATION))
             for c, d in cases]
    assert exact(reused) == exact(fresh)
    assert [r["stable"] for r in fresh] == [1, 0, 0, 1, 1]
    assert made == [1]


@pytest.mark.skipif(multiprocessing.get_start_method() != "fork",
                    reason="counts instantiations through a patch the pool's children inherit")
def test_pool_workers_adopt_the_parents_fmus(monkeypatch, tmp_path, serial):
    """The parent instantiates the FMUs once, before the pool forks; the workers fly on
    their copies (no unzip, no library load of their own) and give the serial table."""
    log = tmp_path / "pids"
    log.write_text("")
    instantiate = sweep._instantiate

    def counted():
        with log.open("a") as f:
            f.write(f"{os.getpid()}\n")
        return instantiate()

    monkeypatch.setattr(sweep, "_instantiate", counted)
    monkeypatch.setattr(sweep, "_LOCAL", threading.local())
    rows = sweep.run_sweep(N, seed=7, duration=DURATION, workers=2, progress=False)
    assert exact(rows) == exact(serial)
    assert log.read_text().split() == [str(os.getpid())]
    sweep.process_worker().close()


def test_a_tiny_sweep_runs_in_process(monkeypatch):
    """One case (two runs) on two workers: no pool is started for it."""
    monkeypatch.setattr(sweep, "_on_pool", lambda *a: pytest.fail("a pool for two runs"))
    rows = sweep.run_sweep(1, seed=1, duration=2.0, workers=2, progress=False)
    assert len(rows) == 2


@pytest.mark.parametrize("config", ["default", "sweep.DASK_CONFIG"])
def test_dask_local_cluster_gives_the_same_table(serial, config):
    distributed = pytest.importorskip("dask.distributed")
    import dask

    with dask.config.set(sweep.DASK_CONFIG if config != "default" else {}), \
            distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                     dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        rows = sweep.run_sweep(N, seed=7, duration=DURATION, dask=client, progress=False)
    assert sweep_report.table_rows(rows) == sweep_report.table_rows(serial)
    assert exact(rows) == exact(serial)


def test_outputs_and_cli(tmp_path, capsys):
    assert main(["sweep", "--cases", "1", "--duration", "2", "--out", str(tmp_path)]) == 0
    for name in ("sweep.csv", "report.md", "sweep_errors.png", "sweep_worst.png"):
        assert (tmp_path / name).stat().st_size > 0
    out = capsys.readouterr().out
    assert "runs/s" in out and "per worker" in out and "x real time" in out
    assert main(["sweep", "--cases", "0"]) == 2
    assert "fullpose: error:" in capsys.readouterr().err
    assert main(["sweep", "--cases", "1", "--noise", "-1"]) == 2
    assert "--noise" in capsys.readouterr().err


def test_noise_factor_keeps_the_other_draws():
    noisy, quiet = sweep.sample_cases(20, 5), sweep.sample_cases(20, 5, noise=0.0)
    for a, b in zip(noisy, quiet, strict=True):
        assert b["noise_scale"] == 0.0 and a["noise_scale"] > 0.0
        assert {k: v for k, v in a.items() if k != "noise_scale"} == \
            {k: v for k, v in b.items() if k != "noise_scale"}


def test_sensitivity_finds_the_parameter_that_drives_the_error():
    cases = sweep.sample_cases(200, 11)
    rows = [{**c, "design": "x", "stable": 1,
             "max_err": 0.01 * c["dist_amp"] * c["mass_scale"] ** 2, "rms_err": 0.0,
             "recovery_time": 0.0} for c in cases]
    sens = sweep_report.sensitivity(rows)["x"]
    assert sens["mass_scale"]["corr"] > 0.99
    assert sens["mass_scale"]["high"] / sens["mass_scale"]["low"] > 1.5
    for key in ("ixx_scale", "tau_motor_scale", "noise_scale"):
        assert abs(sens[key]["corr"]) < 0.25
    text = sweep_report.report_markdown(sweep_report.summarize(rows), {"n": 200}, {"x": sens})
    assert "| mass_scale | +" in text


def test_matched_design_tells_the_controller_the_true_plant(tmp_path, capsys):
    """hinf_matched flies the same cases with the controller given the perturbed mass and
    inertia; the heaviest sampled vehicle then errs less than with nominal values (INDI
    under-corrects when it believes the vehicle lighter than it is)."""
    cases = sweep.sample_cases(40, 0)
    heavy = max(cases, key=lambda c: c["mass_scale"])
    assert heavy["mass_scale"] > 1.2
    params = sweep.designs()
    nominal = sweep.run_case(heavy, "hinf", params["hinf"], sweep.Campaign(duration=3.0))
    matched = sweep.run_case(heavy, "hinf_matched", params["hinf_matched"],
                             sweep.Campaign(duration=3.0))
    assert nominal["stable"] and matched["stable"]
    assert matched["max_err"] < 0.9 * nominal["max_err"]
    with pytest.raises(ValueError, match="unknown design"):
        sweep.run_sweep(1, design_set=("hinf_typo",))
    assert main(["sweep", "--cases", "1", "--designs", "nope", "--out", str(tmp_path)]) == 2
    assert "unknown design" in capsys.readouterr().err


def test_a_sweep_perturbs_the_airframe_of_any_scenario_and_vehicle(tmp_path):
    """The X8 on a user's scenario file: every case's plant flies a perturbed copy of the X8
    (mass, principal inertias, time constants scaled by the case's factors), the controller
    keeps the nominal X8 (or is told the true mass and inertia: _matched), and the cases
    hold the hover under the disturbance steps (stable, error well under a metre)."""
    scenario = tmp_path / "hold.toml"
    scenario.write_text('duration = 3.0\nairframe = "paper_hexacopter"\n'
                        "[reference.position]\nz = -2.0\n")
    campaign = sweep.Campaign(str(scenario), "x8_coaxial", DURATION)
    base = campaign.base()
    x8 = plant.load_airframe("x8_coaxial")
    (case,) = sweep.sample_cases(1, 4)
    for design in ("hinf", "hinf_matched"):
        sc = sweep.perturbed(base, case, design, sweep.designs()[design], DURATION)
        truth = sc.true_airframe
        assert truth.mass == pytest.approx(x8.mass * case["mass_scale"], rel=1e-15)
        assert np.allclose(np.diag(truth.inertia), np.diag(x8.inertia) * [
            case["ixx_scale"], case["iyy_scale"], case["izz_scale"]], rtol=1e-15)
        assert truth.tau_motor == pytest.approx(x8.tau_motor * case["tau_motor_scale"])
        assert np.array_equal(truth.positions, x8.positions)
        told = sc.airframe.mass
        assert told == (truth.mass if design.endswith("_matched") else x8.mass)
    rows = sweep.run_sweep(3, seed=4, duration=DURATION, scenario=scenario,
                           airframe="x8_coaxial", design_set=("hinf",), progress=False)
    assert [r["stable"] for r in rows] == [1, 1, 1]
    assert max(r["max_err"] for r in rows) < 0.5
