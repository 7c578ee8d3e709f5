"""Controller design: force sets, robust gains, the allocation solver; the controller FMU."""

from pathlib import Path

from plant import find_artifact

CONTROLLER_FMU = "FullPoseController"
"""Model name of the controller FMU (``controller/fmus/FullPoseController.fmu``)."""


def controller_fmu() -> Path:
    """Path of the installed (or ``FULLPOSE_BUILD_DIR``-built) FullPoseController FMU."""
    return find_artifact("controller", "fmus", f"{CONTROLLER_FMU}.fmu")
