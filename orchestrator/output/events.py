"""The moments of a run worth marking on its timeline, from its recording alone: the reference
pose turning infeasible or feasible again, rotor faults, the controller's detections,
disturbance steps, reference jumps, on the ground touchdowns, liftoffs and the rotors
idling or spinning up, and a mission's items started and reached.  One source for the
figures (orchestrator/output/plots.py) and the 3-D view (orchestrator/output/view.py)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orchestrator.output.run_result import RunResult

KINDS = ("feasibility", "fault", "detection", "disturbance", "reference", "ground",
         "mission")
JUMP = 1e-3
"""m: a reference increment beyond what its velocity explains by this much is a jump (a
trajectory's own error over 2 ms is ~1e-9 m; a waypoint or a step is centimetres or more)."""
OUTSTANDING = 20.0
"""... and by this many times the median unexplained increment of the reference."""
MAX_PER_KIND = 200
"""At most this many events of one kind (a timeline of thousands of lines reads as none)."""


@dataclass(frozen=True)
class Event:
    """A moment on a run's timeline: its time (s), kind (KINDS) and text."""
    time: float
    kind: str  # one of KINDS
    text: str


def changes(x: np.ndarray) -> np.ndarray:
    """Rows where x differs from the row before (rows >= 1)."""
    x = np.asarray(x)
    diff = np.any(x[1:] != x[:-1], axis=1) if x.ndim > 1 else x[1:] != x[:-1]
    return np.nonzero(diff)[0] + 1


def events(r: RunResult, kinds: tuple[str, ...] = KINDS) -> list[Event]:
    """The run's events of ``kinds``, in time order."""
    t = np.asarray(r.time)
    n = r.n_rotors
    out: list[Event] = []
    if "feasibility" in kinds and r.has("ctrl.feasible"):
        feasible = r.get("ctrl.feasible")
        for i in changes(feasible)[:MAX_PER_KIND]:
            out.append(Event(float(t[i]), "feasibility",
                             "mu_ref feasible again" if feasible[i] > 0.5
                             else "mu_ref infeasible: flying mu_c"))
    if "fault" in kinds and r.has("dist.efficiency[1]"):
        eff = r.get("dist.efficiency")[:, :n]
        for i in changes(eff):
            what = [f"rotor {j + 1} at {eff[i, j]:.2f}" for j in range(eff.shape[1])
                    if eff[i, j] != eff[i - 1, j]]
            out.append(Event(float(t[i]), "fault", "fault: " + ", ".join(what)))
    if "detection" in kinds and r.has("ctrl.rotors_detected"):
        found = r.get("ctrl.rotors_detected")
        for i in changes(found):
            rotors = [str(j + 1) for j in range(8) if int(found[i]) >> j & 1]
            out.append(Event(float(t[i]), "detection", "detected: rotor " + ", ".join(rotors)))
    if "disturbance" in kinds:
        for name in ("dist.a_d", "dist.f_d", "dist.tau_d"):
            if r.has(f"{name}[1]"):
                for i in changes(r.get(name))[:MAX_PER_KIND]:
                    out.append(Event(float(t[i]), "disturbance",
                                     f"{name.removeprefix('dist.')} step"))
    if "reference" in kinds and r.has("ref.pos_ref[1]") and t.size > 1:
        # a jump: an increment its own velocity does not explain (the trapezoidal rule, as
        # the controller's reference shaping tells a jump from a trajectory)
        pos = r.get("ref.pos_ref")
        vel = r.get("ref.vel_ref") if r.has("ref.vel_ref[1]") else np.zeros_like(pos)
        step = np.abs(np.diff(pos, axis=0) - 0.5 * np.diff(t)[:, None] * (vel[1:] + vel[:-1]))
        # ... and stands out of the reference's own unexplained motion (a trajectory given
        # without its velocity moves millimetres every sample: no jumps)
        floor = np.maximum(JUMP, OUTSTANDING * np.median(step, axis=0))
        for i in np.nonzero(np.any(step > floor, axis=1))[0][:MAX_PER_KIND] + 1:
            out.append(Event(float(t[i]), "reference", "reference jump"))
    if "ground" in kinds:
        out += ground_events(r, t)
    if "mission" in kinds:
        out += mission_events(r)
    return sorted(out, key=lambda e: (e.time, e.kind))


def mission_events(r: RunResult) -> list[Event]:
    """A scenario mission's items (``meta["mission"]``): each leg's start and the moment it is
    reached, the mission's end and the disarm after the landing."""
    record = r.meta.get("mission")
    if not isinstance(record, dict):
        return []
    out: list[Event] = []
    for leg in record.get("legs", [])[:MAX_PER_KIND]:
        if leg.get("reached") is not None and leg.get("end") is not None and \
                leg["reached"] == leg["start"] == leg["end"]:
            continue  # a do-item: done at once, its leg's start says it
        out.append(Event(float(leg["start"]), "mission", f"item {leg['seq']} {leg['command']}"))
        if leg.get("reached") is not None:
            out.append(Event(float(leg["reached"]), "mission", f"item {leg['seq']} reached"))
    ends = [e for e in record.get("events", []) if e.get("kind") == "finished"]
    if ends:
        out.append(Event(float(ends[0]["time"]), "mission", "mission finished"))
    if record.get("disarmed") is not None:
        out.append(Event(float(record["disarmed"]), "mission", "disarmed"))
    return out


def ground_events(r: RunResult, t: np.ndarray) -> list[Event]:
    """Touchdowns and liftoffs (the plant's landing gear: any foot below the ground or none),
    the controller's land detector, and its rotors idling or spinning up again."""
    out: list[Event] = []
    if r.has("plant.contact_flags"):
        touching = r.get("plant.contact_flags") > 0
        for i in changes(touching)[:MAX_PER_KIND]:
            out.append(Event(float(t[i]), "ground", "touchdown" if touching[i] else "liftoff"))
    for name, on, off in (("ctrl.landed", "landed", "leaving the ground"),
                          ("ctrl.idle", "rotors idle", "rotors spinning up")):
        if r.has(name):
            flag = r.get(name) > 0.5
            for i in changes(flag)[:MAX_PER_KIND]:
                out.append(Event(float(t[i]), "ground", on if flag[i] else off))
    return out
