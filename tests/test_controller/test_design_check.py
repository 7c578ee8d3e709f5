"""`fullpose design`: whether the gains are certified for an airframe, a synthesis for one
where they are not, gains files, and the one warning runs print outside the certified set.

Oracles: the shipped synthesis' own record (controller/default_gains.json: the gammas the
synthesis certified on the design airframe's model set); the exact H-infinity norms of
controller.lti (tested against independent methods in tests/test_controller/test_hinf.py); the
definition
of the certified set (the design airframe's actuator lag x [0.7, 1.3])."""

from __future__ import annotations

import json

import pytest
from helpers import cli
from helpers.airframe_kinds import write_kind

import plant
from controller import design_check
from controller.gains_defaults import CACHE

SHIPPED_GAMMA = json.loads(CACHE.read_text())["report"]




@pytest.mark.parametrize("name", plant.list_airframes())
def test_the_shipped_gains_hold_for_every_shipped_airframe(name):
    """Every shipped airframe has the design airframe's actuators: the check reproduces the
    synthesis' certified gammas (the INDI loops are normalized by each vehicle's own mass
    and inertia, so the mass does not enter)."""
    result = design_check.check(plant.load_airframe(name))
    assert result.certified
    for loop in result.loops:
        assert loop.gamma == pytest.approx(SHIPPED_GAMMA[loop.cascade]["gamma"], rel=1e-9)
    assert design_check.lag_warning(plant.load_airframe(name)) is None


def test_the_certified_lags_are_the_design_lag_times_0_7_to_1_3():
    tau = plant.load_airframe("paper_hexacopter").tau_motor
    assert design_check.certified_lags() == (pytest.approx(0.7 * tau), pytest.approx(1.3 * tau))


def test_a_slow_servo_vehicle_is_outside_and_not_certified(tmp_path):
    af = plant.load_airframe(write_kind("heavy_tilting_hexacopter", tmp_path))
    assert design_check.actuator_lag(af) == af.tau_servo == 0.04  # the servos are slower
    result = design_check.check(af)
    assert not result.certified
    assert {lp.cascade for lp in result.loops if lp.gamma > 1.0} == {"translation", "rotation"}
    warning = design_check.lag_warning(af)
    assert warning is not None and "40 ms" in warning and "fullpose design" in warning


def test_runs_warn_once_outside_and_not_with_gains_for_the_vehicle(tmp_path):
    frame = write_kind("heavy_tilting_hexacopter", tmp_path)
    af = plant.load_airframe(frame)
    res = cli("check", "hover", "--airframe", str(frame))
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("fullpose: warning:") == 1 and "40 ms" in res.stderr
    # gains synthesized at this lag (here: the shipped blocks relabelled, enough for the
    # warning's logic; the synthesis itself is tested below) silence it
    gains = design_check.GainsFile("", af.name, 0.04, design_check.shipped_blocks(), {})
    path = design_check.write_gains(tmp_path / "g.json", gains)
    res = cli("check", "hover", "--airframe", str(frame), "--gains", str(path))
    assert res.returncode == 0, res.stderr
    assert "warning" not in res.stderr
    res = cli("check", "hover", "--gains", str(path))  # the paper hexacopter, 18.5 ms
    assert "outside the 28-52 ms the gains of" in res.stderr


def test_gains_files_round_trip_and_refuse_what_they_are_not(tmp_path):
    blocks = design_check.shipped_blocks()
    path = design_check.write_gains(tmp_path / "g.json", design_check.GainsFile(
        "", "x", 0.02, blocks, {"translation": 0.9}))
    back = design_check.read_gains(path)
    assert back.blocks == blocks and back.lag == 0.02
    params = back.controller_parameters()
    assert params["K_pos_A[3]"] == blocks["pos"][0]
    doc = json.loads(path.read_text())
    bad = {"missing.json": {**doc, "blocks": {"pos": blocks["pos"]}},
           "unstable.json": {**doc, "blocks": {**doc["blocks"], "att": [1.5, 1, 1, 1]}},
           "nolag.json": {**doc, "actuator_lag": -1}}
    for name, content in bad.items():
        (tmp_path / name).write_text(json.dumps(content))
        with pytest.raises(design_check.GainsFileError, match=name):
            design_check.read_gains(tmp_path / name)
    (tmp_path / "junk.json").write_text("{")
    res = cli("run", "hover", "--gains", str(tmp_path / "junk.json"), "--out",
              str(tmp_path / "out"))
    assert res.returncode == 2 and "junk.json" in res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "out").exists()


@pytest.mark.heavy  # about 2 s: the heavy tier (CI runs it), room in the fast one
def test_design_command_checks_without_synthesis(tmp_path):
    res = cli("design", "y6")
    assert res.returncode == 0, res.stderr
    assert "the gains hold for this airframe" in res.stdout and "synthesis" not in res.stdout
    frame = write_kind("heavy_tilting_hexacopter", tmp_path)
    res = cli("design", str(frame), "--no-synthesis", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "NOT certified" in res.stdout and not list(tmp_path.glob("*.gains.json"))


@pytest.mark.slow
def test_a_synthesis_certifies_gains_for_the_slow_vehicle(tmp_path):
    """About 20 s: the synthesis for a 40 ms lag (performance scaled to the actuators)
    reaches gamma <= 1 on its own model set, and its file flies the vehicle."""
    frame = write_kind("heavy_tilting_hexacopter", tmp_path)
    res = cli("design", str(frame), "--out", str(tmp_path / "heavy.json"))
    assert res.returncode == 0, res.stderr
    gains = design_check.read_gains(tmp_path / "heavy.json")
    result = design_check.check(plant.load_airframe(frame), gains)
    assert result.certified and all(g <= 1.0 for g in gains.gamma.values())
    res = cli("run", "position_step", "--airframe", str(frame), "--gains",
              str(tmp_path / "heavy.json"), "--no-plots", "--out", str(tmp_path / "r"))
    assert res.returncode == 0 and "warning" not in res.stderr, res.stderr


@pytest.mark.heavy  # about 2 s: the heavy tier (CI runs it), room in the fast one
def test_fly_warns_once_outside_and_takes_gains(tmp_path):
    frame = write_kind("heavy_tilting_hexacopter", tmp_path)
    base = ["fly", "--airframe", str(frame), "--speed", "max", "--duration", "0.2", "--gcs",
            "udpout:127.0.0.1:9"]
    res = cli(*base)
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("fullpose: warning:") == 1 and "40 ms" in res.stderr
    assert "flying heavy_tilting_hexacopter" in res.stdout
    gains = design_check.GainsFile("", "heavy", 0.04, design_check.shipped_blocks(), {})
    path = design_check.write_gains(tmp_path / "g.json", gains)
    res = cli(*base, "--gains", str(path))
    assert res.returncode == 0, res.stderr
    assert "warning" not in res.stderr
