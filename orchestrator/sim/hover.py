"""Open-loop hover demo: the plant FMU alone, actuators held at hover trim.

This is the first main job of the product (before the controller exists): it
exercises the installed plant FMU end to end and reports how well the trim
holds.  The plant starts at trim (init_trim) and its measured actuator states
are held as its commands, stepped by the same C engine as every closed loop.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from orchestrator.sim.engine import Connections, Recording, make_engine
from orchestrator.sim.fmu import FmuInstance
from orchestrator.sim.start_values import Pose, plant_start_values
from plant import load_airframe, plant_fmu

STEP = 0.002  # s, the co-simulation rate of 500 Hz
COMMANDS = ("omega_cmd", "alpha_cmd", "beta_cmd")
OUTPUTS = ("pos", "vel", "euler")


@dataclass
class HoverSummary:
    """What the open-loop hover demo reports: the airframe, duration, steps and the largest
    position and attitude drifts."""
    airframe: str
    duration: float
    steps: int
    max_position_drift_m: float
    max_attitude_drift_rad: float
    final_position_m: list[float]
    hover_omega_rad_s: list[float]
    wall_time_s: float
    real_time_factor: float


def run_hover(airframe: str = "paper_hexacopter", duration: float = 10.0,
              out_dir: Path | None = None, pos0: tuple[float, float, float] = (0.0, 0.0, -3.0),
              ) -> tuple[HoverSummary, np.ndarray]:
    """Simulate hover at trim; returns the summary and the recorded table."""
    if not duration > 0:
        raise ValueError(f"duration must be positive, got {duration}")
    af = load_airframe(airframe)
    params = plant_start_values(af, Pose.of(pos0), overrides={"init_trim": True})
    n = af.n_rotors
    steps = round(duration / STEP)
    with FmuInstance(plant_fmu(), "plant") as fmu:
        conn = Connections.open_loop(fmu, COMMANDS)
        rec = Recording(conn, steps + 1)
        engine = make_engine("native", fmu, None, conn, rec, STEP)
        engine.initialize(params, {}, np.zeros(0))
        # the commands: the trim the plant initialized to, held; the disturbances at rest
        rec.commands[:] = rec.plant[0, [conn.plant_out.index(c.replace("_cmd[", "["))
                                        for c in conn.commands]]
        rec.dist[:] = [float(fmu.variables[v].start) for v in conn.dist_names]
        rec.time[:] = np.arange(steps + 2) * STEP
        t0 = time.perf_counter()
        engine.steps(0, steps, 0.0)
        wall = time.perf_counter() - t0
        trim = rec.commands[0, :n]
        blocks = [rec.columns_of(f"plant.{g}") for g in OUTPUTS]
        outputs = [c for b in blocks for c in range(b.start, b.stop)]
        table = rec.data[:steps + 1][:, [0, *outputs]].copy()
        names = ["time", *(rec.columns[c].split(".", 1)[1] for c in outputs)]
    drift = np.linalg.norm(table[:, 1:4] - np.asarray(pos0), axis=1)
    summary = HoverSummary(
        airframe=af.name,
        duration=steps * STEP,
        steps=steps,
        max_position_drift_m=float(drift.max()),
        max_attitude_drift_rad=float(np.abs(table[:, 7:10]).max()),
        final_position_m=[float(x) for x in table[-1, 1:4]],
        hover_omega_rad_s=[float(x) for x in trim[:n]],
        wall_time_s=wall,
        real_time_factor=steps * STEP / wall if wall > 0 else float("inf"),
    )
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        with open(out_dir / "hover.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(names)
            w.writerows(table.tolist())
        (out_dir / "hover_summary.json").write_text(json.dumps(asdict(summary), indent=2) + "\n")
    return summary, table
