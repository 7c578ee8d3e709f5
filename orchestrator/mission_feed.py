"""A scenario's mission fed to a run: before each control period the mission executor sees
the vehicle's latest state and writes the reference rows of the period into the recording.

The executor (:mod:`orchestrator.mission.executor`) is the one the MAVLink bridge flies
AUTO.MISSION with; it runs here at the bridge's rate (every :data:`PERIOD_ROWS` steps), on
the measured position and attitude and the controller's land detector, as it does there.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from orchestrator.mission.executor import Executor, Vehicle
from orchestrator.scenario.mission import ScenarioMission
from orchestrator.sim.engine import REF_INPUTS, Engine

PERIOD_ROWS = 5
"""Steps between two updates of the mission executor (10 ms at 2 ms, the bridge's chunk)."""
DISARM_AFTER = 2.0
"""s landed after a mission's end before the controller is disarmed (the bridge's default
COM_DISARM_LAND, as PX4's)."""


class MissionFeed:
    """The reference of a mission run, written into ``engine``'s recording period by period."""

    def __init__(self, engine: Engine, mission: ScenarioMission, home: np.ndarray,
                 euler0: np.ndarray) -> None:
        self.engine = engine
        rec = engine.rec
        settings = type(mission.settings)(**vars(mission.settings))  # a DO_CHANGE_SPEED
        self.executor = Executor(mission.items, settings, np.array(home, float),  # changes it
                                 np.array(euler0, float), home=np.array(home, float))
        self._pos = rec.columns_of("plant.pos")
        self._euler = rec.columns_of("plant.euler")
        self._landed = rec.int_columns.index("ctrl.landed")
        self.landed_since = math.inf  # s: landed continuously since, after the mission's end
        self.disarmed_at: float | None = None
        widths = [len(b) for b in engine.conn.ref]
        self._ref_cols = dict(zip(REF_INPUTS, np.cumsum([0, *widths[:-1]]), strict=True))

    def fill(self, first: int, stop: int, h: float) -> None:
        """The reference rows first..stop-1 from the vehicle's state at row first (the
        controller's land detector as it answered row first - 1)."""
        rec = self.engine.rec
        row = rec.data[first]
        landed_row = rec.spare if first == 0 else first - 1
        vehicle = Vehicle(row[self._pos].copy(), row[self._euler].copy(),
                          bool(rec.ints[landed_row, self._landed]))
        ref = self.executor.update(first * h, vehicle)
        self._disarm(first * h, vehicle.landed)
        block = rec.ref
        end = min(stop + 1, rec.rows)  # the next row too: the last row keeps the last one
        for name, col in self._ref_cols.items():
            if name in ref:
                block[first:end, col:col + 3] = ref[name]
        # between two updates the carrot moves on along its leg: the reference is continuous,
        # not a staircase of 10 ms treads
        pos, vel, acc = (self._ref_cols[k] for k in ("pos_ref", "vel_ref", "acc_ref"))
        for row in range(first + 1, end):
            p, v, a = self.executor.sample(row * h)
            block[row, pos:pos + 3], block[row, vel:vel + 3], block[row, acc:acc + 3] = p, v, a

    def _disarm(self, t: float, landed: bool) -> None:
        """A mission that ended on the ground disarms DISARM_AFTER later, as the bridge does:
        the controller's ``armed`` input (held through a run) set false, the rotors stop."""
        if self.disarmed_at is not None or self.engine.ctrl is None:
            return
        if not (self.executor.finished and landed):
            self.landed_since = math.inf
            return
        self.landed_since = min(self.landed_since, t)
        if t - self.landed_since >= DISARM_AFTER - 1e-9:
            self.engine.ctrl.set("armed", False)
            self.disarmed_at = t

    def record(self) -> dict[str, Any]:
        """What the mission did, for the run's metadata: each leg (seq, command, start,
        reached, end; None: not reached / not ended) and the events."""
        def num(x: float) -> float | None:
            return None if math.isnan(x) else float(x)

        ex = self.executor
        return {"finished": ex.finished, "disarmed": self.disarmed_at,
                "legs": [{"seq": leg.seq, "command": leg.name, "start": leg.start,
                          "reached": num(leg.reached), "end": num(leg.end)} for leg in ex.legs],
                "events": [{"time": e.time, "kind": e.kind, "seq": e.seq, "text": e.text}
                           for e in ex.events]}
