"""Scenario files (TOML): what to fly, on which airframe, under which disturbances.

A scenario is data: users write their own without touching code.  The shipped ones live in
``orchestrator/scenarios/`` (``list_scenarios()``); a path works wherever a name does.
Loading validates everything -- types, ranges, unknown keys, parameter overrides against the
installed FMUs' modelDescription -- so nothing runs half-way: every error surfaces at load
time as a :class:`ScenarioError` naming the file, the dotted field and what is expected::

    my.toml: field 'reference.attitude_deg.roll.omega': expected a number, got '0.2'

Layout (units SI, angles in rad unless the key ends in ``_deg``; world frame NED, body FRD)::

    name = "my_scenario"          # optional, default: the file name without .toml
    description = "free text"     # optional
    duration = 100.0              # s, > 0, a multiple of step
    step = 0.002                  # s, communication step, optional (default 0.002): a
                                  #   positive multiple of 0.002 (controller Ts; the plant's
                                  #   internal RK4 step 0.0005 divides it)
    airframe = "paper_hexacopter" # shipped airframe name, or a path to an airframe file
                                  #   (relative paths: from this file's folder)
    coupling = "gauss-seidel"     # optional: "gauss-seidel" (default) or "jacobi"

    [reference.position]          # xi_ref, m, world NED; each axis a signal, default 0
    x = { type = "chirp", amplitude = 3.0, omega0 = 0.0, omega1 = 0.5, t1 = 100.0 }
    y = 0.0
    z = -3.0

    [reference.attitude]          # mu_ref = [roll, pitch, yaw], rad, default 0 ...
    roll = { type = "sine", amplitude = 0.7, omega = 0.2 }
    # [reference.attitude_deg]    # ... or the same in degrees (one of the two tables)

    [disturbance.force]           # f_d, N, world NED: x, y, z (default 0)
    [disturbance.torque]          # tau_d, N m, body FRD: x, y, z
    [disturbance.acceleration]    # a_d, m/s^2, world NED: x, y, z
    x = { type = "steps", times = [10.0, 14.0], values = [2.0, 0.0] }

    [[fault]]                     # rotor faults; efficiencies start at 1 and are
    time = 10.0                   #   piecewise constant: from `time` on (s, >= 0)
    rotor = 1                     #   rotor (1-based, <= the airframe's rotor count)
    efficiency = 0.0              #   runs at this efficiency (0..1, 0 = lost)

    [plant]                       # start-value overrides of MultirotorPlant parameters,
    noise_pos = 0.01              #   by FMU variable name, applied after the airframe's;
    "pos0[1]" = 0.5               #   an element of a vector needs quotes ...
    [controller]                  # ... and FullPoseController parameters
    K_pos_D = [3.0, 3.0, 2.2]     #   a whole vector as an array (a matrix: array of rows)

Signals (``orchestrator.scenario.signals``): a number is a constant; a table with
``type = "constant" | "sine" | "chirp" | "steps" | "ramp" | "waypoints" | "sum"`` is that
signal; an array of signals is their sum.  Their analytic derivatives give the feed-forward
inputs: ``vel_ref``/``acc_ref`` from the position, ``euler_rate_ref`` (time derivatives of
the Euler angles) from the attitude.

Override values must match the FMU variable type (Real: a number, Integer: an integer,
Boolean: true/false) and name a variable whose causality is ``parameter``.  The vehicle
starts at the reference pose at t = 0 (:meth:`Scenario.initial_pose`) unless ``[plant]``
overrides ``pos0``/``euler0``.

Plausible units (docs/scenarios.md, "Plausibility checks"): a roll or pitch reference
leaving the controller's bounds ``euler_min``/``euler_max`` (FMU defaults +-60 deg, or the
scenario's ``[controller]`` values) is an error naming the most specific field, with the
value in rad and deg and, for a radian value that reads as degrees, the hint to use
``[reference.attitude_deg]``; yaw is not bounded (any angle), but a radian sine or chirp
yaw amplitude above a full turn is an error too.  A position axis moving more than
``POSITION_WARN_DISTANCE`` m and ``POSITION_WARN_RATIO`` times the rest of the trajectory's
size is a warning in :attr:`Scenario.warnings`.
"""

from __future__ import annotations

import difflib
import math
import re
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from controller import CONTROLLER_FMU, controller_fmu
from orchestrator.scenario.reader import FieldReader, ScenarioError
from orchestrator.scenario.signals import (
    ZERO,
    Chirp,
    Constant,
    Ramp,
    Scaled,
    Signal,
    Sine,
    Steps,
    Sum,
    Waypoints,
    parse_signal,
    value_range,
)
from orchestrator.sim.engine import COUPLINGS
from orchestrator.sim.fmu import installed_fmu
from orchestrator.sim.outcome import DEFAULT_POSITION_ERROR, DEFAULT_TILT_DEG, LostCriteria
from plant import PLANT_FMU, Airframe, AirframeError, list_airframes, load_airframe
from plant.airframe import MAX_ROTORS
from plant.common.model_description import fmu_variables, start_value
from plant.common.toml_reader import read_toml, resolve_file, shipped_names

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "COUPLINGS",
    "STEP_QUANTUM",
    "Fault",
    "Scenario",
    "ScenarioError",
    "check_scenario",
    "list_scenarios",
    "load_scenario",
    "parse_scenario",
    "scenario_names",
]

STEP_QUANTUM = start_value(controller_fmu(), "Ts")
"""Communication steps are positive integer multiples of this (the controller's Ts), s."""
DEFAULT_STEP = STEP_QUANTUM
POSITION_AXES = ("x", "y", "z")
ATTITUDE_AXES = ("roll", "pitch", "yaw")
DISTURBANCES = {"force": "f_d", "torque": "tau_d", "acceleration": "a_d"}
_REL_TOL = 1e-9
_TOP_KEYS = ("name", "description", "duration", "step", "airframe", "coupling", "reference",
             "disturbance", "fault", "fault_detection", "lost", "plant", "controller", "origin")

ParamValue = float | int | bool
Vec3 = tuple[Signal, Signal, Signal]


@dataclass(frozen=True)
class Fault:
    """From ``time`` on, rotor ``rotor`` (1-based) runs at ``efficiency`` (0..1)."""

    time: float
    rotor: int
    efficiency: float


@dataclass(frozen=True, eq=False)
class Scenario:
    """A validated scenario.  Signals are in SI units and radians.  ``warnings``: the
    plausibility warnings of loading (``file: field '...': reason``), for a CLI to print."""

    name: str
    description: str
    source: str
    duration: float
    step: float
    airframe: Airframe
    coupling: str
    position: Vec3  # xi_ref, m, world NED
    attitude: Vec3  # mu_ref = [roll, pitch, yaw], rad
    force: Vec3 = (ZERO, ZERO, ZERO)  # f_d, N, world NED
    torque: Vec3 = (ZERO, ZERO, ZERO)  # tau_d, N m, body FRD
    acceleration: Vec3 = (ZERO, ZERO, ZERO)  # a_d, m/s^2, world NED
    faults: tuple[Fault, ...] = ()
    fault_detection: float | None = 0.0  # delay (s) until the controller knows; None: never
    plant_parameters: dict[str, ParamValue] = field(default_factory=dict)
    controller_parameters: dict[str, ParamValue] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()  # plausibility warnings (file: field '...': reason)
    lost: LostCriteria = field(default_factory=LostCriteria)  # when a run is lost and stops
    # WGS84 point of the local NED origin (lat deg, lon deg, alt m AMSL), for `fullpose fly`;
    # None: the flier's default
    origin: tuple[float, float, float] | None = None
    # the airframe the plant flies when it is not the one the controller is told (a sweep's
    # perturbed vehicle: the model mismatch); None: ``airframe``.  No scenario file field.
    plant_airframe: Airframe | None = None

    @property
    def true_airframe(self) -> Airframe:
        """The airframe the plant flies (``plant_airframe``, else ``airframe``)."""
        return self.plant_airframe if self.plant_airframe is not None else self.airframe

    @property
    def n_steps(self) -> int:
        """Number of communication steps (duration / step)."""
        return round(self.duration / self.step)

    def times(self) -> np.ndarray:
        """The communication points t_k = k * step, k = 0..n_steps."""
        return np.arange(self.n_steps + 1) * self.step

    # -- signals ---------------------------------------------------------------

    def references(self, t: ArrayLike) -> dict[str, np.ndarray]:
        """Controller reference inputs at times ``t``, each (len(t), 3).

        ``pos_ref``, ``vel_ref``, ``acc_ref`` (position and its analytic derivatives),
        ``euler_ref``, ``euler_rate_ref`` (attitude and its analytic derivative).
        """
        tt = _column_times(t)
        return {
            "pos_ref": _stack(self.position, tt, 0),
            "vel_ref": _stack(self.position, tt, 1),
            "acc_ref": _stack(self.position, tt, 2),
            "euler_ref": _stack(self.attitude, tt, 0),
            "euler_rate_ref": _stack(self.attitude, tt, 1),
        }

    def disturbances(self, t: ArrayLike) -> dict[str, np.ndarray]:
        """Plant disturbance inputs at times ``t``: ``f_d``, ``tau_d``, ``a_d`` (len(t), 3)
        and ``efficiency`` (len(t), 8; rotors beyond the airframe's count stay 1)."""
        tt = _column_times(t)
        return {
            "f_d": _stack(self.force, tt, 0),
            "tau_d": _stack(self.torque, tt, 0),
            "a_d": _stack(self.acceleration, tt, 0),
            "efficiency": self.efficiency(tt),
        }

    def efficiency(self, t: ArrayLike) -> np.ndarray:
        """Rotor efficiencies (len(t), 8): 1 until a fault, piecewise constant after."""
        tt = _column_times(t)
        eff = np.ones((len(tt), MAX_ROTORS))
        for fault in sorted(self.faults, key=lambda f: f.time):
            eff[tt >= fault.time, fault.rotor - 1] = fault.efficiency
        return eff

    def health(self, t: ArrayLike) -> np.ndarray:
        """What the controller is told of the rotors (``rotor_health``, (len(t), 8)): the
        efficiencies delayed by ``fault_detection`` seconds, or all 1 when it is None
        (the controller is never told: no reconfiguration)."""
        tt = _column_times(t)
        if self.fault_detection is None:
            return np.ones((len(tt), MAX_ROTORS))
        return self.efficiency(tt - self.fault_detection)

    def initial_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(position, Euler angles) to start from: the reference at t = 0, unless the
        ``[plant]`` overrides set ``pos0[i]`` / ``euler0[i]``."""
        ref = self.references(np.zeros(1))
        pos, euler = ref["pos_ref"][0], ref["euler_ref"][0]
        for i in range(3):
            pos[i] = float(self.plant_parameters.get(f"pos0[{i + 1}]", pos[i]))
            euler[i] = float(self.plant_parameters.get(f"euler0[{i + 1}]", euler[i]))
        return pos, euler

    def summary(self) -> dict[str, Any]:
        """JSON-friendly facts about the scenario (for run metadata)."""
        return {
            "name": self.name,
            "description": self.description,
            "source": self.source,
            "duration": self.duration,
            "step": self.step,
            "airframe": self.airframe.name,
            "airframe_source": self.airframe.source,
            "coupling": self.coupling,
            "faults": [vars(f) for f in self.faults],
            "plant_parameters": dict(self.plant_parameters),
            "controller_parameters": dict(self.controller_parameters),
        }

    # -- overrides -------------------------------------------------------------

    def with_overrides(self, duration: float | None = None,
                       settings: Iterable[str] = (),
                       airframe: str | Path | Airframe | None = None) -> Scenario:
        """A copy with another duration, another airframe (a shipped name, an airframe file
        or an :class:`Airframe`: the command line's ``--airframe``) and/or parameter settings
        ``plant.NAME=VALUE`` / ``controller.NAME=VALUE`` (VALUE in TOML syntax: ``3.0``,
        ``false``, ``[1, 2, 3]``), validated like the file's ``[plant]`` / ``[controller]``
        tables."""
        sc = self if airframe is None else self._on_airframe(airframe)
        if sc is not self and duration is None and not settings:
            return _checked(sc)
        return sc._with_settings(duration, settings)

    def _on_airframe(self, airframe: str | Path | Airframe) -> Scenario:
        af = airframe if isinstance(airframe, Airframe) else load_airframe(airframe)
        for fault in self.faults:
            if fault.rotor > af.n_rotors:
                raise ScenarioError(self.source, "fault.rotor",
                                    f"rotor {fault.rotor} does not exist on airframe {af.name!r} "
                                    f"({af.n_rotors} rotors)")
        return replace(self, airframe=af)

    def _with_settings(self, duration: float | None, settings: Iterable[str]) -> Scenario:
        plant_p = dict(self.plant_parameters)
        ctrl_p = dict(self.controller_parameters)
        for setting in settings:
            where = f"{self.source}: setting '{setting}'"
            if not isinstance(setting, str) or "=" not in setting:
                raise ScenarioError(where, "", "expected plant.NAME=VALUE or "
                                    "controller.NAME=VALUE")
            lhs, text = (s.strip() for s in setting.split("=", 1))
            section, _, name = lhs.partition(".")
            if section not in ("plant", "controller") or not name:
                raise ScenarioError(where, lhs, "expected plant.NAME=VALUE or "
                                    "controller.NAME=VALUE")
            try:
                value = tomllib.loads(f"v = {text}")["v"]
            except tomllib.TOMLDecodeError:
                raise ScenarioError(where, lhs, f"cannot read the value {text!r}: expected a "
                                    "number, true/false or an array like [1.0, 2.0]") from None
            target = plant_p if section == "plant" else ctrl_p
            fmu = PLANT_FMU if section == "plant" else CONTROLLER_FMU
            target.update(_parameter(fmu, name, value, where, lhs))
        new_duration = self.duration
        if duration is not None:
            where = f"{self.source}: duration override"
            if isinstance(duration, bool) or not isinstance(duration, (int, float)):
                raise ScenarioError(where, "duration", f"expected a number, got {duration!r}")
            new_duration = float(duration)
        _check_timing(self.source, self.step, new_duration, plant_p, ctrl_p)
        return _checked(replace(self, duration=new_duration, plant_parameters=plant_p,
                                controller_parameters=ctrl_p))


def _column_times(t: ArrayLike) -> np.ndarray:
    return np.asarray(t, dtype=np.float64).reshape(-1)


def _stack(axes: Vec3, t: np.ndarray, order: int) -> np.ndarray:
    if order == 0:
        return np.column_stack([s.value(t) for s in axes])
    return np.column_stack([s.derivative(t, order) for s in axes])


# ---------------------------------------------------------------------------
# FMU parameters


@cache
def _fmu_variables(model: str) -> dict[str, tuple[str, str]]:
    """name -> (causality, type) of an installed FMU's model variables."""
    return {name: (v.causality, v.type) for name, v in fmu_variables(installed_fmu(model)).items()}


_INDEX = re.compile(r"\[(\d+)(?:,(\d+))?\]$")


def _parameter(model: str, name: str, raw: object, source: str,
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
        return int(raw)
    if kind == "Boolean":
        if not isinstance(raw, bool):
            raise ScenarioError(source, field_name, f"'{name}' is a Boolean parameter: "
                                f"expected true or false, got {_show(raw)}")
        return raw
    raise ScenarioError(source, field_name,  # pragma: no cover - no such variables today
                        f"'{name}' has type {kind}, which scenarios cannot set")


def _overrides(top: FieldReader, section: str, model: str) -> dict[str, ParamValue]:
    table = top.table(section)
    if table is None:
        return {}
    out: dict[str, ParamValue] = {}
    for key, raw in table.data.items():
        table.used.add(key)
        out.update(_parameter(model, key, raw, table.source, table.field(key)))
    return out


# ---------------------------------------------------------------------------
# Timing


def _is_multiple(x: float, quantum: float) -> bool:
    k = round(x / quantum)
    return k >= 1 and abs(x - k * quantum) <= _REL_TOL * max(x, quantum)


def _check_timing(source: str, step: float, duration: float,
                  plant_p: Mapping[str, ParamValue],
                  ctrl_p: Mapping[str, ParamValue]) -> None:
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
"""... and farther than this many times the rest of the trajectory's size is a warning."""
_DEG = math.pi / 180.0
_ANGLE_TOL = 1e-9  # rad: a reference exactly at a bound (say 60 deg converted) is inside
_BOUNDED_AXES = {"roll": 1, "pitch": 2}  # the guidance bounds [phi_c, theta_c]; yaw is free


def _checked(sc: Scenario) -> Scenario:
    """``sc`` after the plausibility checks: errors raised, warnings recorded."""
    _check_attitude(sc)
    return replace(sc, warnings=_position_warnings(sc))


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
    """A position axis moving (from its value at t = 0) more than POSITION_WARN_DISTANCE and
    more than POSITION_WARN_RATIO times the rest of the trajectory's size (the largest
    distance of the other two axes from the origin) -- a step of 1000 m on a vehicle flown
    at 3 m: probably not metres."""
    t = _check_times(sc)
    p = np.column_stack([s.value(t) for s in sc.position])
    out: list[str] = []
    for a, axis in enumerate(POSITION_AXES):
        x = p[:, a]
        moves = np.abs(x - x[0])
        k = int(np.argmax(moves))
        excursion = float(moves[k])
        rest = float(np.max(np.linalg.norm(np.delete(p, a, axis=1), axis=1)))
        if excursion <= POSITION_WARN_DISTANCE or excursion <= POSITION_WARN_RATIO * rest:
            continue
        jumps = np.abs(np.diff(x))
        j = int(np.argmax(jumps))
        if jumps[j] > 0.5 * excursion:
            what = (f"a step of {jumps[j]:.5g} m (from {x[j]:.5g} to {x[j + 1]:.5g} m at "
                    f"t = {t[j + 1]:.5g} s)")
        else:
            what = (f"an excursion of {excursion:.5g} m (from {x[0]:.5g} m at t = 0 to "
                    f"{x[k]:.5g} m at t = {t[k]:.5g} s)")
        stays = f"within {rest:.3g} m of the origin" if rest > 0.0 else "at the origin"
        out.append(f"{sc.source}: field 'reference.position.{axis}': {what} while the rest "
                   f"of the trajectory stays {stays}; is this the intended unit (m)?")
    return tuple(out)


# ---------------------------------------------------------------------------
# Loading


def scenario_names() -> list[str]:
    """Names of the scenario files shipped with the package."""
    return shipped_names("orchestrator", "scenarios")


def list_scenarios() -> list[Scenario]:
    """The shipped scenarios, loaded."""
    return [load_scenario(name) for name in scenario_names()]


def resolve_scenario(name_or_path: str | Path) -> Path:
    """The scenario file a name or path stands for (a shipped name, or a file)."""
    return resolve_file(name_or_path, "orchestrator", "scenarios", "scenario", ScenarioError)


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load and validate a scenario file, or a shipped scenario by name."""
    path = resolve_scenario(name_or_path)
    return parse_scenario(read_toml(path, ScenarioError), str(path), default_name=path.stem,
                          base_dir=path.parent)


def check_scenario(path: str | Path) -> Scenario:
    """Validate a scenario completely (the same as loading it: nothing is deferred)."""
    return load_scenario(path)


def _airframe(top: FieldReader, base_dir: Path | None) -> Airframe:
    value = top.string("airframe")
    source = top.source
    looks_like_path = value.endswith(".toml") or "/" in value or "\\" in value
    if looks_like_path:
        path = Path(value).expanduser()
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        if not path.is_file():
            raise ScenarioError(source, "airframe", f"no airframe file {str(path)!r}; expected "
                                "a shipped airframe name or the path of an airframe file "
                                "(relative to the scenario's folder)")
        target: str | Path = path
    else:
        shipped = list_airframes()
        if value not in shipped:
            raise ScenarioError(source, "airframe", f"no shipped airframe {value!r}; expected "
                                f"one of {', '.join(shipped)} or the path of an airframe "
                                "file (ending in .toml)")
        target = value
    try:
        return load_airframe(target)
    except AirframeError as e:
        raise ScenarioError(source, "airframe", f"invalid airframe: {e}") from None


def _axes(parent: FieldReader, key: str, axes: tuple[str, ...],
          scale: float | None = None) -> Vec3 | None:
    table = parent.table(key)
    if table is None:
        return None
    out: list[Signal] = []
    for axis in axes:
        if table.has(axis):
            signal = parse_signal(table.raw(axis), table.source, table.field(axis))
            out.append(Scaled(scale, signal) if scale is not None else signal)
        else:
            out.append(ZERO)
    table.reject_unknown(lambda _k: f" (expected {', '.join(axes)})")
    return out[0], out[1], out[2]


def _faults(top: FieldReader, n_rotors: int) -> tuple[Fault, ...]:
    raw = top.raw("fault")
    if raw is None:
        return ()
    if not isinstance(raw, list) or not all(isinstance(f, dict) for f in raw):
        raise top.fail("fault", "expected an array of tables [[fault]] with time, rotor, "
                       "efficiency")
    faults: list[Fault] = []
    seen: set[tuple[float, int]] = set()
    for k, entry in enumerate(raw):
        r = FieldReader(top.source, entry, f"fault[{k + 1}].")
        time = r.number("time", nonnegative=True)
        rotor = r.integer("rotor")
        if not 1 <= rotor <= n_rotors:
            raise r.fail("rotor", f"expected a rotor number in 1..{n_rotors} (the airframe "
                         f"has {n_rotors} rotors), got {rotor}")
        efficiency = r.number("efficiency")
        if not 0.0 <= efficiency <= 1.0:
            raise r.fail("efficiency", f"expected a number in 0..1, got {efficiency!r}")
        r.reject_unknown()
        if (time, rotor) in seen:
            raise r.fail("time", f"rotor {rotor} already has a fault at t = {time:g} s")
        seen.add((time, rotor))
        faults.append(Fault(time, rotor, efficiency))
    return tuple(faults)


def _origin(top: FieldReader) -> tuple[float, float, float] | None:
    """``origin = [lat_deg, lon_deg, alt_m_amsl]``: where local NED (0, 0, 0) is on Earth."""
    if not top.has("origin"):
        return None
    expect = " (expected [latitude deg, longitude deg, altitude m AMSL])"
    value = top.data["origin"]
    if not isinstance(value, list) or len(value) != 3:
        raise top.fail("origin", f"expected 3 numbers, got {value!r}{expect}")
    lat, lon, alt = top.numbers("origin")
    for what, v, bound in (("latitude", lat, 89.0), ("longitude", lon, 180.0)):
        if abs(v) > bound:
            raise top.fail("origin", f"{what} {v:g} outside [-{bound:g}, {bound:g}] deg{expect}")
    if not -500.0 <= alt <= 10000.0:
        raise top.fail("origin", f"altitude {alt:g} m outside [-500, 10000] m AMSL{expect}")
    return (lat, lon, alt)


def _lost(top: FieldReader) -> LostCriteria:
    """``[lost]``: ``position_error`` (m, > 0) and ``tilt_deg`` (0 < tilt <= 180)."""
    table = top.table("lost")
    if table is None:
        return LostCriteria()
    error = table.number("position_error", DEFAULT_POSITION_ERROR, positive=True)
    tilt = table.number("tilt_deg", DEFAULT_TILT_DEG, positive=True)
    if tilt > 180.0:
        raise table.fail("tilt_deg", f"expected an angle in (0, 180] deg, got {tilt:g}")
    table.reject_unknown(lambda _k: " (expected position_error, tilt_deg)")
    return LostCriteria(position_error=error, tilt_deg=tilt)


def _fault_detection(top: FieldReader) -> float | None:
    """``fault_detection``: "immediate" (default), "none", or a delay in seconds."""
    raw = top.raw("fault_detection")
    if raw is None or raw == "immediate":
        return 0.0
    if raw == "none":
        return None
    if isinstance(raw, (int, float)) and not isinstance(raw, bool) and math.isfinite(raw) \
            and raw >= 0:
        return float(raw)
    raise top.fail("fault_detection", f'expected "immediate", "none" or a delay in seconds '
                   f">= 0, got {raw!r}")


def parse_scenario(data: dict[str, Any], source: str = "<scenario>", *,
                   default_name: str | None = None,
                   base_dir: Path | None = None) -> Scenario:
    """Validate parsed TOML data; ``base_dir`` resolves a relative airframe path."""
    top = FieldReader(source, data)
    top.used.update(_TOP_KEYS)  # unknown keys first: a typo is not "missing duration"
    top.reject_unknown(lambda _k: f" (expected one of {', '.join(_TOP_KEYS)})")
    name = top.string("name", default_name)
    description = top.string("description", "")
    duration = top.number("duration", positive=True)
    step = top.number("step", DEFAULT_STEP, positive=True)
    airframe = _airframe(top, base_dir)
    coupling = top.string("coupling", "gauss-seidel", choices=COUPLINGS)

    position: Vec3 = (ZERO, ZERO, ZERO)
    attitude: Vec3 = (ZERO, ZERO, ZERO)
    reference = top.table("reference")
    if reference is not None:
        position = _axes(reference, "position", POSITION_AXES) or position
        if reference.has("attitude") and reference.has("attitude_deg"):
            raise reference.fail("attitude_deg", "give either [reference.attitude] (rad) or "
                                 "[reference.attitude_deg] (degrees), not both")
        attitude = (_axes(reference, "attitude", ATTITUDE_AXES)
                    or _axes(reference, "attitude_deg", ATTITUDE_AXES, math.pi / 180.0)
                    or attitude)
        reference.reject_unknown(lambda _k: " (expected position, attitude or attitude_deg)")

    dist: dict[str, Vec3] = {}
    disturbance = top.table("disturbance")
    if disturbance is not None:
        for key in DISTURBANCES:
            axes = _axes(disturbance, key, POSITION_AXES)
            if axes is not None:
                dist[key] = axes
        disturbance.reject_unknown(lambda _k: " (expected force, torque or acceleration)")

    origin = _origin(top)
    faults = _faults(top, airframe.n_rotors)
    detection = _fault_detection(top)
    lost = _lost(top)
    plant_p = _overrides(top, "plant", PLANT_FMU)
    ctrl_p = _overrides(top, "controller", CONTROLLER_FMU)
    _check_timing(source, step, duration, plant_p, ctrl_p)

    return _checked(Scenario(
        name=name,
        description=description,
        source=source,
        duration=duration,
        step=step,
        airframe=airframe,
        coupling=coupling,
        position=position,
        attitude=attitude,
        faults=faults,
        fault_detection=detection,
        lost=lost,
        origin=origin,
        plant_parameters=plant_p,
        controller_parameters=ctrl_p,
        force=dist.get("force", Scenario.force),
        torque=dist.get("torque", Scenario.torque),
        acceleration=dist.get("acceleration", Scenario.acceleration),
    ))
