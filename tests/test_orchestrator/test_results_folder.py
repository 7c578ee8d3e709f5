"""Results folders are whole or absent; S(0) is cached by content; paper claims are only
judged for runs in the paper's conditions."""

import dataclasses
import json
import os

import numpy as np
import pytest

from controller import polytope_cache
from controller.force_sets import feasible_force_set
from controller.polytope import same_polytope
from orchestrator.runner import OutputError, paper_conditions, prepare, publish
from plant import load_airframe

# -- publish -----------------------------------------------------------------


def fill(files):
    def write(folder):
        for name, text in files.items():
            (folder / name).write_text(text)
    return write


def test_publish_replaces_the_whole_folder(tmp_path):
    out = tmp_path / "res"
    publish(out, fill({"metrics.json": "{}", "tracking.png": "old figure"}))
    publish(out, fill({"metrics.json": '{"new": 1}'}))
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json"]  # no figure of the old run
    assert json.loads((out / "metrics.json").read_text()) == {"new": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["res"]  # no temporary folder left


def test_a_failing_write_leaves_the_previous_results(tmp_path):
    out = tmp_path / "res"
    publish(out, fill({"metrics.json": "previous"}))

    def broken(folder):
        (folder / "metrics.json").write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        publish(out, broken)
    assert (out / "metrics.json").read_text() == "previous"
    assert [p.name for p in tmp_path.iterdir()] == ["res"]


def test_publish_never_replaces_a_folder_that_is_not_results(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    with pytest.raises(OutputError, match="does not hold fullpose results"):
        publish(mine, fill({"metrics.json": "{}"}))
    assert (mine / "thesis.tex").read_text() == "years of work"
    empty = tmp_path / "empty"
    empty.mkdir()
    publish(empty, fill({"metrics.json": "{}"}))  # an empty folder is fine
    assert (empty / "metrics.json").is_file()


# -- the polytope cache ----------------------------------------------------------


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FULLPOSE_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def _tilted_quad():
    """A quadrotor with rotors no shipped airframe has (no shipped sets)."""
    af = load_airframe("quadrotor")
    return dataclasses.replace(af, name="tilted", alpha_limits=np.tile([0.1, 0.1], (4, 1)))


def test_cache_computes_once_per_rotor_content(cache, monkeypatch):
    """The key is what the sets depend on: the rotors, not the name, mass or lags."""
    af = _tilted_quad()
    calls = []
    real = polytope_cache.compute_polytope

    def compute(kind, a):
        calls.append((kind, a.name))
        return real(kind, a)

    monkeypatch.setattr(polytope_cache, "compute_polytope", compute)
    monkeypatch.setattr(polytope_cache, "_MEMO", {})
    first = polytope_cache.cached_polytope("s0", af)
    assert calls == [("s0", "tilted")]
    polytope_cache._MEMO.clear()
    for same in (dataclasses.replace(af, name="another name"),
                 dataclasses.replace(af, mass=af.mass * 1.3, tau_motor=0.05,
                                     inertia=af.inertia * 1.5)):
        again = polytope_cache.cached_polytope("s0", same)  # from the disk entry
        polytope_cache._MEMO.clear()
        assert np.array_equal(again.A, first.A) and np.array_equal(again.b, first.b)
    assert len(calls) == 1
    slower = dataclasses.replace(af, omega_max=af.omega_max * 0.99)  # other rotors
    polytope_cache.cached_polytope("s0", slower)
    assert len(calls) == 2


def test_a_corrupt_entry_is_recomputed(cache, monkeypatch):
    monkeypatch.setattr(polytope_cache, "_MEMO", {})
    af = _tilted_quad()
    first = polytope_cache.cached_polytope("s0", af)
    (entry,) = cache.iterdir()
    for garbage in ('{"A": [[NaN, 0, 0]]}', "garbage"):
        entry.write_text(garbage)
        polytope_cache._MEMO.clear()
        again = polytope_cache.cached_polytope("s0", af)
        assert np.array_equal(again.b, first.b)


def test_an_unwritable_cache_only_costs_the_caching(tmp_path, monkeypatch):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv("FULLPOSE_CACHE_DIR", str(blocker / "cache"))
    monkeypatch.setattr(polytope_cache, "_MEMO", {})
    af = _tilted_quad()
    assert polytope_cache.cached_polytope("s0", af).n_facets >= 4


def test_design_sets_serve_shipped_rotors_only():
    """A shipped airframe's design-time S(0) (oracle: controller.force_sets now) and failure
    sets; the same rotors on a heavier vehicle get them too; other rotors get none (the
    controller derives them)."""
    af = load_airframe("quadrotor")
    for vehicle in (af, dataclasses.replace(af, mass=1.2, name="heavier")):
        params = polytope_cache.design_set_parameters(vehicle)
        n = int(params["poly_n"])
        A = np.array([[params[f"poly_A[{i + 1},{j + 1}]"] for j in range(3)] for i in range(n)])
        b = np.array([params[f"poly_b[{i + 1}]"] for i in range(n)])
        poly = feasible_force_set(af)
        same, why = same_polytope(A, b, poly.A, poly.b)
        assert same, why
        assert all(f"fail_poly_n[{i + 1}]" in params for i in range(af.n_rotors))
    assert polytope_cache.design_set_parameters(_tilted_quad()) == {}


@pytest.mark.heavy  # about 2 s: the heavy tier (CI runs it), room in the fast one
def test_shipped_sets_are_fresh_for_every_shipped_airframe():
    """Oracle: controller.force_sets and controller.failures now: each shipped facet's offset
    is the outer bound computed here for its normal (``python -m controller.shipped_sets
    --check``)."""
    from controller import shipped_sets

    for name in shipped_sets.list_airframes():
        af = load_airframe(name)
        assert polytope_cache.shipped(af) is not None, f"{name}: no shipped sets for its numbers"
        assert shipped_sets.check(af) == [], name


@pytest.mark.heavy  # about 2 s: the heavy tier (CI runs it), room in the fast one
def test_the_shipped_set_check_catches_a_moved_facet():
    """One facet of the shipped AFS moved out by 1 mm of force, or a set of rotors 1 %
    slower: the check names the facet; the shipped set itself passes.  Oracle for the slower
    rotors: with omega_min = 0 the set scales with thrust, (0.99)^2 = 0.9801, exactly."""
    from controller import shipped_sets
    from controller.force_sets import facet_problem

    af = load_airframe("paper_hexacopter")
    poly = polytope_cache.polytope_from_doc(polytope_cache.shipped(af)["afs"])
    assert facet_problem(af, poly.A, poly.b) is None
    moved = poly.b.copy()
    moved[7] += 1e-3
    why = facet_problem(af, poly.A, moved)
    assert why is not None and "facet 7 " in why, why
    slow = dataclasses.replace(af, omega_max=0.99 * af.omega_max)
    assert facet_problem(slow, poly.A, 0.9801 * poly.b) is None
    why = facet_problem(slow, poly.A, poly.b)
    assert why is not None and "where the forces reach" in why, why
    assert shipped_sets.check(af) == []


def test_shipped_sets_serve_only_the_shipped_numbers(cache):
    af = load_airframe("quadrotor")
    weaker = dataclasses.replace(af, omega_max=af.omega_max * 0.9)
    assert polytope_cache.shipped(weaker) is None
    _, s0 = polytope_cache.force_sets(weaker)  # computed, then kept in the cache
    assert [p.name.split("-")[1] for p in sorted(cache.iterdir())] == ["afs", "s0"]
    fresh = feasible_force_set(weaker)
    assert same_polytope(s0.A, s0.b, fresh.A, fresh.b)[0]
    assert s0.z_range[0] > polytope_cache.force_sets(af)[1].z_range[0]  # less thrust


def test_polytope_documents_round_trip_exactly():
    af = load_airframe("fixed_tilt_hexarotor")
    for poly in polytope_cache.force_sets(af):
        back = polytope_cache.polytope_from_doc(json.loads(json.dumps(
            polytope_cache.polytope_doc(poly))))
        for field in ("A", "b", "vertices", "inner_points", "torque"):
            assert np.array_equal(getattr(back, field), getattr(poly, field)), field
        assert (back.z_range, back.gap, back.kind) == (poly.z_range, poly.gap, poly.kind)
    with pytest.raises(ValueError, match="not a polytope document"):
        polytope_cache.polytope_from_doc({"A": []})


# -- paper conditions ------------------------------------------------------------


def test_paper_claims_are_judged_only_in_the_papers_conditions(tmp_path):
    assert paper_conditions(prepare("hover_varying_orientation")) is None
    assert "20 s run; the paper's is 100 s" in paper_conditions(
        prepare("hover_varying_orientation", duration=20.0))
    assert "controller.K_pos_D[1]" in paper_conditions(
        prepare("hover_varying_orientation", settings=["controller.K_pos_D[1]=3"]))
    assert paper_conditions(prepare("hover")) is None  # no claims at all
    copy = tmp_path / "hover_varying_orientation.toml"
    shipped = prepare("hover_varying_orientation").source
    copy.write_text(open(shipped).read())
    assert paper_conditions(prepare(copy)) is None  # the same file elsewhere is the same
    copy.write_text(open(shipped).read() + "\n[plant]\nnoise_pos = 0.05\n")
    assert "differs from the shipped scenario file" in paper_conditions(prepare(copy))


def test_a_failure_between_the_two_moves_restores_the_previous_results(tmp_path, monkeypatch):
    out = tmp_path / "res"
    publish(out, fill({"metrics.json": "previous"}))
    real = os.replace
    calls = []

    def second_move_fails(src, dst):
        calls.append((src, dst))
        if len(calls) == 2:  # the new folder into place: interrupted here
            raise KeyboardInterrupt
        real(src, dst)

    monkeypatch.setattr(os, "replace", second_move_fails)
    with pytest.raises(KeyboardInterrupt):
        publish(out, fill({"metrics.json": "new"}))
    monkeypatch.setattr(os, "replace", real)
    assert (out / "metrics.json").read_text() == "previous"
    assert [p.name for p in tmp_path.iterdir()] == ["res"]


# -- the lost-vehicle rule ---------------------------------------------------------


def test_first_lost_finds_the_first_sample_beyond_any_bound():
    from orchestrator.sim.outcome import LostCriteria, first_lost

    n = 10
    t = np.arange(n) * 0.002
    ref = np.zeros((n, 3))
    pos = np.zeros((n, 3))
    euler = np.zeros((n, 3))
    finite = np.ones(n, dtype=bool)
    crit = LostCriteria(position_error=1.0, tilt_deg=60.0)
    assert first_lost(t, pos, ref, euler, finite, crit) is None
    pos[7] = [0.6, 0.6, 0.6]  # |e| = 1.04 m > 1 m
    euler[5] = [np.radians(40.0), np.radians(40.0), 3.0]  # tilt 54 deg; yaw does not tilt
    assert first_lost(t, pos, ref, euler, finite, crit).row == 7
    euler[4] = [np.radians(50.0), np.radians(45.0), 0.0]  # tilt 63 deg
    lost = first_lost(t, pos, ref, euler, finite, crit)
    assert (lost.row, lost.nonfinite) == (4, False) and "tilt 63" in lost.reason
    finite[2] = False
    pos[2] = np.nan
    lost = first_lost(t, pos, ref, euler, finite, crit)
    assert lost.row == 2 and lost.nonfinite and lost.time == pytest.approx(0.004)
