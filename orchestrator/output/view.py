"""A run in 3-D, in Rerun (``fullpose view``, ``fullpose run --view / --save``).

The vehicle is drawn where it truly was (the recorded truth when sensors differ from it), as
a body with arms and each rotor's thrust as an arrow along the rotor's tilted axis, scaled so
that the hover share of the weight spans one arm.  Beside it, as ghosts: the reference pose
(position and mu_ref) and the commanded feasible attitude mu_c at the vehicle's position.
The whole path is a trail; disturbance forces are arrows at the vehicle; feasibility changes,
rotor faults and detections, shaped reference jumps are events on the timeline; time series
panels show the position error (mm), the attitude error against mu_c (deg), rotor speeds
(commanded and measured, rpm), servo angles and the QPs' iterations; a force space shows the
body force the guidance required and the one it commanded inside the attainable force set.
A blueprint saved with the recording lays these out, so the viewer opens ready to read.

Everything goes through Rerun's columnar API (one ``send_columns`` per entity for the whole
run), the 3-D entities decimated to :data:`VIEW_HZ`, the time series at the full 500 Hz.
``rerun-sdk`` is an optional dependency (the ``view`` extra): without it these functions
raise :class:`ViewUnavailable` naming the install command.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from orchestrator.output.metrics import wrap_deg

if TYPE_CHECKING:
    from orchestrator.output.run_result import RunResult
    from plant.airframe import Airframe

VIEW_HZ = 50.0
"""Rate of the 3-D entities (poses, thrust arrows): enough for the eye, a tenth of the data."""
APP_ID = "fullpose"
INSTALL = 'pip install "fullpose[view]"'


class ViewUnavailable(RuntimeError):
    """Rerun is not installed, or its viewer cannot be started here."""


@dataclass
class ViewReport:
    """What a replay wrote: seconds spent, rows per entity kind, the file (if saved)."""

    seconds: float
    pose_rows: int
    series_rows: int
    path: Path | None


def _rerun() -> Any:
    try:
        import rerun as rr
    except ImportError as e:
        raise ViewUnavailable(f"the 3-D view needs Rerun: {INSTALL}") from e
    return rr


def check_viewer(display: bool = True) -> None:
    """Refuses, before any work, a view that cannot be made here: Rerun missing, or (with
    ``display``: a viewer to open) Linux without a display."""
    _rerun()
    if display and sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        raise ViewUnavailable("no display here (DISPLAY and WAYLAND_DISPLAY unset): the "
                              "Rerun viewer cannot open; write a recording with --save "
                              "FILE.rrd and open it where a display is (rerun FILE.rrd)")


def arm_span(af: Airframe) -> float:
    """The farthest rotor's distance from the centre (m): the scale of the drawings."""
    return float(np.max(np.linalg.norm(af.positions, axis=1)))


def quaternion_xyzw(euler: np.ndarray) -> np.ndarray:
    """ZYX Euler angles [phi, theta, psi] (N, 3) as unit quaternions [x, y, z, w]."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("ZYX", np.asarray(euler)[:, ::-1]).as_quat()


def thrust_directions(alpha: np.ndarray, beta: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """Unit thrust directions in the body frame, -R_Mi^B e_z with R = Rz(gamma) Rx(alpha)
    Ry(beta): (N, n) angles -> (N, n, 3)."""
    sa, ca, sb, cb = np.sin(alpha), np.cos(alpha), np.sin(beta), np.cos(beta)
    sg, cg = np.sin(gamma), np.cos(gamma)
    w0, w1, w2 = sb, -sa * cb, ca * cb  # Rx(alpha) Ry(beta) e_z
    return -np.stack([cg * w0 - sg * w1, sg * w0 + cg * w1, w2], axis=-1)


def blueprint(center: Any = (0.0, 0.0, -3.0), span: float = 0.3) -> Any:
    """The layout the recording opens with: the 3-D scene left, the time series right.  The
    camera follows the vehicle, from behind and above its start ``center`` (NED: up is -z),
    a dozen arm spans ``span`` away."""
    import rerun.blueprint as rrb

    c = np.asarray(center, float)
    eye = rrb.EyeControls3D(position=(c + span * np.array([-8.0, -8.0, -5.0])).tolist(),
                            look_target=c.tolist(), eye_up=[0.0, 0.0, -1.0],
                            tracking_entity="world/vehicle")

    series = [("position error (mm)", "series/position_error_mm"),
              ("attitude error against mu_c (deg)", "series/attitude_error_deg"),
              ("rotor speeds (rpm)", "series/omega_rpm"),
              ("servo angles (deg)", "series/servo_deg"),
              ("QP iterations", "series/qp")]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(rrb.Spatial3DView(name="vehicle", origin="world", eye_controls=eye),
                         rrb.Horizontal(
                             rrb.Spatial3DView(name="body force in the attainable set (N)",
                                               origin="force"),
                             rrb.TextLogView(name="events", origin="events")),
                         row_shares=[3, 2]),
            rrb.Vertical(*[rrb.TimeSeriesView(name=n, origin=o) for n, o in series]),
            column_shares=[3, 2]),
        collapse_panels=True)


def replay(result: RunResult, airframe: Airframe, save: Path | None = None,
           spawn: bool = False) -> ViewReport:
    """Sends ``result`` to a Rerun recording: written to ``save`` (an .rrd file), and/or
    streamed to a viewer started here (``spawn``)."""
    rr = _rerun()
    t0 = time.perf_counter()
    first = result.get(result.judged("plant.pos"))[0]
    span = arm_span(airframe)
    rec = _open(rr, str(result.meta.get("scenario", "run")), save, spawn,
                blueprint(first, span))
    poses, series = _send(rr, rec, result, airframe)
    rec.flush()
    rec.disconnect()
    return ViewReport(time.perf_counter() - t0, poses, series, save)


def _open(rr: Any, recording_id: str, save: Path | None, spawn: bool, layout: Any) -> Any:
    """A recording stream to a viewer started here (``spawn``) and/or to ``save``, opening
    with ``layout``."""
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
    if spawn:
        check_viewer()
        try:
            rec.spawn(connect=save is None, default_blueprint=layout)
        except Exception as e:  # no viewer binary, no display
            raise ViewUnavailable(f"cannot start the Rerun viewer: {e}; write a recording "
                                  "with --save FILE.rrd and open it where a display is") from e
        if save is not None:  # both: the viewer and the file
            rec.set_sinks(rr.sinks.GrpcSink(), rr.sinks.FileSink(save),
                          default_blueprint=layout)
    elif save is not None:
        rec.save(save, default_blueprint=layout)
    return rec


def _scene(rr: Any, rec: Any, af: Airframe) -> float:
    """The static parts: NED world, the body's arms and rotors, the ghosts' outlines.
    Returns the arm span (m)."""
    n = af.n_rotors
    span = arm_span(af)
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_DOWN, static=True)  # NED
    arms = [[[0.0, 0.0, 0.0], list(p)] for p in af.positions]
    rec.log("world/vehicle/arms", rr.LineStrips3D(arms, radii=0.01 * span,
                                                  colors=[60, 60, 60]), static=True)
    rec.log("world/vehicle/rotors", rr.Points3D(af.positions, radii=0.2 * span / max(n, 2) ** 0.5,
                                                colors=[90, 90, 200]), static=True)
    ghost = rr.Boxes3D(half_sizes=[[span, span, 0.05 * span]], fill_mode="majorwireframe")
    for name, color in (("reference", [120, 120, 120]), ("commanded", [230, 140, 20])):
        rec.log(f"world/{name}/body", ghost, rr.Points3D([[0.0, 0.0, 0.0]], colors=[color]),
                static=True)
    return span


def thrust_vectors(af: Airframe, omega: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
                   efficiency: np.ndarray | float = 1.0) -> np.ndarray:
    """Each rotor's thrust k_t omega^2 (times its efficiency) along its tilted axis, drawn so
    that the hover share of the weight spans one arm: (N, n) -> (N, n, 3)."""
    span = arm_span(af)
    scale = span / (af.mass * af.gravity / af.n_rotors)
    thrust = af.k_t * omega ** 2 * efficiency
    return thrust_directions(alpha, beta, af.gamma[None, :]) * (thrust * scale)[..., None]


def _send(rr: Any, rec: Any, r: RunResult, af: Airframe) -> tuple[int, int]:
    t = np.asarray(r.time)
    step = max(1, round((t[1] - t[0] if t.size > 1 else 0.002) ** -1 / VIEW_HZ))
    k = np.arange(0, t.size, step)
    when = [rr.TimeColumn("time", duration=t[k])]
    pos, euler = r.get(r.judged("plant.pos"))[k], r.get(r.judged("plant.euler"))[k]
    n = af.n_rotors
    span = _scene(rr, rec, af)
    omega, alpha, beta = (r.get(f"plant.{s}")[k][:, :n] for s in ("omega", "alpha", "beta"))
    eff = r.get("dist.efficiency")[k][:, :n] if r.has("dist.efficiency[1]") else 1.0
    _send_poses(rr, rec, af, when, pos, euler, r.get("ref.pos_ref")[k],
                r.get("ref.euler_ref")[k], r.get("ctrl.mu_c")[k], omega, alpha, beta, eff)
    scale = span / (af.mass * af.gravity / n)
    # the trail, and the disturbance force at the vehicle (world frame)
    rec.log("world/trail", rr.LineStrips3D([pos], radii=0.003 * span, colors=[40, 160, 80]),
            static=True)
    f_d = r.get("dist.f_d")[k] + af.mass * r.get("dist.a_d")[k]
    if np.any(f_d != 0.0):
        rec.send_columns("world/disturbance", indexes=when, columns=rr.Arrows3D.columns(
            vectors=f_d * scale, origins=pos, colors=np.tile([200, 30, 30], (k.size, 1))))
    _send_forces(rr, rec, r, af, k, when)
    series = _send_series(rr, rec, r, n)
    _send_events(rr, rec, r)
    return int(k.size), series


def _send_poses(rr: Any, rec: Any, af: Airframe, when: list[Any], pos: np.ndarray,
                euler: np.ndarray, pos_ref: np.ndarray, euler_ref: np.ndarray, mu_c: np.ndarray,
                omega: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
                efficiency: np.ndarray | float = 1.0) -> None:
    """The moving 3-D parts at the instants ``when``: the vehicle, its ghosts (the reference
    pose, mu_c at the vehicle) and each rotor's thrust (k_t omega^2 times its efficiency
    along its tilted axis)."""
    for path, p, e in (("world/vehicle", pos, euler), ("world/reference", pos_ref, euler_ref),
                       ("world/commanded", pos, mu_c)):
        rec.send_columns(path, indexes=when, columns=rr.Transform3D.columns(
            translation=p, quaternion=quaternion_xyzw(e)))
    vec = thrust_vectors(af, omega, alpha, beta, efficiency)
    origins = np.broadcast_to(af.positions, vec.shape)
    rec.send_columns("world/vehicle/thrust", indexes=when, columns=rr.Arrows3D.columns(
        vectors=vec.reshape(-1, 3), origins=origins.reshape(-1, 3)).partition(
            [af.n_rotors] * pos.shape[0]))


def _send_forces(rr: Any, rec: Any, r: RunResult, af: Airframe, k: np.ndarray,
                 when: list[Any]) -> None:
    """The force space (body FRD, N): the attainable force set as a translucent hull, the
    force the guidance required (f_b_ref) and the one it commanded (f_b_c) as arrows."""
    from scipy.spatial import ConvexHull, QhullError

    from controller.polytope_cache import force_sets

    afs, _ = force_sets(af)
    rec.log("force", rr.ViewCoordinates.RIGHT_HAND_Z_DOWN, static=True)
    try:
        hull = ConvexHull(afs.vertices)
        rec.log("force/attainable_set", rr.Mesh3D(
            vertex_positions=afs.vertices, triangle_indices=hull.simplices,
            albedo_factor=[80, 180, 80, 70]), static=True)
    except QhullError:  # a flat set (a quadrotor's is a segment): its vertices
        rec.log("force/attainable_set", rr.Points3D(afs.vertices, colors=[80, 180, 80]),
                static=True)
    origin = np.zeros((k.size, 3))
    for name, sig, color in (("required", "ctrl.f_b_ref", [120, 120, 120]),
                             ("commanded", "ctrl.f_b_c", [230, 140, 20])):
        if r.has(f"{sig}[1]"):
            rec.send_columns(f"force/{name}", indexes=when, columns=rr.Arrows3D.columns(
                vectors=r.get(sig)[k], origins=origin,
                colors=np.tile(color, (k.size, 1))))


def series_block(rr: Any, rec: Any, path: str, when: list[Any], values: np.ndarray,
                 names: list[str] | None) -> None:
    """Several series of one panel as one entity: a row of scalars per instant (one chunk
    per call, not one per series); ``names`` (for the legend) are sent when given."""
    values = np.asarray(values, float).reshape(values.shape[0], -1)
    if names is not None:
        rec.log(path, rr.SeriesLines(names=names), static=True)
    rec.send_columns(path, indexes=when, columns=rr.Scalars.columns(
        scalars=values.reshape(-1)).partition([values.shape[1]] * values.shape[0]))


def _send_panels(rr: Any, rec: Any, when: list[Any], pos_error: np.ndarray,
                 euler: np.ndarray, mu_c: np.ndarray, omega: np.ndarray,
                 omega_cmd: np.ndarray, iterations: np.ndarray, named: bool = True) -> None:
    """The time-series panels a replay and a live view share: position error (mm), attitude
    error against mu_c (deg), rotor speeds measured and commanded (rpm), QP iterations;
    ``named``: send the legends' names too (once per recording)."""
    rotors = [str(i + 1) for i in range(omega.shape[1])]
    rpm = 60.0 / (2.0 * np.pi)
    for path, values, names in (
            ("series/position_error_mm", 1e3 * pos_error, ["x", "y", "z"]),
            ("series/attitude_error_deg", wrap_deg(np.degrees(euler - mu_c)),
             ["roll", "pitch", "yaw"]),
            ("series/omega_rpm/measured", rpm * omega, [f"{i} measured" for i in rotors]),
            ("series/omega_rpm/commanded", rpm * omega_cmd, [f"{i} commanded" for i in rotors]),
            ("series/qp", iterations, ["guidance iterations", "allocation iterations"])):
        series_block(rr, rec, path, when, values, names if named else None)


def _send_series(rr: Any, rec: Any, r: RunResult, n: int) -> int:
    t = np.asarray(r.time)
    when = [rr.TimeColumn("time", duration=t)]
    pos = r.get(r.judged("plant.pos"))
    ref = r.get("ctrl.pos_ref_s") if r.has("ctrl.pos_ref_s[1]") else r.get("ref.pos_ref")
    _send_panels(rr, rec, when, pos - ref, r.get(r.judged("plant.euler")), r.get("ctrl.mu_c"),
                 r.get("plant.omega")[:, :n], r.get("ctrl.omega_cmd")[:, :n],
                 np.column_stack([r.get("ctrl.guid_iter"), r.get("ctrl.alloc_iter")]))
    for servo in ("alpha", "beta"):
        series_block(rr, rec, f"series/servo_deg/{servo}", when,
                     np.degrees(r.get(f"plant.{servo}")[:, :n]),
                     [f"{servo}_{i + 1}" for i in range(n)])
    return int(t.size)


def _send_events(rr: Any, rec: Any, r: RunResult) -> None:
    from orchestrator.output.events import events

    found = events(r, ("feasibility", "fault", "detection", "reference", "ground",
                       "mission"))
    if not found:
        return
    # one row per instant (a timeline holds one value per entity and time): events at the
    # same time share it
    rows: dict[float, tuple[list[str], str]] = {}
    for e in found:
        texts = rows.setdefault(e.time, ([], "INFO"))[0]
        texts.append(e.text + (": flown shaped" if e.kind == "reference" else ""))
        if e.kind in ("fault", "detection"):
            rows[e.time] = (texts, "WARN")
    times = sorted(rows)
    rec.send_columns("events", indexes=[rr.TimeColumn("time", duration=times)],
                     columns=rr.TextLog.columns(text=["; ".join(rows[t][0]) for t in times],
                                                level=[rows[t][1] for t in times]))


LIVE_HZ = 25.0
"""Rate of a live view: what a ground station's display shows, at a fifth of the CPU of
fly's own work (measured: docs/orchestrator.md)."""
LIVE_BATCH = 25
"""Moments a live view gathers before sending them as columns (1 s at 25 Hz): one call per
entity per batch instead of one per moment."""


class LiveView:
    """A live session in the 3-D view (``fullpose fly --view / --save``): call :meth:`log`
    after each chunk the session advanced.  Every 1 / :data:`LIVE_HZ` of simulated time it
    keeps the vehicle's pose, the ghosts, the thrust and the series' values, and sends them
    as columns every :data:`LIVE_BATCH` moments (the view trails the flight by a second);
    mode, arming and setpoint-stream changes are events, sent at once."""

    def __init__(self, airframe: Airframe, save: Path | None = None, spawn: bool = False,
                 recording_id: str = "fly", start: Any = (0.0, 0.0, -3.0)) -> None:
        self.rr = _rerun()
        self.af = airframe
        span = arm_span(airframe)
        self.rec = _open(self.rr, recording_id, save, spawn, blueprint(start, span))
        _scene(self.rr, self.rec, airframe)
        self.next_t = 0.0
        self.logged = 0
        self.seconds = 0.0  # spent logging and sending
        self._last: dict[str, Any] = {}
        self._rows: list[np.ndarray] = []
        self._named = False  # the series' names sent (static, once)

    def log(self, t: float, state: dict[str, dict[str, np.ndarray]], pos_ref: np.ndarray,
            euler_ref: np.ndarray, status: dict[str, Any] | None = None) -> None:
        """One moment of a live flight: its outputs (``LiveSession.state()``), its reference
        and the ground-station facts (``status``: mode, armed, setpoints) for events."""
        if t + 1e-9 < self.next_t:
            return
        t0 = time.perf_counter()
        self.next_t = t + 1.0 / LIVE_HZ
        n = self.af.n_rotors
        plant, ctrl = state["plant"], state["ctrl"]
        self._rows.append(np.concatenate([
            [t], plant.get("pos_true", plant["pos"]), plant.get("euler_true", plant["euler"]),
            pos_ref, euler_ref, ctrl["mu_c"], ctrl.get("pos_ref_s", pos_ref),
            plant["omega"][:n], plant["alpha"][:n], plant["beta"][:n], ctrl["omega_cmd"][:n],
            ctrl["guid_iter"][:1], ctrl["alloc_iter"][:1]]))
        changed = []
        for key, value in (status or {}).items():
            if key in self._last and self._last[key] != value:
                changed.append(f"{key}: {value}")
            self._last[key] = value
        if changed:  # one row per instant: a timeline holds one value per entity and time
            self.rec.set_time("time", duration=t)
            self.rec.log("events", self.rr.TextLog(
                "; ".join(changed),
                level="WARN" if any(c.endswith("stale") for c in changed) else "INFO"))
        self.logged += 1
        if len(self._rows) >= LIVE_BATCH:
            self._flush()
        self.seconds += time.perf_counter() - t0

    def _flush(self) -> None:
        if not self._rows:
            return
        rr, rec, af, n = self.rr, self.rec, self.af, self.af.n_rotors
        a = np.array(self._rows)
        self._rows = []
        t, pos, euler, pos_ref, euler_ref, mu_c, pos_s = (
            a[:, 0], a[:, 1:4], a[:, 4:7], a[:, 7:10], a[:, 10:13], a[:, 13:16], a[:, 16:19])
        omega, alpha, beta, omega_cmd = (a[:, 19 + i * n:19 + (i + 1) * n] for i in range(4))
        iters = a[:, 19 + 4 * n:]
        when = [rr.TimeColumn("time", duration=t)]
        _send_poses(rr, rec, af, when, pos, euler, pos_ref, euler_ref, mu_c, omega, alpha, beta)
        _send_panels(rr, rec, when, pos - pos_s, euler, mu_c, omega, omega_cmd, iters,
                     named=not self._named)
        self._named = True

    def close(self) -> None:
        """Close the recording (and the file, with save)."""
        t0 = time.perf_counter()
        self._flush()
        self.rec.flush()
        self.rec.disconnect()
        self.seconds += time.perf_counter() - t0
