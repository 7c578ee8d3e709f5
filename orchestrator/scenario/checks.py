"""The checks a scenario passes before anything runs: FMU parameter overrides against the
installed FMUs' modelDescriptions (types, integers within their declared or 32-bit range),
the timing (step, duration, the FMUs' own steps), signals that stay finite, and the
plausibility of units (docs/scenarios.md, "Plausibility checks").  Every failure is a
:class:`~orchestrator.scenario.reader.ScenarioError` naming the file and the field."""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Mapping
from dataclasses import replace
from functools import cache

import numpy as np

from controller import controller_fmu
from orchestrator.scenario.model import ATTITUDE_AXES, POSITION_AXES, ParamValue, Scenario
from orchestrator.scenario.reader import ScenarioError
from orchestrator.scenario.signals import (
    Chirp,
    Constant,
    Ramp,
    Scaled,
    Signal,
    Sine,
    Steps,
    Sum,
    Waypoints,
    value_range,
)
from orchestrator.sim.fmu import installed_fmu
from plant.common.model_description import fmu_variables, start_value

STEP_QUANTUM = start_value(controller_fmu(), "Ts")
"""Communication steps are positive integer multiples of this (the controller's Ts), s."""
_REL_TOL = 1e-9


# ---------------------------------------------------------------------------
# FMU parameters


FMI_INTEGER = (-2**31, 2**31 - 1)
"""An FMI 2.0 Integer is a C int: 32 bits (fmi2Integer)."""


@cache
def _fmu_variables(model: str) -> dict[str, tuple[str, str]]:
    """name -> (causality, type) of an installed FMU's model variables."""
    return {name: (v.causality, v.type) for name, v in fmu_variables(installed_fmu(model)).items()}


@cache
def _integer_range(model: str, name: str) -> tuple[int, int, bool]:
    """(min, max, declared) of an Integer variable: its modelDescription's range within
    the FMI Integer's, or the FMI Integer's when it declares none."""
    v = fmu_variables(installed_fmu(model))[name]
    lo, hi = FMI_INTEGER
    declared = False
    for bound, which in ((v.min, 0), (v.max, 1)):
        if bound is None:
            continue
        declared = True
        if which == 0:
            lo = max(lo, int(bound))
        else:
            hi = min(hi, int(bound))
    return lo, hi, declared


_INDEX = re.compile(r"\[(\d+)(?:,(\d+))?\]$")


def parameter_values(model: str, name: str, raw: object, source: str,
                     field_name: str) -> dict[str, ParamValue]:
    """Validated start values {scalar FMU name: value} for one override entry."""
    variables = _fmu_variables(model)
    if name in variables:
        return {name: _scalar(model, name, variables[name], raw, source, field_name)}
    elements = [n for n in variables if n.startswith(name + "[") and _INDEX.search(n)]
    if not elements:
        bases = sorted({re.sub(r"\[.*$", "", n) for n in variables
                        if variables[n][0] == "parameter"})
        close = difflib.get_close_matches(name, bases + list(variables), n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise ScenarioError(source, field_name,
                            f"the {model} FMU has no variable '{name}'{hint}; expected the "
                            "name of one of its parameters")
    first = variables[elements[0]]
    if first[0] != "parameter":
        raise _not_parameter(model, name, first[0], source, field_name)
    shape = [0, 0]
    for n in elements:
        m = _INDEX.search(n)
        assert m is not None
        shape[0] = max(shape[0], int(m.group(1)))
        shape[1] = max(shape[1], int(m.group(2) or 0))
    rows, cols = shape
    if cols == 0:
        if not isinstance(raw, list) or len(raw) != rows:
            raise ScenarioError(source, field_name, f"'{name}' is a vector of {rows}: expected "
                                f"an array of {rows} values (or set '{name}[i]'), "
                                f"got {_show(raw)}")
        items = {f"{name}[{i + 1}]": v for i, v in enumerate(raw)}
    else:
        if (not isinstance(raw, list) or len(raw) != rows
                or not all(isinstance(r, list) and len(r) == cols for r in raw)):
            raise ScenarioError(source, field_name, f"'{name}' is a {rows}x{cols} matrix: "
                                f"expected an array of {rows} rows of {cols} values "
                                f"(or set '{name}[i,j]'), got {_show(raw)}")
        items = {f"{name}[{i + 1},{j + 1}]": v for i, r in enumerate(raw)
                 for j, v in enumerate(r)}
    out: dict[str, ParamValue] = {}
    section = field_name[: len(field_name) - len(name)]  # "controller." (or a setting's)
    for n, v in items.items():
        if n not in variables:  # pragma: no cover - tables are dense
            raise ScenarioError(source, field_name, f"the {model} FMU has no variable '{n}'")
        out[n] = _scalar(model, n, variables[n], v, source, f"{section}{n}")
    return out


def _not_parameter(model: str, name: str, causality: str, source: str,
                   field_name: str) -> ScenarioError:
    article = "an" if causality[:1] in "aeiou" else "a"
    return ScenarioError(source, field_name, f"'{name}' is {article} {causality} of the {model} "
                         "FMU; expected a variable whose causality is parameter")


def _show(raw: object) -> str:
    """A value as the TOML file spells it (true/false, not True/False)."""
    if isinstance(raw, bool):
        return "true" if raw else "false"
    return repr(raw)


def _scalar(model: str, name: str, info: tuple[str, str], raw: object, source: str,
            field_name: str) -> ParamValue:
    causality, kind = info
    if causality != "parameter":
        raise _not_parameter(model, name, causality, source, field_name)
    if kind == "Real":
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            raise ScenarioError(source, field_name, f"'{name}' is a Real parameter: "
                                f"expected a number, got {_show(raw)}")
        if not math.isfinite(raw):
            raise ScenarioError(source, field_name,
                                f"'{name}' is a Real parameter: expected a finite number, "
                                f"got {_show(raw)}")
        return float(raw)
    if kind == "Integer":
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise ScenarioError(source, field_name, f"'{name}' is an Integer parameter: "
                                f"expected an integer, got {_show(raw)}")
        lo, hi, declared = _integer_range(model, name)
        if not lo <= raw <= hi:  # (beyond 32 bits it would reach the FMU wrapped around)
            where = (f"its declared range in the {model} FMU" if declared else
                     "a 32-bit FMI Integer")
            raise ScenarioError(source, field_name, f"'{name}' is an Integer parameter: "
                                f"expected an integer in {lo}..{hi} ({where}), got {raw}")
        return int(raw)
    if kind == "Boolean":
        if not isinstance(raw, bool):
            raise ScenarioError(source, field_name, f"'{name}' is a Boolean parameter: "
                                f"expected true or false, got {_show(raw)}")
        return raw
    raise ScenarioError(source, field_name,  # pragma: no cover - no such variables today
                        f"'{name}' has type {kind}, which scenarios cannot set")


# ---------------------------------------------------------------------------
# Timing


def _is_multiple(x: float, quantum: float) -> bool:
    k = round(x / quantum)
    return k >= 1 and abs(x - k * quantum) <= _REL_TOL * max(x, quantum)


def check_timing(source: str, step: float, duration: float,
                 plant_p: Mapping[str, ParamValue],
                 ctrl_p: Mapping[str, ParamValue]) -> None:
    """A positive duration that is a multiple of the step, a step that is a multiple of the
    controller's Ts, and overridden FMU steps (``controller.Ts``, ``plant.h_internal``) that
    divide it."""
    if not (math.isfinite(duration) and duration > 0):
        raise ScenarioError(source, "duration", f"expected a positive number of seconds, "
                            f"got {duration!r}")
    if not _is_multiple(step, STEP_QUANTUM):
        raise ScenarioError(source, "step", f"expected a positive integer multiple of "
                            f"{STEP_QUANTUM} s (the controller's sample time), got {step!r}")
    for params, name, field_name in ((ctrl_p, "Ts", "controller.Ts"),
                                     (plant_p, "h_internal", "plant.h_internal")):
        if name in params:
            value = float(params[name])
            if not value > 0 or not _is_multiple(step, value):
                raise ScenarioError(source, field_name, f"expected a positive value that "
                                    f"divides the communication step {step:g} s, got {value!r}")
    if not _is_multiple(duration, step):
        raise ScenarioError(source, "duration", f"expected a multiple of the communication "
                            f"step {step:g} s, got {duration!r}")


# ---------------------------------------------------------------------------
# Plausibility: units (docs/scenarios.md, "Plausibility checks")

POSITION_WARN_DISTANCE = 100.0
"""m: a position axis moving farther than this from its value at t = 0 ..."""
POSITION_WARN_RATIO = 50.0
"""... and farther than this many times the rest of the trajectory's size is a warning;
so is one ..."""
POSITION_WARN_SPEED = 50.0
"""... whose reference moves faster than this, m/s (180 km/h, beyond almost every
multirotor; a step moves at its jump per step), and so is ..."""
POSITION_MM_DISTANCE = 1000.0
"""... a position axis reaching farther than this from the origin, m: a vehicle asked to
be a kilometre away is more likely given millimetres (3000 for 3 m)."""
_DEG = math.pi / 180.0
_ANGLE_TOL = 1e-9  # rad: a reference exactly at a bound (say 60 deg converted) is inside
_BOUNDED_AXES = {"roll": 1, "pitch": 2}  # the guidance bounds [phi_c, theta_c]; yaw is free


def checked(sc: Scenario) -> Scenario:
    """``sc`` after the plausibility checks: errors raised, warnings recorded."""
    _check_finite(sc)
    _check_attitude(sc)
    with np.errstate(over="ignore", invalid="ignore"):  # (a norm of 1e300 m is inf: fine)
        return replace(sc, warnings=_position_warnings(sc))


_DERIVATIVES = ("value", "rate of change", "second derivative")


def _check_finite(sc: Scenario) -> None:
    """Every signal the run feeds the FMUs (references with the derivatives fed forward,
    disturbances) finite over the run: numbers a file may hold (up to 1.8e308) can still
    overflow a double when a signal combines them (amplitude x omega^2, a ramp's slope)."""
    degrees = any(isinstance(s, Scaled) and s.factor == _DEG for s in sc.attitude)
    groups = (("reference.position", POSITION_AXES, sc.position, 2),
              (f"reference.{'attitude_deg' if degrees else 'attitude'}", ATTITUDE_AXES,
               sc.attitude, 1),
              ("disturbance.force", POSITION_AXES, sc.force, 0),
              ("disturbance.torque", POSITION_AXES, sc.torque, 0),
              ("disturbance.acceleration", POSITION_AXES, sc.acceleration, 0))
    t = _check_times(sc)
    for table, axes, signals, orders in groups:
        for axis, signal in zip(axes, signals, strict=True):
            for order in range(orders + 1):
                with np.errstate(all="ignore"):
                    try:
                        v = signal.value(t) if order == 0 else signal.derivative(t, order)
                        bad: np.ndarray | None = ~np.isfinite(v)
                    except OverflowError:
                        bad = None
                if bad is not None and not bad.any():
                    continue
                when = "" if bad is None else f" at t = {t[int(np.argmax(bad))]:.5g} s"
                raise ScenarioError(sc.source, f"{table}.{axis}", f"its {_DERIVATIVES[order]} "
                                    f"overflows{when}: the signal's numbers are too large "
                                    "for a double (1.8e308) together")


def _rad(x: float) -> str:
    return f"{x:.5g} rad ({x / _DEG:.5g} deg)"


def _euler_bounds(sc: Scenario, index: int) -> tuple[float, float, bool]:
    """(euler_min[index], euler_max[index], set in [controller]): the guidance's attitude
    bounds, the FMU's defaults unless the scenario overrides them."""
    names = (f"euler_min[{index}]", f"euler_max[{index}]")
    p = sc.controller_parameters
    lo, hi = (float(p.get(n, start_value(controller_fmu(), n))) for n in names)
    for name, value in zip(names, (lo, hi), strict=True):
        if name in p and not abs(value) < math.pi / 2:
            raise ScenarioError(sc.source, f"controller.{name}", "expected a bound inside "
                                f"(-pi/2, pi/2) rad (-90..90 deg, exclusive), got {value!r}")
    if lo > hi:
        shown = [f"{n} = {v!r}" + ("" if n in p else " (the FMU's default)")
                 for n, v in zip(names, (lo, hi), strict=True)]
        raise ScenarioError(sc.source, f"controller.{names[0] if names[0] in p else names[1]}",
                            f"expected {names[0]} <= {names[1]}, got {shown[0]} > {shown[1]}")
    return lo, hi, any(n in p for n in names)


def _beyond(signal: Signal, t: np.ndarray, lo: float,
            hi: float) -> tuple[float, float | None] | None:
    """The value of ``signal`` (rad) farthest outside [lo, hi] and its first time, sampled at
    ``t``; when the samples stay inside, the end of its closed-form range outside (time None:
    after the run); None when inside."""
    v = signal.value(t)
    excess = np.maximum(lo - v, v - hi)
    k = int(np.argmax(excess))
    if excess[k] > _ANGLE_TOL:
        return float(v[k]), float(t[k])
    ends = value_range(signal)
    if ends is not None:
        worst = max(ends, key=lambda x: max(lo - x, x - hi))
        if max(lo - worst, worst - hi) > _ANGLE_TOL:
            return worst, None
    return None


def _parameters(signal: Signal) -> list[tuple[str, float, bool]]:
    """The keys of a signal setting its values: (key, value, swings +-value); key "" for a
    constant (the signal's own field)."""
    if isinstance(signal, Constant):
        return [("", signal.level, False)]
    if isinstance(signal, (Sine, Chirp)):
        return [("amplitude", signal.amplitude, True), ("offset", signal.offset, False)]
    if isinstance(signal, Ramp):
        return [("from", signal.start, False), ("to", signal.end, False)]
    if isinstance(signal, (Steps, Waypoints)):
        out = [(f"values[{i + 1}]", v, False) for i, v in enumerate(signal.values)]
        if isinstance(signal, Steps) and signal.times[0] > 0.0:
            out.insert(0, ("initial", signal.initial, False))
        return out
    return []


def _culprit(signal: Signal, field_name: str, unit: float, t: np.ndarray, lo: float,
             hi: float) -> tuple[str, float | None]:
    """The most specific field taking the reference ``signal`` (file units, ``unit`` rad
    each) outside [lo, hi] rad: a term of a sum that leaves the bounds on its own, then the
    key whose value does (an amplitude, a ramp's end, a step's value), with that value."""
    if isinstance(signal, Sum):
        for k, term in enumerate(signal.terms):
            if _beyond(Scaled(unit, term), t, lo, hi) is not None:
                return _culprit(term, f"{field_name}{signal.spelling}[{k + 1}]", unit, t, lo, hi)
        return field_name, None
    for key, value, swings in _parameters(signal):
        low, high = (-abs(value), abs(value)) if swings else (value, value)
        if low * unit < lo - _ANGLE_TOL or high * unit > hi + _ANGLE_TOL:
            return (f"{field_name}.{key}" if key else field_name), value
    return field_name, None


_CHECK_SAMPLES = 1_000_001
"""At most this many samples per signal for the load-time checks (a 2000 s run at 2 ms):
a longer run is checked at every k-th step, so checking never costs more memory than a
short run (the closed-form ranges of the signals still cover every instant)."""


def _check_times(sc: Scenario) -> np.ndarray:
    stride = -(-(sc.n_steps + 1) // _CHECK_SAMPLES)
    return np.arange(0, sc.n_steps + 1, stride, dtype=np.float64) * sc.step


def _check_attitude(sc: Scenario) -> None:
    """Roll and pitch references inside the controller's bounds over the whole run (and
    beyond, as far as the signals' parameters say), yaw amplitudes within a turn (rad)."""
    degrees = any(isinstance(s, Scaled) and s.factor == _DEG for s in sc.attitude)
    table = "attitude_deg" if degrees else "attitude"
    t = _check_times(sc)
    for axis, index in _BOUNDED_AXES.items():
        lo, hi, overridden = _euler_bounds(sc, index)
        signal = sc.attitude[index - 1]
        found = _beyond(signal, t, lo, hi)
        if found is None:
            continue
        peak, when = found
        inner = signal.signal if isinstance(signal, Scaled) else signal
        unit = _DEG if degrees else 1.0
        field_name, value = _culprit(inner, f"reference.{table}.{axis}", unit, t, lo, hi)
        where = f"at t = {when:.5g} s" if when is not None else \
            f"after this run's {sc.duration:g} s"
        names = f"euler_min[{index}], euler_max[{index}]" + \
            (" as overridden" if overridden else "")
        if degrees:
            head = f"{value:.5g} deg: " if value is not None else ""
            head = "" if head == f"{peak / _DEG:.5g} deg: " else head
            reason = (f"{head}the {axis} reference reaches {peak / _DEG:.5g} deg {where}, "
                      f"outside the controller's {axis} bounds {lo / _DEG:.5g}..{hi / _DEG:.5g} "
                      f"deg ({names} = {lo:.5g}..{hi:.5g} rad; [controller] can set them, "
                      "in rad, inside (-pi/2, pi/2))")
        else:
            head = f"{_rad(value)}: " if value is not None and _rad(value) != _rad(peak) else ""
            reason = (f"{head}the {axis} reference reaches {_rad(peak)} {where}, outside the "
                      f"controller's {axis} bounds {lo:.5g}..{hi:.5g} rad "
                      f"({lo / _DEG:.5g}..{hi / _DEG:.5g} deg; {names})")
            if abs(peak) <= 360.0:
                reason += "; if you meant degrees, use [reference.attitude_deg]"
                if not lo - _ANGLE_TOL <= peak * _DEG <= hi + _ANGLE_TOL:
                    reason += f" ({peak:.5g} deg is outside the bounds too)"
        raise ScenarioError(sc.source, field_name, reason)
    if not degrees:
        _check_yaw(sc.source, sc.attitude[2], "reference.attitude.yaw")


def _check_yaw(source: str, signal: Signal, field_name: str) -> None:
    """The controller does not bound yaw (psi_c = psi_ref, the heading unwrapped), so any
    yaw angle is valid; but a sine or chirp swinging it by more than a full turn each way
    is not radians."""
    if isinstance(signal, Sum):
        for k, term in enumerate(signal.terms):
            _check_yaw(source, term, f"{field_name}{signal.spelling}[{k + 1}]")
    elif isinstance(signal, (Sine, Chirp)) and abs(signal.amplitude) > 2.0 * math.pi:
        reason = (f"{_rad(signal.amplitude)} swings the yaw reference by more than a full "
                  "turn (2 pi rad = 360 deg) each way, not plausible in radians (yaw angles "
                  "themselves are not bounded)")
        if abs(signal.amplitude) <= 360.0:
            reason += "; if you meant degrees, use [reference.attitude_deg]"
        raise ScenarioError(source, f"{field_name}.amplitude", reason)


def _position_warnings(sc: Scenario) -> tuple[str, ...]:
    """Positions that are probably not metres, at most one warning per axis (the first rule
    that applies; docs/scenarios.md, "Plausibility checks"):

    - an axis moving (from its value at t = 0) more than POSITION_WARN_DISTANCE and more
      than POSITION_WARN_RATIO times the rest of the trajectory's size (the largest distance
      of the other two axes from the origin): a step of 1000 m on a vehicle flown at 3 m;
    - an axis moving more than POSITION_WARN_DISTANCE whose reference moves faster than
      POSITION_WARN_SPEED somewhere (the larger of its analytic rate and its change between
      samples, so a step counts as its jump per step): a move no multirotor flies, and a
      move of 1 m written in millimetres;
    - an axis reaching farther than POSITION_MM_DISTANCE from the origin: a hover at 3 m
      written as -3000."""
    t = _check_times(sc)
    p = np.column_stack([s.value(t) for s in sc.position])
    out: list[str] = []
    for a, axis in enumerate(POSITION_AXES):
        x = p[:, a]
        moves = np.abs(x - x[0])
        k = int(np.argmax(moves))
        excursion = float(moves[k])
        rest = float(np.max(np.linalg.norm(np.delete(p, a, axis=1), axis=1)))
        jumps = np.abs(np.diff(x))
        j = int(np.argmax(jumps)) if len(jumps) else 0
        step = len(jumps) > 0 and jumps[j] > 0.5 * excursion
        if step:
            what = (f"a step of {jumps[j]:.5g} m (from {x[j]:.5g} to {x[j + 1]:.5g} m at "
                    f"t = {t[j + 1]:.5g} s)")
        else:
            what = (f"an excursion of {excursion:.5g} m (from {x[0]:.5g} m at t = 0 to "
                    f"{x[k]:.5g} m at t = {t[k]:.5g} s)")
        field_name = f"{sc.source}: field 'reference.position.{axis}'"
        if excursion > POSITION_WARN_DISTANCE and excursion > POSITION_WARN_RATIO * rest:
            stays = f"within {rest:.3g} m of the origin" if rest > 0.0 else "at the origin"
            out.append(f"{field_name}: {what} while the rest of the trajectory stays {stays}; "
                       "is this the intended unit (m)?")
            continue
        if excursion > POSITION_WARN_DISTANCE:
            rate = float(np.max(np.abs(sc.position[a].derivative(t, 1))))
            dt = np.diff(t)
            speed = max(rate, float(np.max(jumps / dt)) if len(dt) else 0.0)
            if speed > POSITION_WARN_SPEED:
                how = ("" if step else f" at up to {speed:.3g} m/s")
                out.append(f"{field_name}: {what}{how}: a move of more than "
                           f"{POSITION_WARN_DISTANCE:g} m faster than a multirotor flies "
                           f"({POSITION_WARN_SPEED:g} m/s); is this the intended unit (m)? "
                           f"In millimetres it would be {excursion / 1000.0:.5g} m")
                continue
        far = int(np.argmax(np.abs(x)))
        if abs(x[far]) > POSITION_MM_DISTANCE:
            out.append(f"{field_name}: the reference is {x[far]:.5g} m at t = {t[far]:.5g} s, "
                       f"more than {POSITION_MM_DISTANCE:g} m from the origin; is this the "
                       f"intended unit (m)? In millimetres it would be {x[far] / 1000.0:.5g} m")
    return tuple(out)
