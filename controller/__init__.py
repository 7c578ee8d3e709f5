"""Controller design: force sets, robust gains, the allocation solver; the controller FMU."""

CONTROLLER_FMU = "FullPoseController"
"""Model name of the controller FMU (``controller/fmus/FullPoseController.fmu``)."""
