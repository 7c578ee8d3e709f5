"""Scenario files (TOML): what to fly, on which airframe, under which disturbances; parsed
into a :class:`~orchestrator.scenario.model.Scenario`, and the command line's overrides
(:func:`with_overrides`).

A scenario is data: users write their own without touching code.  The shipped ones live in
``orchestrator/scenarios/`` (``catalogue.list_scenarios()``); a path works wherever a name does.
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
    fmi = 2                       # optional: the FMUs' FMI version, 2 (default) or 3
    start = "air"                 # optional: "air" (default: at the reference's start, rotors
                                  #   at hover trim) or "ground" (resting level on the landing
                                  #   gear below it, rotors stopped)

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
starts at the reference pose at t = 0
(:meth:`~orchestrator.scenario.model.Scenario.initial_pose`) unless ``[plant]`` overrides
``pos0``/``euler0``.

Plausible units (docs/scenarios.md, "Plausibility checks"): a roll or pitch reference
leaving the controller's bounds ``euler_min``/``euler_max`` (FMU defaults +-60 deg, or the
scenario's ``[controller]`` values) is an error naming the most specific field, with the
value in rad and deg and, for a radian value that reads as degrees, the hint to use
``[reference.attitude_deg]``; yaw is not bounded (any angle), but a radian sine or chirp
yaw amplitude above a full turn is an error too.  A position axis moving more than
``POSITION_WARN_DISTANCE`` m and ``POSITION_WARN_RATIO`` times the rest of the trajectory's
size is a warning in :attr:`~orchestrator.scenario.model.Scenario.warnings`
(the checks: :mod:`orchestrator.scenario.checks`).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

from controller import CONTROLLER_FMU
from orchestrator.scenario.checks import STEP_QUANTUM, check_timing, checked, parameter_values
from orchestrator.scenario.mission import parse_mission
from orchestrator.scenario.model import (
    ATTITUDE_AXES,
    DISTURBANCES,
    POSITION_AXES,
    Fault,
    ParamValue,
    Scenario,
    Vec3,
)
from orchestrator.scenario.reader import FieldReader, ScenarioError, is_number
from orchestrator.scenario.signals import ZERO, Constant, Scaled, Signal, parse_signal
from orchestrator.sim.engine import COUPLINGS
from orchestrator.sim.outcome import DEFAULT_POSITION_ERROR, DEFAULT_TILT_DEG, LostCriteria
from plant import PLANT_FMU, Airframe, AirframeError, list_airframes, load_airframe
from plant.common.toml_reader import NestingError
from plant.common.toml_reader import loads as toml_loads

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DEFAULT_STEP = STEP_QUANTUM
"""The communication step of a scenario that names none, s."""
_TOP_KEYS = ("name", "description", "duration", "step", "airframe", "coupling", "start",
             "reference", "disturbance", "fault", "fault_detection", "lost", "plant",
             "controller", "origin", "mission", "fmi")


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
    fmi = _fmi_version(top)
    start = top.string("start", "air", choices=("air", "ground"))
    if start == "ground" and airframe.gear is None:
        raise top.fail("start", f"'ground' needs a landing gear, and airframe "
                       f"{airframe.name} has none ([landing_gear] in its file, "
                       "docs/airframes.md)")

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

    mission = None
    mission_table = top.table("mission")
    if mission_table is not None:
        if reference is not None:
            raise top.fail("mission", "give either [reference] signals or a [mission], "
                           "not both")
        plant_ground = top.raw("plant")
        ground_z = 0.0
        if isinstance(plant_ground, dict) and is_number(plant_ground.get("ground_z")):
            ground_z = float(plant_ground["ground_z"])
        mission = parse_mission(mission_table, ground_z)
        position = (Constant(mission.start[0]), Constant(mission.start[1]),
                    Constant(mission.start[2]))
        attitude = (ZERO, ZERO, Constant(mission.yaw))

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
    check_timing(source, step, duration, plant_p, ctrl_p)

    return checked(Scenario(
        name=name,
        description=description,
        source=source,
        duration=duration,
        step=step,
        airframe=airframe,
        coupling=coupling,
        start=start,
        mission=mission,
        fmi=fmi,
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


def _fmi_version(top: FieldReader) -> int:
    """``fmi = 2`` (default) or ``3``: which FMUs a run flies."""
    if not top.has("fmi"):
        top.used.add("fmi")
        return 2
    value = top.integer("fmi")
    if value not in (2, 3):
        raise top.fail("fmi", f"expected 2 or 3 (the FMI version of the FMUs), got {value}")
    return value


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


def _overrides(top: FieldReader, section: str, model: str) -> dict[str, ParamValue]:
    table = top.table(section)
    if table is None:
        return {}
    out: dict[str, ParamValue] = {}
    for key, raw in table.data.items():
        table.used.add(key)
        out.update(parameter_values(model, key, raw, table.source, table.field(key)))
    return out


# ---------------------------------------------------------------------------
# Overrides from the command line


def with_overrides(scenario: Scenario, duration: float | None = None,
                   settings: Iterable[str] = (),
                   airframe: str | Path | Airframe | None = None) -> Scenario:
    """A copy with another duration, another airframe (a shipped name, an airframe file
    or an :class:`Airframe`: the command line's ``--airframe``) and/or parameter settings
    ``plant.NAME=VALUE`` / ``controller.NAME=VALUE`` (VALUE in TOML syntax: ``3.0``,
    ``false``, ``[1, 2, 3]``), validated like the file's ``[plant]`` / ``[controller]``
    tables."""
    sc = scenario if airframe is None else _on_airframe(scenario, airframe)
    if sc is not scenario and duration is None and not settings:
        return checked(sc)
    return _with_settings(sc, duration, settings)


def _on_airframe(scenario: Scenario, airframe: str | Path | Airframe) -> Scenario:
    af = airframe if isinstance(airframe, Airframe) else load_airframe(airframe)
    for fault in scenario.faults:
        if fault.rotor > af.n_rotors:
            raise ScenarioError(scenario.source, "fault.rotor",
                                f"rotor {fault.rotor} does not exist on airframe {af.name!r} "
                                f"({af.n_rotors} rotors)")
    if scenario.start == "ground" and af.gear is None:
        raise ScenarioError(scenario.source, "start", f"'ground' needs a landing gear, and "
                            f"airframe {af.name} has none ([landing_gear] in its file, "
                            "docs/airframes.md)")
    return replace(scenario, airframe=af)


def _with_settings(scenario: Scenario, duration: float | None,
                   settings: Iterable[str]) -> Scenario:
    plant_p = dict(scenario.plant_parameters)
    ctrl_p = dict(scenario.controller_parameters)
    for setting in settings:
        where = f"{scenario.source}: setting '{setting}'"
        if not isinstance(setting, str) or "=" not in setting:
            raise ScenarioError(where, "", "expected plant.NAME=VALUE or "
                                "controller.NAME=VALUE")
        lhs, text = (s.strip() for s in setting.split("=", 1))
        section, _, name = lhs.partition(".")
        if section not in ("plant", "controller") or not name:
            raise ScenarioError(where, lhs, "expected plant.NAME=VALUE or "
                                "controller.NAME=VALUE")
        try:
            value = toml_loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            raise ScenarioError(where, lhs, f"cannot read the value {text!r}: expected a "
                                "number, true/false or an array like [1.0, 2.0]") from None
        except NestingError as e:
            raise ScenarioError(where, lhs, f"the value is {e}") from None
        target = plant_p if section == "plant" else ctrl_p
        fmu = PLANT_FMU if section == "plant" else CONTROLLER_FMU
        target.update(parameter_values(fmu, name, value, where, lhs))
    new_duration = scenario.duration
    if duration is not None:
        where = f"{scenario.source}: duration override"
        if isinstance(duration, bool) or not isinstance(duration, (int, float)):
            raise ScenarioError(where, "duration", f"expected a number, got {duration!r}")
        new_duration = float(duration)
    check_timing(scenario.source, scenario.step, new_duration, plant_p, ctrl_p)
    return checked(replace(scenario, duration=new_duration, plant_parameters=plant_p,
                            controller_parameters=ctrl_p))
