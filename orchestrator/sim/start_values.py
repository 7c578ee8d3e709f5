"""The two FMUs' start values from an airframe, a design, a pose and the failures to handle.

This is the one road from the design tools to the FMUs: scenario runs, live sessions, sweep
cases, the open-loop hover demo and the SSP export all build their parameters here.

* plant: the airframe's numbers (``Airframe.fmu_parameters``), the initial pose, then the
  caller's overrides;
* controller: the airframe numbers the controller also has (the names both FMUs share); for
  an airframe with a shipped airframe's rotors, that airframe's design-time S(0) and
  single-failure sets (``controller.polytope_cache.design_set_parameters``), for any other
  nothing: the controller derives them from its airframe parameters at initialization; the
  design's gains (``controller.fmu_parameters.block_parameters``; None keeps the gains
  compiled into the FMU, i.e. the shipped synthesis), then the caller's overrides.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from controller import controller_fmu
from controller.polytope_cache import design_set_parameters
from plant import Airframe
from plant.common.model_description import fmu_variables

Value = float | int | bool
Vec3 = tuple[float, float, float]


def _vec3(name: str, v: Sequence[float]) -> Vec3:
    if len(v) != 3:
        raise ValueError(f"{name} must have 3 elements, got {len(v)}")
    return (float(v[0]), float(v[1]), float(v[2]))


@dataclass(frozen=True)
class Pose:
    """The vehicle's initial pose (NED, m; Euler angles phi, theta, psi, rad) and velocity."""

    pos: Vec3 = (0.0, 0.0, -3.0)
    euler: Vec3 = (0.0, 0.0, 0.0)
    vel: Vec3 = (0.0, 0.0, 0.0)

    @staticmethod
    def of(pos: Sequence[float] = (0.0, 0.0, -3.0), euler: Sequence[float] = (0.0, 0.0, 0.0),
           vel: Sequence[float] = (0.0, 0.0, 0.0)) -> Pose:
        """A pose from any 3-sequences (checked to have 3 elements)."""
        return Pose(_vec3("pos", pos), _vec3("euler", euler), _vec3("vel", vel))


@dataclass
class StartValues:
    """Start values by FMU variable name, one dict per FMU."""

    plant: dict[str, Value] = field(default_factory=dict)
    controller: dict[str, Value] = field(default_factory=dict)


def plant_start_values(airframe: Airframe, pose: Pose = Pose(), *,
                       overrides: Mapping[str, Value] | None = None) -> dict[str, Value]:
    """The plant's: the airframe, the initial pose, then ``overrides``."""
    params: dict[str, Value] = dict(airframe.fmu_parameters())
    params.update(airframe.plant_parameters())
    for i in range(3):
        params[f"pos0[{i + 1}]"] = pose.pos[i]
        params[f"euler0[{i + 1}]"] = pose.euler[i]
        params[f"vel0[{i + 1}]"] = pose.vel[i]
    params.update(overrides or {})
    return params


def controller_start_values(airframe: Airframe, *,
                            design: Mapping[str, float] | None = None,
                            overrides: Mapping[str, Value] | None = None) -> dict[str, Value]:
    """The controller's: shared airframe numbers, the design-time force sets where the rotors
    are a shipped airframe's, the design's gains, then ``overrides``."""
    variables = fmu_variables(controller_fmu())
    params: dict[str, Value] = {k: v for k, v in airframe.fmu_parameters().items()
                                if k in variables and variables[k].causality == "parameter"}
    params.update(design_set_parameters(airframe))
    params.update(design or {})
    params.update(overrides or {})
    return params


def start_values(airframe: Airframe, pose: Pose = Pose(), *,
                 design: Mapping[str, float] | None = None, timing: bool = False,
                 plant_overrides: Mapping[str, Value] | None = None,
                 controller_overrides: Mapping[str, Value] | None = None,
                 plant_airframe: Airframe | None = None) -> StartValues:
    """Both FMUs' start values for a closed loop starting at ``pose``; ``timing`` switches
    on the FMUs' self-timing outputs.  ``plant_airframe``: the vehicle the plant flies when
    it is not ``airframe``, the one the controller is told (a model mismatch)."""
    flown = plant_airframe if plant_airframe is not None else airframe
    return StartValues(
        plant=plant_start_values(flown, pose, overrides={"timing": timing,
                                                            **(plant_overrides or {})}),
        controller=controller_start_values(airframe, design=design,
                                           overrides={"timing": timing,
                                                      **(controller_overrides or {})}))


def resting_on_ground(airframe: Airframe, pos: Sequence[float], yaw: float,
                      ground_z: float = 0.0) -> tuple[Pose, dict[str, Value]]:
    """The pose of a vehicle resting level on its landing gear on the ground at ``ground_z``
    below the point ``pos`` (its heading ``yaw``), and the plant overrides that start it
    there: no hover trim, every rotor stopped and its tilt at zero."""
    gear = airframe.gear
    if gear is None:
        raise ValueError(f"airframe {airframe.name} has no landing gear to rest on "
                         "([landing_gear] in its file, docs/airframes.md)")
    z = ground_z - gear.rest_height(airframe.mass, airframe.gravity)
    stopped: dict[str, Value] = {f"{a}0[{i + 1}]": 0.0 for a in ("omega", "alpha", "beta")
                                 for i in range(airframe.n_rotors)}
    return (Pose.of((float(pos[0]), float(pos[1]), z), (0.0, 0.0, float(yaw))),
            {"init_trim": False, **stopped})
