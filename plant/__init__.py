"""Multirotor plant: airframes, rotor kinematics and effectiveness (C core), the plant FMU."""

from pathlib import Path

from plant.airframe import Airframe, AirframeError, list_airframes, load_airframe
from plant.common.artifacts import NativeBuildMissing, find_artifact
from plant.effectiveness import RotorSet, rotor_rotation, thrust_direction

PLANT_FMU = "MultirotorPlant"
"""Model name of the plant FMU (``plant/fmus/MultirotorPlant.fmu``)."""


def plant_fmu() -> Path:
    """Path of the installed (or ``FULLPOSE_BUILD_DIR``-built) MultirotorPlant FMU."""
    return find_artifact("plant", "fmus", f"{PLANT_FMU}.fmu")


__all__ = [
    "PLANT_FMU",
    "Airframe",
    "AirframeError",
    "NativeBuildMissing",
    "RotorSet",
    "find_artifact",
    "list_airframes",
    "load_airframe",
    "plant_fmu",
    "rotor_rotation",
    "thrust_direction",
]
