"""Multirotor plant: airframes, effectiveness matrices (C core), FMU location."""

from plant._native import NativeBuildMissing, fmu_path
from plant.airframe import Airframe, AirframeError, list_airframes, load_airframe
from plant.effectiveness import RotorSet, rotor_rotation, thrust_direction

PLANT_FMU = "MultirotorPlant"


def plant_fmu_path() -> str:
    """Filesystem path of the installed MultirotorPlant FMU."""
    return str(fmu_path(PLANT_FMU))


__all__ = [
    "PLANT_FMU",
    "Airframe",
    "AirframeError",
    "NativeBuildMissing",
    "RotorSet",
    "fmu_path",
    "list_airframes",
    "load_airframe",
    "plant_fmu_path",
    "rotor_rotation",
    "thrust_direction",
]
