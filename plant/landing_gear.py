"""The landing gear: contact points and their contact law, from an airframe file's
``[landing_gear]`` table, as the plant FMU's contact parameters (``fmu_src/plant/contact.h``).

    [landing_gear]
    points = [[0.1, 0.1, 0.1], [0.1, -0.1, 0.1], [-0.1, -0.1, 0.1], [-0.1, 0.1, 0.1]]  # m, FRD
    stiffness = 816      # N/m per point
    damping = 23         # N s/m per point
    friction = 0.5       # Coulomb coefficient

Choosing the numbers (docs/plant.md, "Ground contact"): for n points carrying the weight m g,
the static penetration is m g / (n k) and the heave mode's damping ratio c sqrt(n / (k m)) / 2
(1: critically damped, no bounce).  The plant refuses a contact too stiff for its RK4 step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from plant.common.toml_reader import TomlTable

MAX_CONTACTS = 8
"""Contact points the plant FMU takes (``PLANT_MAX_CONTACTS``)."""


@dataclass(frozen=True)
class LandingGear:
    """Contact points (body FRD, m; z > 0 is below the centre of gravity) and the contact
    law of each: stiffness (N/m), damping (N s/m), Coulomb friction coefficient."""

    points: np.ndarray  # (k, 3)
    stiffness: float
    damping: float
    friction: float

    def plant_parameters(self) -> dict[str, float | int]:
        """The plant FMU's contact parameters (``n_contacts``, ``contact_pos[i,j]``, ...)."""
        p: dict[str, float | int] = {"n_contacts": len(self.points),
                                     "contact_stiffness": self.stiffness,
                                     "contact_damping": self.damping,
                                     "contact_friction": self.friction}
        for i in range(MAX_CONTACTS):
            for j in range(3):
                p[f"contact_pos[{i + 1},{j + 1}]"] = (float(self.points[i, j])
                                                      if i < len(self.points) else 0.0)
        return p

    def rest_height(self, mass: float, gravity: float) -> float:
        """How far above the ground the centre of gravity rests, level, on the lowest points
        (each sinking m g / (n k) under the weight shared by the n of them)."""
        lowest = float(self.points[:, 2].max())
        n = int(np.sum(self.points[:, 2] >= lowest - 1e-12))
        return lowest - mass * gravity / (n * self.stiffness)

    def record(self) -> dict[str, Any]:
        """JSON-ready numbers (``Airframe.record``)."""
        return {"points": self.points.tolist(), "stiffness": self.stiffness,
                "damping": self.damping, "friction": self.friction}

    @staticmethod
    def from_record(doc: dict[str, Any]) -> LandingGear:
        """The inverse of :meth:`record` (ValueError when malformed)."""
        points = np.array(doc["points"], dtype=float)
        if points.ndim != 2 or points.shape[1] != 3 or not 1 <= len(points) <= MAX_CONTACTS:
            raise ValueError(f"landing_gear.points: expected 1..{MAX_CONTACTS} points of 3")
        return LandingGear(points, float(doc["stiffness"]), float(doc["damping"]),
                           float(doc["friction"]))


NO_GEAR: dict[str, float | int] = {"n_contacts": 0}
"""The plant's contact parameters of an airframe without landing gear (no ground)."""


def parse_landing_gear(table: TomlTable) -> LandingGear:
    """The ``[landing_gear]`` table of an airframe file; errors name the field."""
    raw = table.raw("points")
    if (not isinstance(raw, list) or not 1 <= len(raw) <= MAX_CONTACTS
            or not all(isinstance(p, list) and len(p) == 3 for p in raw)):
        raise table.fail("points", f"expected 1..{MAX_CONTACTS} points [x, y, z] (m, body "
                         f"FRD), got {raw!r}")
    values = [v for p in raw for v in p]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool)
               and math.isfinite(float(v)) for v in values):
        raise table.fail("points", "expected finite numbers")
    points = np.array(raw, dtype=float)
    if not np.any(points[:, 2] > 0):
        raise table.fail("points", "no point lies below the centre of gravity (z > 0 in FRD): "
                         "the vehicle would rest on its body")
    gear = LandingGear(points, table.number("stiffness", positive=True),
                       table.number("damping", nonnegative=True),
                       table.number("friction", 0.5, nonnegative=True))
    return gear
