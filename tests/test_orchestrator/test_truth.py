"""With sensor noise, a run records the plant's true state beside the measured one, and the
metrics and figures judge the truth (the measured errors reported as such)."""

from __future__ import annotations

import numpy as np
import pytest

from orchestrator import master
from orchestrator.output.metrics import compute_metrics
from orchestrator.output.plots import tracking_figure
from orchestrator.scenario.catalogue import load_scenario
from orchestrator.scenario.parser import with_overrides

NOISE = ["plant.noise_pos=0.005", "plant.noise_vel=0.01", "plant.noise_att=0.003",
         "plant.noise_seed=4"]
TRUE = ("pos_true", "vel_true", "euler_true", "quat_true", "rate_true")


@pytest.fixture(scope="module")
def runs():
    sc = with_overrides(load_scenario("hover_varying_orientation"), duration=12.0)
    return master.run(sc), master.run(with_overrides(sc, settings=NOISE))


def _max_norm(a: np.ndarray) -> float:
    return float(np.linalg.norm(a, axis=1).max())


def test_the_truth_is_recorded_only_with_noise(runs):
    clean, noisy = runs
    assert not any(c.split("[")[0].removeprefix("plant.") in TRUE for c in clean.columns)
    assert all(noisy.has(f"plant.{name}") for name in TRUE)
    assert len(noisy.columns) == len(clean.columns) + 16  # 3 + 3 + 3 + 4 + 3


def test_metrics_judge_the_true_state(runs):
    """Oracle: the errors recomputed here from the recorded columns."""
    clean, noisy = runs
    m = compute_metrics(noisy)
    assert m["judged_on"] == "true state"
    ref = noisy.get("ref.pos_ref")
    true_err = _max_norm(noisy.get("plant.pos_true") - ref)
    sensed_err = _max_norm(noisy.get("plant.pos") - ref)
    assert m["position_error"]["max"] == pytest.approx(true_err, rel=1e-12)
    assert m["measured"]["position_error"]["max"] == pytest.approx(sensed_err, rel=1e-12)
    assert sensed_err > true_err  # 5 mm of noise on a ~1 cm error
    # the vehicle flies the same whether or not the clean run's sensors were noisy: its
    # true error stays the clean run's within the noise's effect on the loop (<< the noise)
    mc = compute_metrics(clean)
    assert mc["judged_on"] == "measured state" and mc["measured"] is None
    assert abs(m["position_error"]["max"] - mc["position_error"]["max"]) < 0.005


def test_the_tracking_figure_draws_the_truth_over_the_faint_measurement(runs):
    _, noisy = runs
    fig = tracking_figure(noisy)
    ax = fig.axes[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    assert {"true", "measured (sensors)", "reference"} <= set(lines)
    assert lines["measured (sensors)"].get_alpha() < 0.5 and lines["true"].get_alpha() is None
    assert "pos_true" in fig.axes[6].get_ylabel()


def test_latency_alone_records_the_truth_and_the_lag_shows_in_it():
    """No noise, a 10 ms pose latency: the measured pose lags the true one by the speed
    times the latency (S2's reference moves at ~0.1 m/s at first: ~1 mm), and the truth is
    what the metrics judge."""
    sc = with_overrides(load_scenario("translation_frequency_sweep"),
                        duration=20.0, settings=["plant.mocap_delay=0.01"])
    r = master.run(sc)
    m = compute_metrics(r)
    assert m["judged_on"] == "true state"
    lag = np.linalg.norm(r.get("plant.pos") - r.get("plant.pos_true"), axis=1)
    speed = np.linalg.norm(r.get("plant.vel_true"), axis=1)
    k = len(lag) // 2
    assert lag[k:].max() == pytest.approx(0.01 * speed[k:].max(), rel=0.1)


MOCAP_120 = ["plant.mocap_period=0.008333333333333333", "plant.mocap_delay=0.005"]


def test_the_controller_predicts_a_late_pose_to_now():
    """Motion capture at 120 Hz, 5 ms late, while translating: a controller that took the
    pose as current would trail the reference by the speed times the pose's age (5 to
    13.3 ms); predicting with pose_age keeps the true error at the ideal sensors' level
    (1.0 mm here; the paper's bound is 2 cm)."""
    sc = with_overrides(load_scenario("translation_frequency_sweep"), duration=40.0)
    ideal = compute_metrics(master.run(sc))
    r = master.run(with_overrides(sc, settings=MOCAP_120))
    m = compute_metrics(r)
    age = r.get("plant.pose_age")
    # 5 ms, plus up to one 8.3 ms sample period as seen at 2 ms communication points
    assert age.min() == pytest.approx(0.005)
    assert 0.005 + 1 / 120 - 0.002 <= age.max() <= 0.005 + 1 / 120
    speed = float(np.linalg.norm(r.get("plant.vel_true"), axis=1).max())
    lag = speed * float(age.mean())  # what taking the pose as current would cost
    assert m["measured"]["position_error"]["max"] > 0.5 * lag  # the sensors are that late
    assert m["position_error"]["max"] < 0.25 * lag
    assert m["position_error"]["max"] < ideal["position_error"]["max"] + 0.001
