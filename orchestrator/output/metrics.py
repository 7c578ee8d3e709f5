"""Metrics of a recorded run (the JSON summary) and the paper's claims beside ours.

:func:`compute_metrics` reduces a :class:`~orchestrator.output.run_result.RunResult` to a plain
dict (str keys; float, int, str, None, lists and dicts of these; never NaN or inf), which the caller
writes as JSON.  Every sample (row) has the same weight: rows are equally spaced communication
points.  A value that cannot be computed (signal not recorded, timing not measured, wall time
unknown) is ``None``; so is a statistic whose samples are not all finite (the run diverged),
and ``nonfinite_rows`` then counts the rows with a non-finite position or attitude.

Keys (units in brackets)
------------------------
``scenario``, ``airframe``
    Names from ``result.meta`` (None when absent).
``outcome``, ``lost``
    ``"completed"``, or ``"lost"`` when the master stopped the run because the vehicle was
    lost (``orchestrator.sim.outcome``); ``lost`` is then ``{"time" [s], "reason"}``, else None.
``n_samples`` [-], ``step`` [s], ``duration`` [s]
    Rows recorded, communication step and simulated time (meta, else from ``time``); a lost
    run records up to the time it was lost.
``judged_on``
    ``"true state"`` when the run recorded the plant's true state beside the measured one
    (a run with sensor noise, sampling or latency: ``plant.pos_true``,
    ``plant.euler_true``), else ``"measured state"`` (ideal sensors: the two are the same).
    The errors below use it.
``nonfinite_rows`` [-]
    Rows where the judged position or attitude is not finite.
``errors_against``
    ``{"position": column, "attitude": column}``: the reference the errors below are
    against, the one the controller flies: its shaped reference ``ctrl.pos_ref_s``,
    ``ctrl.euler_ref_s`` (a step of the input flown within the shaping's limits; the input
    itself wherever no jump is being shaped), or, in results recorded without them, the
    reference as given, ``ref.pos_ref``, ``ref.euler_ref`` (None when neither is recorded).
    So a 1 m step is not a 1 m error; what the step did is in ``steps``.  Rows on the
    ground are not judged: with a foot of the landing gear touching (``plant.contact_flags``)
    or the rotors idle (``ctrl.idle``), the vehicle flies no reference (a landing's runs on
    below the ground).
``position_error`` [m]
    e = ``plant.pos_true`` (or ``plant.pos``) - the flown position reference
    (``errors_against["position"]``; world NED).  ``max`` and ``rms`` of the norm |e|; per
    axis ``x``, ``y``, ``z``: ``{"max": max |e_i|, "rms": sqrt(mean(e_i^2))}``.
``measured``
    With the true state recorded: ``position_error``, ``attitude_error_vs_mu_c`` and
    ``attitude_error_vs_mu_ref`` of the *measured* state (what the sensors said), reported
    as such; else None.
``attitude_error_vs_mu_c``, ``attitude_error_vs_mu_ref`` [deg]
    e = ``plant.euler_true`` (or ``plant.euler``) - ``ctrl.mu_c`` (resp. the flown attitude
    reference, ``errors_against["attitude"]``: mu_ref as shaped), each component wrapped to
    [-180, 180) deg.  Per axis ``phi``, ``theta``, ``psi``: ``{"max": max |e_i|, "rms": ...}``;
    ``max_axis``: the largest of the three per-axis maxima (how the paper reads its plots);
    overall ``max`` and ``rms`` of the norm of the wrapped Euler-error vector.
``steps``
    One dict per step of the setpoint (jumps of ``ref.pos_ref`` or ``ref.euler_ref``, e.g.
    from a scenario's ``steps`` signal), in time order, judged against the setpoint as given:
    ``kind``, ``time``, ``end``, ``jump``, ``size``, ``band``, ``settle_time`` (to within
    1 cm / 1 deg for good), ``overshoot``, ``peak_tilt``, ``sag``, ``sag_of``,
    ``acc_limit``, ``bound`` (2 sqrt(L/a_max)) and ``bound_ratio``
    (:mod:`orchestrator.output.step_metrics` defines each); an empty list without steps.
``mission_legs``
    A run of a scenario's ``[mission]``: one dict per leg flown (``seq``, ``command``,
    ``start``, ``reached``, ``end`` [s], ``flying_s``, ``position_error`` {``max``, ``rms``}
    [m] of the error norm, ``attitude_error`` {``max``, ``rms``} [deg] of the largest axis
    error, both in the air and against the flown reference); None without a mission.
``controller_on``
    A run with the controller image on the emulated Cortex-M7 (``fullpose run --pil``): the
    machine, the instructions per sample (``mean``, ``p99``, ``max``), of fpc_start, the
    deepest stack and the C library's heap and formatting calls during the samples
    (:meth:`orchestrator.pil.instance.PilController.summary`); None with the controller FMU.
``infeasible_fraction`` [-]
    Fraction of samples where the reference pose was infeasible: 1 - mean(``ctrl.feasible``).
``saturation`` [-]
    From ``ctrl.sat_flags`` (bit i-1 motor i, bit 7+i alpha i, bit 15+i beta i; only rotors
    1..``n_rotors`` count).  ``any_motor`` / ``any_alpha`` / ``any_beta`` / ``any``: fraction of
    samples with at least one such flag set; ``motor`` / ``alpha`` / ``beta``: fraction of
    actuator-samples at a limit (set bits / (n_samples * n_rotors)).
``guidance_qp``, ``allocation_qp``
    ``iter_mean`` [-] and ``iter_max`` [-] of ``ctrl.guid_iter`` / ``ctrl.alloc_iter``;
    ``status_counts``: samples per status ``optimal`` (0), ``max_iter`` (1), ``infeasible``
    (2), ``bad_input`` (3) (and ``other`` when an unknown code occurs).
``timing`` [s]
    For ``t_guid``, ``t_alloc`` and ``t_step`` (controller computation times measured inside
    the FMU): ``{"mean", "p99", "max"}`` over all samples, or None when the column is all zero
    (the run did not measure it).
``wall_time`` [s]
    Wall-clock time of the co-simulation loop (meta), or None.
``real_time_factor`` [-]
    ``duration / wall_time``: simulated seconds per wall-clock second (> 1: faster than real
    time), or None.
``master_overhead_fraction`` [-]
    ``(wall_time - fmu_time.plant - fmu_time.controller) / wall_time``: share of the wall time
    spent outside the two FMUs (the Python master), or None when fmu_time is not recorded.

:func:`compare_with_paper` states the quantitative claims of the paper's Section IV for the
paper's three scenarios next to our values.  Their references are smooth (sines, chirps), so
the flown reference is the input and the lines are those against ``ref.pos_ref`` and
``ref.euler_ref`` (positions bit for bit; a sine heading to 3e-14 rad, the rounding of the
controller's unwrapped heading; tests/test_orchestrator/test_step_metrics.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from controller.fmu_parameters import SAT_FLAG_SHIFT
from controller.wls import STATUS_NAMES
from orchestrator.output.run_result import RunResult
from orchestrator.output.step_metrics import step_metrics

"""Names of the QP status codes 0..3 (controller outputs guid_status and alloc_status)."""

POSITION_AXES = ("x", "y", "z")
EULER_AXES = ("phi", "theta", "psi")

FLOWN_REFERENCE = {"position": ("ctrl.pos_ref_s", "ref.pos_ref"),
                   "attitude": ("ctrl.euler_ref_s", "ref.euler_ref")}
"""The reference each error is against, the first recorded: the controller's shaped one
(the input wherever no jump is being shaped), else the input."""

PAPER_MAX_POSITION_ERROR = 0.02
"""m, scenario 1 (hovering with varying orientations), Sec. IV-A / Fig. 4."""
PAPER_MAX_ATTITUDE_ERROR = 0.6
"""deg, scenario 2 (translating with minimal orientation), Sec. IV-B / Fig. 7."""
PAPER_MAX_GUIDANCE_TIME = 2.5e-4
"""s, scenario 3 (full pose with disturbances), Sec. IV-C / Fig. 8 (MATLAB lsqlin, i7-12th)."""


def _num(x: float | np.floating | np.integer) -> float | None:
    """A plain float, or None when not finite (JSON has no NaN/inf)."""
    v = float(x)
    return v if math.isfinite(v) else None


def wrap_deg(angle: np.ndarray) -> np.ndarray:
    """Angles in degrees wrapped to [-180, 180)."""
    return (np.asarray(angle, dtype=float) + 180.0) % 360.0 - 180.0


def _rms(x: np.ndarray, axis: int | None = None) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=axis))


def _error_stats(err: np.ndarray, axes: tuple[str, ...]) -> dict[str, Any]:
    """max/RMS of the norm of err (n, k) and per column of its absolute values."""
    norm = np.linalg.norm(err, axis=1)
    out: dict[str, Any] = {"max": _num(float(np.max(norm))), "rms": _num(float(_rms(norm)))}
    per_max = np.max(np.abs(err), axis=0)
    per_rms = _rms(err, axis=0)
    for i, name in enumerate(axes):
        out[name] = {"max": _num(per_max[i]), "rms": _num(per_rms[i])}
    return out


def saturation_fractions(flags: np.ndarray, n_rotors: int) -> dict[str, float | None]:
    """Saturation fractions of a sat_flags column (see the module docstring)."""
    f = np.asarray(flags, dtype=float)
    if f.size == 0:
        return {k: None for k in
                ("any_motor", "any_alpha", "any_beta", "any", "motor", "alpha", "beta")}
    bits = np.rint(f).astype(np.int64)
    rotors = np.arange(n_rotors)
    anywhere: dict[str, float | None] = {}
    each: dict[str, float | None] = {}
    hit_any = np.zeros(len(bits), dtype=bool)
    for kind, shift in SAT_FLAG_SHIFT.items():  # one kind at a time: a long run's memory
        on = ((bits[:, None] >> (rotors + shift)[None, :]) & 1).astype(bool)  # (n, n_rotors)
        hit = np.any(on, axis=1)
        hit_any |= hit
        anywhere[f"any_{kind}"] = float(np.mean(hit))
        each[kind] = float(np.mean(on)) if on.size else 0.0
    return {**anywhere, "any": float(np.mean(hit_any)), **each}


def _qp_stats(result: RunResult, prefix: str) -> dict[str, Any] | None:
    iters, status = result.optional(f"ctrl.{prefix}_iter"), result.optional(f"ctrl.{prefix}_status")
    if iters is None and status is None:
        return None
    out: dict[str, Any] = {"iter_mean": None, "iter_max": None, "status_counts": None}
    if iters is not None and iters.size:
        out["iter_mean"] = _num(np.mean(iters))
        out["iter_max"] = int(np.max(iters)) if np.all(np.isfinite(iters)) else None
    if status is not None:
        codes = np.rint(status).astype(np.int64)
        counts = {name: int(np.sum(codes == k)) for k, name in enumerate(STATUS_NAMES)}
        other = int(codes.size - sum(counts.values()))
        if other:
            counts["other"] = other
        out["status_counts"] = counts
    return out


def _timing(result: RunResult) -> dict[str, dict[str, float | None] | None]:
    out: dict[str, dict[str, float | None] | None] = {}
    for name in ("t_guid", "t_alloc", "t_step"):
        t = result.optional(f"ctrl.{name}")
        if t is None or t.size == 0 or not np.any(t != 0.0):
            out[name] = None
            continue
        out[name] = {"mean": _num(np.mean(t)), "p99": _num(np.percentile(t, 99.0)),
                     "max": _num(np.max(t))}
    return out


def flown_reference(result: RunResult) -> dict[str, str | None]:
    """The columns the errors are against (``errors_against``): the position and attitude
    reference the controller flies (its shaped ``ctrl.pos_ref_s``, ``ctrl.euler_ref_s``),
    else the reference as given (``ref.pos_ref``, ``ref.euler_ref``), else None."""
    out: dict[str, str | None] = {}
    for key, names in FLOWN_REFERENCE.items():
        out[key] = next((name for name in names if result.has(name)), None)
    return out


def flying_rows(result: RunResult) -> np.ndarray:
    """The rows judged by the tracking errors: all but those on the ground, with a foot of
    the landing gear touching (``plant.contact_flags``) or the rotors idle (``ctrl.idle``)."""
    flying = np.ones(result.time.size, dtype=bool)
    for name in ("ctrl.idle", "plant.contact_flags"):
        flag = result.optional(name)
        if flag is not None:
            flying &= ~(flag > 0.5)
    return flying


def _tracking(result: RunResult, pos_name: str, euler_name: str) -> dict[str, Any]:
    """Position and attitude errors of the signals ``pos_name`` and ``euler_name``."""
    out: dict[str, Any] = {}
    flown = flown_reference(result)
    pos, euler = result.optional(pos_name), result.optional(euler_name)
    pos_ref = None if flown["position"] is None else result.get(flown["position"])
    flying = flying_rows(result)
    out["position_error"] = None
    if pos is not None and pos_ref is not None and flying.any():
        out["position_error"] = _error_stats((pos - pos_ref)[flying], POSITION_AXES)
    for key, ref_name in (("attitude_error_vs_mu_c", "ctrl.mu_c"),
                          ("attitude_error_vs_mu_ref", flown["attitude"])):
        ref = None if ref_name is None else result.optional(ref_name)
        out[key] = None
        if euler is not None and ref is not None and flying.any():
            err = wrap_deg(np.degrees(euler - ref))[flying]
            stats = _error_stats(err, EULER_AXES)
            per_axis = [stats[a]["max"] for a in EULER_AXES]
            stats["max_axis"] = None if None in per_axis else max(per_axis)
            out[key] = stats
    return out


def mission_legs(result: RunResult) -> list[dict[str, Any]] | None:
    """Per mission leg (a run of a scenario's ``[mission]``: ``meta["mission"]``), the
    tracking of the rows it was flown (start to end, in the air): its seq, command, start,
    reached and end times, and position and attitude errors against the flown reference as
    the whole run's are; None without a mission.  Do-items (no time of their own) are left
    out."""
    record = result.meta.get("mission")
    if not isinstance(record, Mapping):
        return None
    t = result.time
    flown = flown_reference(result)
    pos, euler = result.optional(result.judged("plant.pos")), result.optional(
        result.judged("plant.euler"))
    pos_ref = None if flown["position"] is None else result.optional(flown["position"])
    att_ref = None if flown["attitude"] is None else result.optional(flown["attitude"])
    flying = flying_rows(result)
    out = []
    for leg in record.get("legs", []):
        start = float(leg["start"])
        end = float(t[-1]) if leg.get("end") is None else float(leg["end"])
        if end <= start:
            continue
        rows = (t >= start - 1e-9) & (t < end - 1e-9) & flying
        entry: dict[str, Any] = {"seq": leg["seq"], "command": leg["command"],
                                 "start": _num(start), "reached": leg.get("reached"),
                                 "end": leg.get("end"), "flying_s": _num(
                                     float(rows.sum()) * float(t[1] - t[0]) if t.size > 1
                                     else 0.0),
                                 "position_error": None, "attitude_error": None}
        if rows.any() and pos is not None and pos_ref is not None:
            err = np.linalg.norm((pos - pos_ref)[rows], axis=1)
            entry["position_error"] = {"max": _num(err.max()), "rms": _num(float(_rms(err)))}
        if rows.any() and euler is not None and att_ref is not None:
            err = np.abs(wrap_deg(np.degrees(euler - att_ref)[rows])).max(axis=1)
            entry["attitude_error"] = {"max": _num(err.max()), "rms": _num(float(_rms(err)))}
        out.append(entry)
    return out


def _duration(result: RunResult) -> float | None:
    if result.meta.get("duration") is not None:
        return float(result.meta["duration"])
    t = result.time
    return float(t[-1] - t[0]) if t.size else None


def compute_metrics(result: RunResult) -> dict[str, Any]:
    """The metrics summary of a run (see the module docstring for every key and unit)."""
    meta = result.meta
    t = result.time
    step = meta.get("step")
    if step is None and t.size > 1:
        step = float(t[1] - t[0])
    duration = _duration(result)
    m: dict[str, Any] = {
        "scenario": meta.get("scenario"),
        "airframe": meta.get("airframe"),
        "outcome": "completed",
        "lost": None,
        "n_samples": int(t.size),
        "step": None if step is None else _num(step),
        "duration": None if duration is None else _num(duration),
    }

    outcome = meta.get("outcome")
    if isinstance(outcome, Mapping) and outcome.get("outcome") == "lost":
        m["outcome"] = "lost"
        m["lost"] = {"time": _num(outcome.get("time", math.nan)),
                     "reason": str(outcome.get("reason", ""))}

    truth = result.has_truth
    judged = result.judged("plant.pos"), result.judged("plant.euler")
    m["judged_on"] = "true state" if truth else "measured state"
    bad = np.zeros(t.size, dtype=bool)
    for name in judged:
        sig = result.optional(name)
        if sig is not None:
            bad |= ~np.all(np.isfinite(np.atleast_2d(sig.T).T), axis=1)
    m["nonfinite_rows"] = int(np.sum(bad))
    m["errors_against"] = flown_reference(result)
    m.update(_tracking(result, *judged))
    m["measured"] = _tracking(result, "plant.pos", "plant.euler") if truth else None
    m["steps"] = step_metrics(result, *judged)
    m["mission_legs"] = mission_legs(result)
    m["controller_on"] = meta.get("controller_on")

    feasible = result.optional("ctrl.feasible")
    m["infeasible_fraction"] = (None if feasible is None or feasible.size == 0
                                else _num(1.0 - np.mean(feasible)))

    flags = result.optional("ctrl.sat_flags")
    m["saturation"] = None if flags is None else saturation_fractions(flags, result.n_rotors)

    m["guidance_qp"] = _qp_stats(result, "guid")
    m["allocation_qp"] = _qp_stats(result, "alloc")
    m["timing"] = _timing(result)

    wall = meta.get("wall_time")
    wall = float(wall) if wall is not None else None
    m["wall_time"] = None if wall is None else _num(wall)
    m["real_time_factor"] = None
    m["master_overhead_fraction"] = None
    if wall is not None and wall > 0.0:
        if duration is not None:
            m["real_time_factor"] = _num(duration / wall)
        fmu_time = meta.get("fmu_time")
        if isinstance(fmu_time, Mapping) and "plant" in fmu_time and "controller" in fmu_time:
            inside = float(fmu_time["plant"]) + float(fmu_time["controller"])
            m["master_overhead_fraction"] = _num((wall - inside) / wall)
    return m


# ---------------------------------------------------------------------------
# The paper's claims


def _dig(metrics: Mapping[str, Any], *keys: str) -> Any:
    cur: Any = metrics
    for k in keys:
        if not isinstance(cur, Mapping) or cur.get(k) is None:
            return None
        cur = cur[k]
    return cur


def _claim(what: str, paper: str, ours: float | None, limit: float, fmt: str,
           unit: str, missing: str = "not recorded", not_comparable: str | None = None) -> str:
    if not_comparable is not None:
        shown = "" if ours is None else f"{ours:{fmt}} {unit}, "
        return f"{what}: paper {paper}; ours {shown}not comparable ({not_comparable})"
    if ours is None:
        return f"{what}: paper {paper}; ours: {missing}"
    verdict = "meets the claim" if ours <= limit else "EXCEEDS the claim"
    return f"{what}: paper {paper}; ours {ours:{fmt}} {unit} ({verdict})"


def compare_with_paper(metrics: Mapping[str, Any], scenario_name: str, *,
                       not_comparable: str | None = None) -> list[str]:
    """Lines stating the paper's claims (Section IV) next to our metrics for its scenarios.

    ``scenario_name`` is the scenario's name or file path; scenarios other than the paper's
    three (``hover_varying_orientation``, ``translation_frequency_sweep``,
    ``full_pose_with_disturbances``) give an empty list.  ``not_comparable`` says why this
    run's conditions are not the paper's (shorter, other parameters, vehicle lost): the
    claims are then stated as "not comparable" instead of met or exceeded.
    """
    name = Path(str(scenario_name)).stem
    nc = not_comparable
    lines: list[str] = []
    if name == "hover_varying_orientation":
        lines.append(_claim(
            "Scenario 1 (Fig. 4) max position error", f"<= {PAPER_MAX_POSITION_ERROR} m",
            _dig(metrics, "position_error", "max"), PAPER_MAX_POSITION_ERROR, ".4f", "m",
            not_comparable=nc))
        inf = _dig(metrics, "infeasible_fraction")
        sat_a = _dig(metrics, "saturation", "any_alpha")
        sat_b = _dig(metrics, "saturation", "any_beta")
        lines.append(
            "Scenario 1 (Figs. 4-5) mu_ref infeasible and servos at +-40 deg for "
            "20 s <= t <= 30 s (qualitative); ours: infeasible "
            + ("n/a" if inf is None else f"{100 * inf:.1f} %") + " of the time, alpha at a "
            "limit " + ("n/a" if sat_a is None else f"{100 * sat_a:.1f} %") + ", beta at a "
            "limit " + ("n/a" if sat_b is None else f"{100 * sat_b:.1f} %"))
    elif name == "translation_frequency_sweep":
        lines.append(_claim(
            "Scenario 2 (Fig. 7) max attitude error |mu_m - mu_ref| per axis",
            f"within +-{PAPER_MAX_ATTITUDE_ERROR} deg",
            _dig(metrics, "attitude_error_vs_mu_ref", "max_axis"), PAPER_MAX_ATTITUDE_ERROR,
            ".3f", "deg", not_comparable=nc))
        lines.append(_claim(
            "Scenario 2 (Fig. 7) max attitude error |mu_m - mu_c| per axis (for reference)",
            f"within +-{PAPER_MAX_ATTITUDE_ERROR} deg",
            _dig(metrics, "attitude_error_vs_mu_c", "max_axis"), PAPER_MAX_ATTITUDE_ERROR,
            ".3f", "deg", not_comparable=nc))
    elif name == "full_pose_with_disturbances":
        lines.append(_claim(
            "Scenario 3 (Fig. 8) max guidance allocation solve time",
            f"{PAPER_MAX_GUIDANCE_TIME:.1e} s (MATLAB lsqlin, Intel i7 12th gen)",
            _dig(metrics, "timing", "t_guid", "max"), PAPER_MAX_GUIDANCE_TIME, ".3e", "s",
            missing="not measured (run with the controller parameter timing = true)",
            not_comparable=nc))
        alloc = _dig(metrics, "timing", "t_alloc", "max")
        if alloc is not None:
            lines.append(f"Scenario 3 inner allocation solve time (no claim in the paper): "
                         f"ours max {alloc:.3e} s")
    return lines
