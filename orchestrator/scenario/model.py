"""The scenario as data: what to fly (references), on which airframe, under which
disturbances and faults, with which FMU parameter overrides; and the signals it gives the FMUs
at any time.  A :class:`Scenario` is made by the parser (:mod:`orchestrator.scenario.parser`)
and has passed the checks (:mod:`orchestrator.scenario.checks`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from orchestrator.scenario.mission import ScenarioMission
from orchestrator.scenario.signals import ZERO, Signal
from orchestrator.sim.outcome import LostCriteria
from plant import Airframe
from plant.airframe import MAX_ROTORS

ParamValue = float | int | bool
"""An FMU parameter's start value as a scenario sets it."""
Vec3 = tuple[Signal, Signal, Signal]
"""Three signals, one per axis (x, y, z or roll, pitch, yaw)."""
POSITION_AXES = ("x", "y", "z")
ATTITUDE_AXES = ("roll", "pitch", "yaw")
DISTURBANCES = {"force": "f_d", "torque": "tau_d", "acceleration": "a_d"}
"""Disturbance table -> the plant FMU input it drives."""


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
    # "air": start at the reference's pose at hover trim; "ground": resting level on the
    # landing gear below the reference's start, rotors stopped
    start: str = "air"
    # mission items flown by the mission executor instead of reference signals (position
    # and attitude are then the start pose, held until the executor takes over)
    mission: ScenarioMission | None = None
    # the FMI version of the FMUs flown (2 or 3: the same model code, the same results)
    fmi: int = 2

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
        """(position, Euler angles) to start from: the reference at t = 0 (with ``start =
        "ground"``: resting level on the landing gear below it, the reference's heading),
        unless the ``[plant]`` overrides set ``pos0[i]`` / ``euler0[i]``."""
        ref = self.references(np.zeros(1))
        pos, euler = ref["pos_ref"][0], ref["euler_ref"][0]
        gear = self.true_airframe.gear
        if self.start == "ground" and gear is not None:
            ground = float(self.plant_parameters.get("ground_z", 0.0))
            af = self.true_airframe
            pos[2] = ground - gear.rest_height(af.mass, af.gravity)
            euler[:2] = 0.0
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
            "start": self.start,
            "mission": None if self.mission is None else self.mission.summary(),
            "fmi": self.fmi,
            "faults": [vars(f) for f in self.faults],
            "plant_parameters": dict(self.plant_parameters),
            "controller_parameters": dict(self.controller_parameters),
        }


def _column_times(t: ArrayLike) -> np.ndarray:
    return np.asarray(t, dtype=np.float64).reshape(-1)


def _stack(axes: Vec3, t: np.ndarray, order: int) -> np.ndarray:
    if order == 0:
        return np.column_stack([s.value(t) for s in axes])
    return np.column_stack([s.derivative(t, order) for s in axes])
