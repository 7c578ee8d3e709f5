"""The 3-D replay (orchestrator/output/view.py) read back through Rerun's own dataframe API (a
local catalog server over the written .rrd), checked against the results file it came from.

Oracles: the results (Parquet) the run wrote; scipy's rotations for the quaternions; the
plant's C thrust direction (plant.effectiveness) for the rotors' axes; the scenario's fault
time and the controller's detection in the results for the timeline events."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

rr = pytest.importorskip("rerun", reason="the view extra: pip install '.[view]'")

from helpers import cli  # noqa: E402

from orchestrator.output.run_result import RunResult  # noqa: E402
from orchestrator.output.view import LIVE_HZ, VIEW_HZ, quaternion_xyzw, thrust_directions  # noqa: E402
from plant.airframe import load_airframe  # noqa: E402
from plant.effectiveness import thrust_direction  # noqa: E402

SCENARIO, DURATION = "rotor_failure_detected", 4.0




def read_rrd(path: Path):
    """The recording as one pandas frame on the "time" index."""
    with rr.server.Server(datasets={"run": [str(path)]}) as server:
        ds = server.client().get_dataset("run")
        columns = [line.split(": ", 1)[1] for line in str(ds.schema()).splitlines()
                   if line.startswith("Column name")]
        return columns, ds.reader(index="time").to_pandas()


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    out = tmp_path_factory.mktemp("view")
    rrd = out / "run.rrd"
    res = cli("run", SCENARIO, "--duration", str(DURATION), "--no-plots", "--out",
              str(out / "results"), "--save", str(rrd))
    assert res.returncode == 0, res.stderr
    assert "3-D view:" in res.stdout and rrd.is_file()
    result = RunResult.read(out / "results")
    columns, frame = read_rrd(rrd)
    return out, result, columns, frame


def _rows(frame, column):
    return frame[column].dropna()


def test_entities_and_row_counts(flown):
    _, result, columns, frame = flown
    for c in ("/world/vehicle:Transform3D:translation", "/world/vehicle:Transform3D:quaternion",
              "/world/vehicle/thrust:Arrows3D:vectors", "/world/reference:Transform3D:translation",
              "/world/commanded:Transform3D:quaternion", "/world/trail:LineStrips3D:strips",
              "/world/vehicle/arms:LineStrips3D:strips", "/events:TextLog:text",
              "/series/position_error_mm:Scalars:scalars",
              "/series/attitude_error_deg:Scalars:scalars",
              "/series/omega_rpm/commanded:Scalars:scalars", "/series/qp:Scalars:scalars"):
        assert c in columns, c
    n = result.data.shape[0]
    step = round(500.0 / VIEW_HZ)
    assert len(_rows(frame, "/world/vehicle:Transform3D:translation")) == len(range(0, n, step))
    assert len(_rows(frame, "/series/position_error_mm:Scalars:scalars")) == n
    n_rotors = result.n_rotors
    arrows = _rows(frame, "/world/vehicle/thrust:Arrows3D:vectors")
    assert all(len(a) == n_rotors for a in arrows)


def test_values_match_the_results_file(flown):
    _, result, _, frame = flown
    af = load_airframe(result.meta["airframe"])
    step = round(500.0 / VIEW_HZ)
    k = np.arange(0, result.data.shape[0], step)
    pose = frame.dropna(subset=["/world/vehicle:Transform3D:translation"])
    t = pose["time"].dt.total_seconds().to_numpy()
    np.testing.assert_allclose(t, result.time[k], atol=1e-9)
    pos = np.stack([v[0] for v in pose["/world/vehicle:Transform3D:translation"]])
    np.testing.assert_allclose(pos, result.get("plant.pos")[k], rtol=1e-6, atol=1e-6)
    quat = np.stack([v[0] for v in pose["/world/vehicle:Transform3D:quaternion"]])
    from scipy.spatial.transform import Rotation

    want = Rotation.from_euler("ZYX", result.get("plant.euler")[k][:, ::-1])
    got = Rotation.from_quat(quat)
    assert np.degrees((got.inv() * want).magnitude()).max() < 1e-3
    # thrust arrows: k_t omega^2 times the efficiency, the hover share spanning one arm
    span = float(np.max(np.linalg.norm(af.positions, axis=1)))
    scale = span / (af.mass * af.gravity / af.n_rotors)
    vec = np.stack([np.stack(v) for v in pose["/world/vehicle/thrust:Arrows3D:vectors"]])
    omega = result.get("plant.omega")[k][:, :af.n_rotors]
    eff = result.get("dist.efficiency")[k][:, :af.n_rotors]
    # (the file keeps 16 significant bits of omega: 2 * 2**-16 relative in omega**2)
    np.testing.assert_allclose(np.linalg.norm(vec, axis=2), af.k_t * omega ** 2 * eff * scale,
                               rtol=2 * 2.0**-16 + 1e-6, atol=1e-6)
    # the force space: the attainable set's hull, the commanded body force as an arrow
    from controller.polytope_cache import force_sets

    hull = frame["/force/attainable_set:Mesh3D:vertex_positions"].dropna().iloc[0]
    np.testing.assert_allclose(np.stack(hull), force_sets(af)[0].vertices, rtol=1e-6)
    cmd = np.stack([v[0] for v in pose["/force/commanded:Arrows3D:vectors"]])
    np.testing.assert_allclose(cmd, result.get("ctrl.f_b_c")[k], rtol=2.0**-16 + 1e-6,
                               atol=1e-6)  # (16 significant bits of a force in the file)
    # the position error series in mm against the shaped reference, at every row
    err = frame.dropna(subset=["/series/position_error_mm:Scalars:scalars"])
    z = np.array([v[2] for v in err["/series/position_error_mm:Scalars:scalars"]])  # x, y, z
    # (the results file holds float32: 0.24 um of resolution at 3 m in each operand)
    np.testing.assert_allclose(z, 1e3 * (result.get("plant.pos")[:, 2]
                                         - result.get("ctrl.pos_ref_s")[:, 2]), atol=1e-3)


def test_fault_and_detection_on_the_timeline(flown):
    _, result, _, frame = flown
    ev = frame.dropna(subset=["/events:TextLog:text"])
    text = [v[0] for v in ev["/events:TextLog:text"]]
    t = ev["time"].dt.total_seconds().to_numpy()
    fault = [ti for ti, s in zip(t, text, strict=True) if s.startswith("fault: rotor 1")]
    found = [ti for ti, s in zip(t, text, strict=True) if s.startswith("detected:")]
    assert fault == [pytest.approx(2.0, abs=1e-9)]  # the scenario's [[fault]] time
    k = np.nonzero(result.get("ctrl.rotors_detected"))[0][0]
    assert found == [pytest.approx(result.time[k], abs=1e-9)]


def test_view_replays_a_results_folder_without_simulating(flown, tmp_path):
    out, _, columns, frame = flown
    rrd = tmp_path / "again.rrd"
    res = cli("view", str(out / "results"), "--save", str(rrd))
    assert res.returncode == 0, res.stderr
    again_columns, again = read_rrd(rrd)
    assert again_columns == columns
    col = "/world/vehicle:Transform3D:translation"
    a = np.stack([v[0] for v in _rows(frame, col)])
    b = np.stack([v[0] for v in _rows(again, col)])
    np.testing.assert_array_equal(a, b)  # the Parquet file's float32 is the view's float32


def test_view_of_a_missing_folder_is_a_clear_error(tmp_path):
    res = cli("view", str(tmp_path / "nothing"), "--save", str(tmp_path / "x.rrd"))
    assert res.returncode == 2
    assert res.stderr.startswith("fullpose: error:") and "nothing" in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "x.rrd").exists()


def test_quaternions_and_thrust_directions_against_independent_code():
    rng = np.random.default_rng(3)
    euler = rng.uniform(-1.2, 1.2, (50, 3))
    from scipy.spatial.transform import Rotation

    q = quaternion_xyzw(euler)
    r = Rotation.from_quat(q).as_matrix()
    cphi, sphi = np.cos(euler[:, 0]), np.sin(euler[:, 0])
    cth, sth = np.cos(euler[:, 1]), np.sin(euler[:, 1])
    # third row of the ZYX body-to-world matrix: [-sin theta, sin phi cos theta, ...]
    np.testing.assert_allclose(r[:, 2], np.stack([-sth, sphi * cth, cphi * cth], 1), atol=1e-12)
    a, b, g = (rng.uniform(-1.0, 1.0, 20) for _ in range(3))
    got = thrust_directions(a, b, g)
    want = np.stack([thrust_direction(*x) for x in zip(a, b, g, strict=True)])
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_fly_writes_a_live_view_of_the_flight(tmp_path):
    """``fullpose fly --save``: a hover streamed as it flies, read back through Rerun."""
    rrd = tmp_path / "fly.rrd"
    res = subprocess.run([sys.executable, "-m", "orchestrator.cli", "fly", "--start", "air",
                          "--speed", "max",
                          "--duration", "3", "--gcs", "udpout:127.0.0.1:9", "--save", str(rrd)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "3-D view" in res.stdout
    _, frame = read_rrd(rrd)
    pose = frame.dropna(subset=["/world/vehicle:Transform3D:translation"])
    t = pose["time"].dt.total_seconds().to_numpy()
    assert len(t) == pytest.approx(3.0 * LIVE_HZ, abs=1) and np.all(np.diff(t) > 0)
    pos = np.stack([v[0] for v in pose["/world/vehicle:Transform3D:translation"]])
    np.testing.assert_allclose(pos, np.tile([0.0, 0.0, -3.0], (len(t), 1)), atol=1e-6)  # hover
    arrows = _rows(frame, "/world/vehicle/thrust:Arrows3D:vectors")
    assert len(arrows) == len(t) and all(len(a) == 6 for a in arrows)
    # the hover share of the weight spans one arm: every arrow's length is the arm's
    af = load_airframe("paper_hexacopter")
    span = float(np.max(np.linalg.norm(af.positions, axis=1)))
    lengths = np.linalg.norm(np.stack([np.stack(a) for a in arrows]), axis=2)
    np.testing.assert_allclose(lengths, span, rtol=1e-3)
    omega = _rows(frame, "/series/omega_rpm/measured:Scalars:scalars")
    assert len(omega) == len(t) and all(len(v) == 6 for v in omega)


def test_live_view_marks_mode_and_setpoint_changes(tmp_path):
    from orchestrator.output.view import LiveView
    from orchestrator.sim.live import LiveSession

    af = load_airframe("paper_hexacopter")
    rrd = tmp_path / "live.rrd"
    with LiveSession(af) as s:
        view = LiveView(af, rrd)
        for k in range(60):  # chunks of 10 ms; the view logs every 40 ms (25 Hz)
            s.advance()
            mode = "OFFBOARD" if k >= 20 else "HOLD"
            view.log(s.time, s.state(), np.array([0.0, 0.0, -3.0]), np.zeros(3),
                     {"mode": mode, "setpoints": "streaming" if 20 <= k < 40 else "stale"})
        view.close()
    _, frame = read_rrd(rrd)
    ev = frame.dropna(subset=["/events:TextLog:text"])
    got = [(round(float(t), 3), v[0]) for t, v in zip(ev["time"].dt.total_seconds(),
                                                       ev["/events:TextLog:text"], strict=True)]
    # logged moments at 0.01 s and every 40 ms after: the changes (after the 21st and 41st
    # chunk) fall on moments 0.21 s and 0.41 s
    assert got == [(0.21, "mode: OFFBOARD; setpoints: streaming"), (0.41, "setpoints: stale")]


def test_run_with_a_view_that_cannot_open_refuses_before_running(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    res = cli("run", "hover", "--duration", "0.2", "--no-plots", "--view", "--out",
              str(tmp_path / "r"))
    assert res.returncode == 2 and "no display here" in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "r").exists()  # nothing ran, nothing written
