"""Multirotor plant: airframes, rotor kinematics and effectiveness (C core), the plant FMU."""

from pathlib import Path

from plant.airframe import Airframe, AirframeError, list_airframes, load_airframe
from plant.common.artifacts import NativeBuildMissing, find_artifact
from plant.effectiveness import RotorSet, rotor_rotation, thrust_direction

PLANT_FMU = "MultirotorPlant"
"""Model name of the plant FMU (``plant/fmus/MultirotorPlant.fmu``)."""


def plant_fmu(fmi: int = 2) -> Path:
    """Path of the installed (or ``FULLPOSE_BUILD_DIR``-built) MultirotorPlant FMU: FMI 2.0,
    or with ``fmi=3`` the FMI 3.0 one (``fmus/fmi3/``)."""
    return find_artifact("plant", "fmus", fmu_file(PLANT_FMU, fmi))


def fmu_file(model: str, fmi: int) -> str:
    """The file name of a model's FMU of FMI version ``fmi`` (2 or 3) in its folder."""
    if fmi not in (2, 3):
        raise ValueError(f"FMI version must be 2 or 3, got {fmi!r}")
    return f"{model}.fmu" if fmi == 2 else f"fmi3/{model}.fmu"


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
