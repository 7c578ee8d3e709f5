"""One FMU pair for every multirotor class, and surviving a rotor failure."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import plant
from controller.failures import airframe_without, failure_polytopes, hover_possible
from orchestrator.master import run
from orchestrator.output.metrics import compute_metrics
from orchestrator.runner import prepare

ROOT = Path(__file__).resolve().parents[2]
H = 0.002


def pos_error(result):
    return np.linalg.norm(result.get("plant.pos") - result.get("ref.pos_ref"), axis=1)


# -- airframe classes -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "bound"),
    # bounds: about 1.5x the measured maxima (quadrotor 1.5 cm, fixed tilt 3 mm, hexacopter
    # 1 mm), i.e. centimetre-level tracking with margin for platform round-off
    [("quadrotor_translation", 0.025), ("fixed_tilt_translation", 0.006)],
)
def test_translation_with_each_airframe(name, bound):
    result = run(prepare(name))
    assert np.isfinite(result.data).all()
    assert pos_error(result).max() < bound


def test_quadrotor_tilts_and_fixed_tilt_uses_lateral_force_first():
    quad = run(prepare("quadrotor_translation"))
    fixed = run(prepare("fixed_tilt_translation"))
    # the quadrotor has no lateral force: its commanded attitude departs from mu_ref = 0
    assert np.degrees(np.abs(quad.get("ctrl.mu_c")[:, :2]).max()) > 3.0
    assert np.abs(quad.get("ctrl.f_b_c")[:, :2]).max() < 1e-6
    # the fixed-tilt hexarotor uses its bounded lateral force and keeps its attitude
    assert np.degrees(np.abs(fixed.get("ctrl.mu_c")[:, :2]).max()) < 0.01
    assert np.abs(fixed.get("ctrl.f_b_c")[:, :2]).max() > 0.1


@pytest.mark.parametrize("name", ["quadrotor_hover_attitude", "fixed_tilt_hover_attitude"])
def test_hover_with_a_demanded_attitude(name):
    result = run(prepare(name))
    m = compute_metrics(result)
    assert m["position_error"]["max"] < 0.025  # measured: 1.6 cm (quadrotor), 1.3 cm
    assert m["infeasible_fraction"] > 0.3  # the demanded attitudes are (partly) infeasible
    assert m["attitude_error_vs_mu_c"]["max"] < 4.0  # deg: mu_m follows mu_c


# -- rotor failures ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def hexa_failures():
    return failure_polytopes(plant.load_airframe("paper_hexacopter"))


def test_single_failure_sets(hexa_failures):
    hexa = plant.load_airframe("paper_hexacopter")
    assert all(hover_possible(p, hexa) for p in hexa_failures)  # any one rotor can be lost
    reduced = airframe_without(hexa, [0])
    assert reduced.n_rotors == 5 and np.allclose(reduced.positions, hexa.positions[1:])
    quad = plant.load_airframe("quadrotor")
    assert not any(hover_possible(p, quad) for p in failure_polytopes(quad))


def test_rotor_failure_while_hovering_recovers():
    result = run(prepare("rotor_failure_hover"))
    err = pos_error(result)
    t = result.time
    k_fault = round(2.0 / H)
    peak = err[k_fault:].max()
    assert peak < 0.02  # measured 1.3 cm
    settled = np.flatnonzero(err[k_fault:] > 0.005)
    recovery = t[k_fault + settled[-1]] - 2.0 if settled.size else 0.0
    assert recovery < 3.0  # back within 5 mm
    after = slice(k_fault + 1, None)
    assert np.all(result.get("ctrl.rotors_lost")[after] == 1)
    assert np.all(result.get("ctrl.active_polytope")[after] == 1)
    assert np.all(result.get("ctrl.hover_possible")[after] == 1)
    assert np.all(result.get("ctrl.omega_cmd")[after, 0] == 0.0)  # the dead motor is stopped
    assert np.abs(result.get("ctrl.alloc_residual")[-1]).max() < 1e-6


def test_reconfiguration_beats_none():
    told = pos_error(run(prepare("rotor_failure_hover"))).max()
    result = run(prepare("rotor_failure_no_reconfiguration"))
    untold = pos_error(result).max()
    assert np.isfinite(result.data).all()
    assert np.all(result.get("ctrl.rotors_lost") == 0)
    assert untold > 2 * told  # measured 3.8 cm vs 1.3 cm


def test_losing_two_rotors_of_a_quadrotor_is_reported(tmp_path):
    scenario = tmp_path / "quad2.toml"
    scenario.write_text(
        'duration = 3.0\nairframe = "quadrotor"\n[reference.position]\nz = -3.0\n'
        "[[fault]]\ntime = 1.0\nrotor = 1\nefficiency = 0.0\n"
        "[[fault]]\ntime = 1.0\nrotor = 2\nefficiency = 0.0\n")
    result = run(prepare(scenario))
    k = round(1.0 / H)
    assert np.isfinite(result.data).all()  # it falls, but nothing is NaN
    assert result.get("ctrl.hover_possible")[k - 1] == 1
    assert np.all(result.get("ctrl.hover_possible")[k + 1:] == 0)
    assert np.all(result.get("ctrl.rotors_lost")[k + 1:] == 2)
    assert np.all(result.get("ctrl.active_polytope")[k + 1:] == -1)
    assert any("2 rotors lost" in w for w in result.meta["first_warnings"])
    assert result.get("plant.pos")[-1, 2] > -3.0 + 1.0  # fell more than a metre (NED)


def test_rotor_health_input_is_validated():
    from orchestrator.sim.live import LiveSession

    with LiveSession(chunk=1) as live:
        with pytest.raises(ValueError):
            live.set_reference(rotor_health=[1.0] * 7)
        live.set_reference(rotor_health=[1.0, 1.5, 1, 1, 1, 1, 1, 1])  # out of [0, 1]
        live.advance()
        assert any("rotor_health[2]" in m for _, _, m in live.ctrl_inst.messages)
        assert all(math.isfinite(v) for v in live.state()["ctrl"]["omega_cmd"])
