"""A run in 3-D, in Rerun (``fullpose view``, ``fullpose run --view / --save``).

The vehicle is drawn where it truly was (the recorded truth when sensors differ from it), as
a body with arms and each rotor's thrust as an arrow along the rotor's tilted axis, scaled so
that the hover share of the weight spans one arm.  Beside it, as ghosts: the reference pose
(position and mu_ref) and the commanded feasible attitude mu_c at the vehicle's position.
The whole path is a trail; disturbance forces are arrows at the vehicle; feasibility changes,
rotor faults and detections, shaped reference jumps are events on the timeline; time series
panels show the position error (mm), the attitude error against mu_c (deg), rotor speeds
(commanded and measured, rpm), servo angles and the QPs' iterations.  A blueprint saved with
the recording lays these out, so the viewer opens ready to read.

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

if TYPE_CHECKING:
    from orchestrator.results import RunResult
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


def blueprint() -> Any:
    """The layout the recording opens with: the 3-D scene left, the time series right."""
    import rerun.blueprint as rrb

    series = [("position error (mm)", "series/position_error_mm"),
              ("attitude error against mu_c (deg)", "series/attitude_error_deg"),
              ("rotor speeds (rpm)", "series/omega_rpm"),
              ("servo angles (deg)", "series/servo_deg"),
              ("QP iterations", "series/qp")]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(rrb.Spatial3DView(name="vehicle", origin="world"),
                         rrb.TextLogView(name="events", origin="events"), row_shares=[4, 1]),
            rrb.Vertical(*[rrb.TimeSeriesView(name=n, origin=o) for n, o in series]),
            column_shares=[3, 2]),
        collapse_panels=True)


def replay(result: RunResult, airframe: Airframe, save: Path | None = None,
           spawn: bool = False) -> ViewReport:
    """Sends ``result`` to a Rerun recording: written to ``save`` (an .rrd file), and/or
    streamed to a viewer started here (``spawn``)."""
    rr = _rerun()
    t0 = time.perf_counter()
    rec = rr.RecordingStream(APP_ID, recording_id=str(result.meta.get("scenario", "run")))
    if spawn:
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                     or os.environ.get("WAYLAND_DISPLAY")):
            raise ViewUnavailable("no display here (DISPLAY and WAYLAND_DISPLAY unset): the "
                                  "Rerun viewer cannot open; write a recording with --save "
                                  "FILE.rrd and open it where a display is (rerun FILE.rrd)")
        try:
            rec.spawn(connect=save is None, default_blueprint=blueprint())
        except Exception as e:  # no viewer binary, no display
            raise ViewUnavailable(f"cannot start the Rerun viewer: {e}; write a recording "
                                  "with --save FILE.rrd and open it where a display is") from e
        if save is not None:  # both: the viewer and the file
            rec.set_sinks(rr.sinks.GrpcSink(), rr.sinks.FileSink(save),
                          default_blueprint=blueprint())
    elif save is not None:
        rec.save(save, default_blueprint=blueprint())
    poses, series = _send(rr, rec, result, airframe)
    rec.flush()
    rec.disconnect()
    return ViewReport(time.perf_counter() - t0, poses, series, save)


def _send(rr: Any, rec: Any, r: RunResult, af: Airframe) -> tuple[int, int]:
    t = np.asarray(r.time)
    step = max(1, round((t[1] - t[0] if t.size > 1 else 0.002) ** -1 / VIEW_HZ))
    k = np.arange(0, t.size, step)
    when = [rr.TimeColumn("time", duration=t[k])]
    pos, euler = r.get(r.judged("plant.pos"))[k], r.get(r.judged("plant.euler"))[k]
    n = af.n_rotors
    span = float(np.max(np.linalg.norm(af.positions, axis=1)))
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_DOWN, static=True)  # NED
    # the body: arms to the rotors, and its ghosts (reference pose, commanded attitude)
    arms = [[[0.0, 0.0, 0.0], list(p)] for p in af.positions]
    rec.log("world/vehicle/arms", rr.LineStrips3D(arms, radii=0.01 * span,
                                                  colors=[60, 60, 60]), static=True)
    rec.log("world/vehicle/rotors", rr.Points3D(af.positions, radii=0.2 * span / max(n, 2) ** 0.5,
                                                colors=[90, 90, 200]), static=True)
    ghost = rr.Boxes3D(half_sizes=[[span, span, 0.05 * span]], fill_mode="majorwireframe")
    for name, color in (("reference", [120, 120, 120]), ("commanded", [230, 140, 20])):
        rec.log(f"world/{name}/body", ghost, rr.Points3D([[0.0, 0.0, 0.0]], colors=[color]),
                static=True)
    rec.send_columns("world/vehicle", indexes=when, columns=rr.Transform3D.columns(
        translation=pos, quaternion=quaternion_xyzw(euler)))
    rec.send_columns("world/reference", indexes=when, columns=rr.Transform3D.columns(
        translation=r.get("ref.pos_ref")[k], quaternion=quaternion_xyzw(r.get("ref.euler_ref")[k])))
    rec.send_columns("world/commanded", indexes=when, columns=rr.Transform3D.columns(
        translation=pos, quaternion=quaternion_xyzw(r.get("ctrl.mu_c")[k])))
    # thrust: k_t omega^2 (times the rotor's efficiency) along each tilted axis
    omega, alpha, beta = (r.get(f"plant.{s}")[k][:, :n] for s in ("omega", "alpha", "beta"))
    eff = r.get("dist.efficiency")[k][:, :n] if r.has("dist.efficiency[1]") else 1.0
    thrust = af.k_t * omega ** 2 * eff
    scale = span / (af.mass * af.gravity / n)  # the hover share spans one arm
    vec = thrust_directions(alpha, beta, af.gamma[None, :]) * (thrust * scale)[..., None]
    origins = np.broadcast_to(af.positions, vec.shape)
    rec.send_columns("world/vehicle/thrust", indexes=when, columns=rr.Arrows3D.columns(
        vectors=vec.reshape(-1, 3), origins=origins.reshape(-1, 3)).partition([n] * k.size))
    # the trail, and the disturbance force at the vehicle (world frame)
    rec.log("world/trail", rr.LineStrips3D([pos], radii=0.003 * span, colors=[40, 160, 80]),
            static=True)
    f_d = r.get("dist.f_d")[k] + af.mass * r.get("dist.a_d")[k]
    if np.any(f_d != 0.0):
        rec.send_columns("world/disturbance", indexes=when, columns=rr.Arrows3D.columns(
            vectors=f_d * scale, origins=pos, colors=np.tile([200, 30, 30], (k.size, 1))))
    series = _send_series(rr, rec, r, n)
    _send_events(rr, rec, r)
    return int(k.size), series


def _send_series(rr: Any, rec: Any, r: RunResult, n: int) -> int:
    t = np.asarray(r.time)
    when = [rr.TimeColumn("time", duration=t)]
    out: dict[str, np.ndarray] = {}
    err = (r.get(r.judged("plant.pos")) - r.get("ctrl.pos_ref_s")
           if r.has("ctrl.pos_ref_s[1]") else r.get(r.judged("plant.pos")) - r.get("ref.pos_ref"))
    for i, axis in enumerate("xyz"):
        out[f"series/position_error_mm/{axis}"] = 1e3 * err[:, i]
    att = np.degrees(r.get(r.judged("plant.euler")) - r.get("ctrl.mu_c"))
    att = (att + 180.0) % 360.0 - 180.0
    for i, axis in enumerate(("roll", "pitch", "yaw")):
        out[f"series/attitude_error_deg/{axis}"] = att[:, i]
    rpm = 60.0 / (2.0 * np.pi)
    for i in range(n):
        out[f"series/omega_rpm/{i + 1}/measured"] = rpm * r.get("plant.omega")[:, i]
        out[f"series/omega_rpm/{i + 1}/commanded"] = rpm * r.get("ctrl.omega_cmd")[:, i]
        out[f"series/servo_deg/alpha_{i + 1}"] = np.degrees(r.get("plant.alpha")[:, i])
        out[f"series/servo_deg/beta_{i + 1}"] = np.degrees(r.get("plant.beta")[:, i])
    for name in ("guid_iter", "alloc_iter"):
        out[f"series/qp/{name}"] = r.get(f"ctrl.{name}")
    for path, values in out.items():
        rec.send_columns(path, indexes=when, columns=rr.Scalars.columns(scalars=values))
    return int(t.size)


def _send_events(rr: Any, rec: Any, r: RunResult) -> None:
    from orchestrator.events import events

    found = events(r, ("feasibility", "fault", "detection", "reference"))
    if not found:
        return
    level = {"fault": "WARN", "detection": "WARN"}
    text = [e.text + (": flown shaped" if e.kind == "reference" else "") for e in found]
    rec.send_columns("events", indexes=[rr.TimeColumn("time", duration=[e.time for e in found])],
                     columns=rr.TextLog.columns(text=text,
                                                level=[level.get(e.kind, "INFO") for e in found]))
