"""When a run counts as lost, and how that is found in the recording.

A diverged closed loop must not end with exit 0 and a "max position error" of hundreds of
metres: the master checks every chunk of recorded rows and stops at the first row where the
vehicle is lost.  The bounds are scenario fields (``[lost]``, docs/scenarios.md); the
defaults are far outside anything a working controller does on the shipped airframes and far
inside divergence:

* position error |xi - xi_ref| > 10 m, xi_ref the reference the controller flies (its shaped
  reference where it records one: a step is flown within limits, not counted as an error;
  the shipped scenarios stay within centimetres of it);
* tilt (angle between body z and world z, cos = cos(phi) cos(theta)) > 90 deg: upside down,
  beyond what the controller's Euler bounds (+-60 deg each: at most 75.5 deg) command;
* any non-finite plant output or controller command.

The recording then ends at the lost sample, or, when that sample is not finite, at the last
finite one before it (so every recorded number stays finite); the reported time is the lost
sample's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

DEFAULT_POSITION_ERROR = 10.0
"""m: default bound on |xi - xi_ref|."""
DEFAULT_TILT_DEG = 90.0
"""deg: default bound on the tilt of the body z axis from the world z axis."""

EXIT_LOST = 3
"""CLI exit status of a run that lost the vehicle (2: bad input or an FMU error)."""


@dataclass(frozen=True)
class LostCriteria:
    """Bounds beyond which the vehicle counts as lost."""

    position_error: float = DEFAULT_POSITION_ERROR  # m
    tilt_deg: float = DEFAULT_TILT_DEG  # deg

    def summary(self) -> dict[str, float]:
        """The criteria as JSON-ready data."""
        return {"position_error": self.position_error, "tilt_deg": self.tilt_deg}


@dataclass(frozen=True)
class Lost:
    """The first row where the vehicle was lost, its time and why."""

    row: int
    time: float
    reason: str
    nonfinite: bool = False  # the row itself is not finite (the recording ends before it)

    def summary(self) -> dict[str, Any]:
        """The outcome as JSON-ready data."""
        return {"outcome": "lost", "time": self.time, "reason": self.reason}


def first_lost(time: np.ndarray, pos: np.ndarray, pos_ref: np.ndarray, euler: np.ndarray,
               finite: np.ndarray, criteria: LostCriteria) -> Lost | None:
    """The first lost row of a block of rows, or None.

    ``pos``, ``pos_ref``, ``euler``: (n, 3); ``finite``: (n,) whether every plant output and
    controller command of the row is finite.
    """
    with np.errstate(invalid="ignore"):
        err = np.linalg.norm(pos - pos_ref, axis=1)
        cos_tilt = np.cos(euler[:, 0]) * np.cos(euler[:, 1])
        tilt = np.degrees(np.arccos(np.clip(cos_tilt, -1.0, 1.0)))
        far = err > criteria.position_error
        tilted = tilt > criteria.tilt_deg
    bad = ~finite | far | tilted
    if not np.any(bad):
        return None
    k = int(np.argmax(bad))
    if not finite[k]:
        reason = "non-finite state (the simulation diverged)"
    elif far[k]:
        reason = (f"position error {err[k]:.4g} m exceeds the bound "
                  f"{criteria.position_error:g} m")
    else:
        reason = f"tilt {tilt[k]:.1f} deg exceeds the bound {criteria.tilt_deg:g} deg"
    return Lost(row=k, time=float(time[k]), reason=reason, nonfinite=not finite[k])

