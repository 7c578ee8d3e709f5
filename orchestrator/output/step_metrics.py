"""What each step of the user's setpoint did: the ``steps`` of the metrics summary.

A step is a jump of the setpoint (``ref.pos_ref`` or ``ref.euler_ref``) between two
consecutive samples: an increment its own rate (``ref.vel_ref``, ``ref.euler_rate_ref``)
does not explain (by the trapezoidal rule, as the controller's reference shaping tells a
jump from a trajectory, ``fmu_src/controller/reference.c``, or by the rate at either end
where that explains more, as at a ramp's corners), by more than ``POSITION_JUMP`` (m) or
``ATTITUDE_JUMP`` (rad, the Euler increment wrapped to [-pi, pi)) and by
``events.OUTSTANDING`` times the median unexplained increment (as the timeline's
``reference jump`` events).  A scenario's ``steps`` signal makes them; sines, chirps,
waypoints and ramps do not (a ramp's corner between two samples leaves at most a quarter of
its slope times the step unexplained: below 1 mm up to 2 m/s).  The jumps of all three axes
at one sample form one step.

Each step is judged from its sample until the next step of the same kind (position or
attitude) or the end of the run (its *window*), on the judged state (the true one when
recorded), against the setpoint as given (the new setpoint, moving or not).

:func:`step_metrics` gives one dict per step, in time order, with the keys (units in
brackets; position steps in m, attitude steps in rad and deg):

``kind``
    ``"position"`` or ``"attitude"``.
``time`` [s], ``end`` [s]
    The step's sample and the end of its window.
``jump`` [m | rad], ``size`` [m | rad]
    The jump (world NED x, y, z; or roll, pitch, yaw, each wrapped) and its norm.
``band`` [m | deg], ``settle_time`` [s]
    ``band`` is 0.01 m (position) or 1 deg (attitude: the norm of the wrapped Euler error).
    ``settle_time``: time from the step until the state is within ``band`` of the new
    setpoint and stays there to the end of the window; None if it never does.
``overshoot`` [m | deg]
    The largest excursion past the setpoint along the step's direction, >= 0.
``peak_tilt`` [deg]
    The largest tilt in the window, arccos(cos(phi) cos(theta)) of the judged attitude.
``sag`` [m], ``sag_of``
    The largest deviation across the step, from the position reference flown
    (``ctrl.pos_ref_s``, else ``ref.pos_ref``: the setpoint, unless another step is still
    being flown there): for a horizontal step (horizontal part of the jump at least its
    vertical part) of the altitude (``"altitude"``); for a vertical step of the horizontal
    position (``"horizontal position"``); for an attitude step of the position
    (``"position"``).
``acc_limit`` [m/s^2], ``bound`` [s], ``bound_ratio`` [-]
    Position steps when the controller recorded ``ctrl.ref_acc_limit`` (the horizontal
    and vertical acceleration limits its shaping uses) at the step: those limits,
    2 sqrt(L/a_max) (the fastest rest-to-rest move over L at acceleration a_max, the larger
    of the horizontal and vertical parts), and ``settle_time / bound``.  None otherwise,
    and always for attitude steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from orchestrator.output.events import JUMP, OUTSTANDING
from orchestrator.output.run_result import RunResult

POSITION_JUMP = JUMP
"""m: a position increment its velocity leaves unexplained by more than this is a step."""
ATTITUDE_JUMP = 1e-3
"""rad: an Euler-angle increment its rate leaves unexplained by more than this is a step."""
POSITION_BAND = 0.01
"""m: a position step has settled within this distance of its new setpoint."""
ATTITUDE_BAND_DEG = 1.0
"""deg: an attitude step has settled within this (norm of the wrapped Euler error)."""
MAX_STEPS = 100
"""At most this many steps of each kind are reported (the first ones)."""


@dataclass(frozen=True)
class Window:
    """The rows one step is judged on: ``first`` (the step's sample) to ``stop`` (the next
    step's sample or the end, exclusive), and the step's jump."""

    first: int
    stop: int
    jump: np.ndarray  # (3,), m or rad


def wrap_pi(angle: np.ndarray) -> np.ndarray:
    """Angles in radians wrapped to [-pi, pi)."""
    return (np.asarray(angle, dtype=float) + math.pi) % (2.0 * math.pi) - math.pi


def tilt_deg(euler: np.ndarray) -> np.ndarray:
    """Tilt (deg) of Euler angles (n, 3): the angle between the body and world z axes."""
    c = np.cos(euler[:, 0]) * np.cos(euler[:, 1])
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def _explained_at_an_end(raw: np.ndarray, dt: float, rates: tuple[np.ndarray, ...],
                         residual: np.ndarray) -> np.ndarray:
    """The smallest of ``residual`` (the trapezoidal rule's) and the increment ``raw`` less
    either end's rate times dt (a ramp's corner on a sample: one end's rate explains it)."""
    for rate in rates:
        other = raw - dt * rate
        if np.linalg.norm(other) < np.linalg.norm(residual):
            residual = other
    return residual


def find_jumps(t: np.ndarray, value: np.ndarray, rate: np.ndarray | None, tol: float,
               angles: bool = False) -> list[tuple[int, np.ndarray]]:
    """(row, jump) of every jump of ``value`` (n, 3) with time derivative ``rate`` (zero
    when None): rows whose increment from the row before (``angles``: wrapped to
    [-pi, pi)), less what the rate explains (the trapezoidal rule, or either end's rate
    where that explains more), exceeds ``tol`` and ``OUTSTANDING`` times the median
    unexplained increment (a trajectory given without its derivative moves every sample:
    no jumps)."""
    if len(t) < 2:
        return []
    dt = np.diff(t)
    residual = np.diff(value, axis=0)
    if angles:
        residual = wrap_pi(residual)
    if rate is not None:
        residual -= 0.5 * dt[:, None] * (rate[1:] + rate[:-1])
    size = np.linalg.norm(residual, axis=1)
    finite = size[np.isfinite(size)]
    floor = max(tol, OUTSTANDING * float(np.median(finite))) if finite.size else tol
    out = []
    for k in np.nonzero(size > floor)[0]:
        jump = residual[k].copy()
        if rate is not None:
            raw = jump + 0.5 * dt[k] * (rate[k] + rate[k + 1])
            jump = _explained_at_an_end(raw, float(dt[k]), (rate[k], rate[k + 1]), jump)
        if np.linalg.norm(jump) > floor:
            out.append((int(k) + 1, jump))
    return out


def windows(jumps: list[tuple[int, np.ndarray]], n: int) -> list[Window]:
    """The window of each jump: to the next jump or the end (n rows); the first
    ``MAX_STEPS``."""
    rows = [row for row, _ in jumps] + [n]
    return [Window(row, rows[i + 1], jump) for i, (row, jump) in enumerate(jumps[:MAX_STEPS])]


def settle_time(t: np.ndarray, inside: np.ndarray) -> float | None:
    """Time from ``t[0]`` until ``inside`` holds to the end; None when it does not hold at
    the end."""
    if inside.size == 0 or not inside[-1]:
        return None
    out = np.nonzero(~inside)[0]
    return float(t[out[-1] + 1] - t[0]) if out.size else 0.0


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _overshoot(err: np.ndarray, jump: np.ndarray) -> float | None:
    """The largest excursion of err (n, 3) past zero along the jump, >= 0."""
    along = err @ (jump / np.linalg.norm(jump))
    return _num(max(0.0, float(np.max(along)))) if np.all(np.isfinite(along)) else None


def _bound(jump: np.ndarray, acc_limit: np.ndarray) -> float | None:
    """2 sqrt(L/a_max) of the jump's horizontal and vertical parts (the larger), or None
    when a needed limit is not positive."""
    parts = ((math.hypot(jump[0], jump[1]), acc_limit[0]), (abs(jump[2]), acc_limit[1]))
    times = []
    for length, acc in parts:
        if length > 0.0:
            if not (math.isfinite(acc) and acc > 0.0):
                return None
            times.append(2.0 * math.sqrt(length / acc))
    return max(times) if times else None


@dataclass(frozen=True)
class _Run:
    """The signals steps are judged on (judged state, setpoints, tilt, shaping limits)."""

    t: np.ndarray
    pos: np.ndarray | None
    pos_ref: np.ndarray | None
    pos_flown: np.ndarray | None  # ctrl.pos_ref_s, else ref.pos_ref
    euler: np.ndarray | None
    euler_ref: np.ndarray | None
    tilt: np.ndarray | None
    acc_limit: np.ndarray | None  # (n, 2) or None


def _common(run: _Run, w: Window, kind: str, band: float, dist: np.ndarray,
            err: np.ndarray) -> dict[str, Any]:
    t = run.t[w.first:w.stop]
    tilt = None if run.tilt is None else run.tilt[w.first:w.stop]
    return {"kind": kind, "time": float(t[0]),
            "end": float(run.t[w.stop]) if w.stop < len(run.t) else float(run.t[-1]),
            "jump": [float(v) for v in w.jump], "size": float(np.linalg.norm(w.jump)),
            "band": band, "settle_time": settle_time(t, dist <= band),
            "overshoot": _overshoot(err, w.jump),
            "peak_tilt": None if tilt is None else _num(float(np.max(tilt)))}


def _off_flown(run: _Run, w: Window) -> np.ndarray:
    """The position's deviation from the flown position reference in the window."""
    assert run.pos is not None and run.pos_flown is not None
    return run.pos[w.first:w.stop] - run.pos_flown[w.first:w.stop]


def _position_step(run: _Run, w: Window) -> dict[str, Any]:
    assert run.pos is not None and run.pos_ref is not None
    err = run.pos[w.first:w.stop] - run.pos_ref[w.first:w.stop]
    out = _common(run, w, "position", POSITION_BAND, np.linalg.norm(err, axis=1), err)
    off = _off_flown(run, w)
    if math.hypot(w.jump[0], w.jump[1]) >= abs(w.jump[2]):
        out["sag"], out["sag_of"] = _num(float(np.max(np.abs(off[:, 2])))), "altitude"
    else:
        out["sag"] = _num(float(np.max(np.hypot(off[:, 0], off[:, 1]))))
        out["sag_of"] = "horizontal position"
    limit = None if run.acc_limit is None else run.acc_limit[w.first]
    bound = None if limit is None else _bound(w.jump, limit)
    settle = out["settle_time"]
    out["acc_limit"] = None if limit is None else [_num(float(a)) for a in limit]
    out["bound"] = bound
    out["bound_ratio"] = None if bound is None or settle is None else settle / bound
    return out


def _attitude_step(run: _Run, w: Window) -> dict[str, Any]:
    assert run.euler is not None and run.euler_ref is not None
    err = np.degrees(wrap_pi(run.euler[w.first:w.stop] - run.euler_ref[w.first:w.stop]))
    out = _common(run, w, "attitude", ATTITUDE_BAND_DEG, np.linalg.norm(err, axis=1), err)
    out["sag"], out["sag_of"] = None, "position"
    if run.pos is not None and run.pos_flown is not None:
        out["sag"] = _num(float(np.max(np.linalg.norm(_off_flown(run, w), axis=1))))
    out.update(acc_limit=None, bound=None, bound_ratio=None)
    return out


def _signals(result: RunResult, pos_name: str, euler_name: str) -> _Run:
    euler = result.optional(euler_name)
    acc = result.optional("ctrl.ref_acc_limit")
    pos_ref = result.optional("ref.pos_ref")
    shaped = result.optional("ctrl.pos_ref_s")
    return _Run(t=result.time, pos=result.optional(pos_name), pos_ref=pos_ref,
                pos_flown=pos_ref if shaped is None else shaped, euler=euler,
                euler_ref=result.optional("ref.euler_ref"),
                tilt=None if euler is None else tilt_deg(euler),
                acc_limit=None if acc is None or acc.ndim != 2 else acc)


KINDS = (("position", "ref.pos_ref", "ref.vel_ref", POSITION_JUMP),
         ("attitude", "ref.euler_ref", "ref.euler_rate_ref", ATTITUDE_JUMP))
"""Each kind of step: its setpoint, the setpoint's rate and its jump tolerance."""


def step_metrics(result: RunResult, pos_name: str = "plant.pos",
                 euler_name: str = "plant.euler") -> list[dict[str, Any]]:
    """The steps of the run's setpoint with what each did (module docstring), judged on the
    position ``pos_name`` and attitude ``euler_name``; in time order, position steps before
    attitude steps of the same sample."""
    t = result.time
    judged = {"position": pos_name, "attitude": euler_name}
    found: list[tuple[float, int, Window]] = []
    for order, (kind, ref_name, rate_name, tol) in enumerate(KINDS):
        ref = result.optional(ref_name)
        if ref is None or not result.has(judged[kind]):
            continue
        jumps = find_jumps(t, ref, result.optional(rate_name), tol, angles=kind == "attitude")
        found += [(float(t[w.first]), order, w) for w in windows(jumps, len(t))]
    if not found:
        return []
    run = _signals(result, pos_name, euler_name)
    judge = (_position_step, _attitude_step)
    return [judge[order](run, w) for _, order, w in sorted(found, key=lambda f: f[:2])]


AXIS_NAMES = {"position": ("x", "y", "z"), "attitude": ("roll", "pitch", "yaw")}
UNITS = {"position": "m", "attitude": "rad"}


def _what(step: dict[str, Any]) -> str:
    """'x +1.000 m', or the jump vector and its size when it moves more than one axis."""
    jump, unit = step["jump"], UNITS[step["kind"]]
    moved = [i for i, v in enumerate(jump) if abs(v) >= 1e-3 * step["size"]]
    if len(moved) == 1:
        return f"{AXIS_NAMES[step['kind']][moved[0]]} {jump[moved[0]]:+.3f} {unit}"
    return f"({', '.join(f'{v:+.3f}' for v in jump)}) {unit}, {step['size']:.3f} {unit}"


def _settled(step: dict[str, Any]) -> str:
    band = "1 cm" if step["kind"] == "position" else "1 deg"
    if step["settle_time"] is None:
        return f"not within {band} for good by {step['end']:.3f} s"
    text = f"within {band} after {step['settle_time']:.3f} s"
    if step.get("bound") is not None and step.get("bound_ratio") is not None:
        text += f" ({step['bound_ratio']:.2f}x 2 sqrt(L/a_max) = {step['bound']:.3f} s)"
    return text


def _size(value: float | None, spec: str, scale: float, unit: str) -> str:
    return "n/a" if value is None else f"{scale * value:{spec}} {unit}"


def step_line(step: dict[str, Any]) -> str:
    """One line saying what a step (an entry of :func:`step_metrics`) did."""
    position = step["kind"] == "position"
    overshoot = (_size(step["overshoot"], ".1f", 1e3, "mm") if position
                 else _size(step["overshoot"], ".2f", 1.0, "deg"))
    return (f"step {_what(step)} at {step['time']:.3f} s: {_settled(step)}, overshoot "
            f"{overshoot}, peak tilt {_size(step['peak_tilt'], '.1f', 1.0, 'deg')}, sag "
            f"{_size(step['sag'], '.1f', 1e3, 'mm')} ({step['sag_of']})")
