"""Controller design: force sets, robust gains, the allocation solver; the controller FMU."""

from pathlib import Path

from plant import find_artifact

CONTROLLER_FMU = "FullPoseController"
"""Model name of the controller FMU (``controller/fmus/FullPoseController.fmu``)."""


def controller_fmu(fmi: int = 2) -> Path:
    """Path of the installed (or ``FULLPOSE_BUILD_DIR``-built) FullPoseController FMU: FMI
    2.0, or with ``fmi=3`` the FMI 3.0 one (``fmus/fmi3/``)."""
    from plant import fmu_file

    return find_artifact("controller", "fmus", fmu_file(CONTROLLER_FMU, fmi))
