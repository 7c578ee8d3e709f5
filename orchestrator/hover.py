"""Open-loop hover demo: the plant FMU alone, actuators held at hover trim.

This is the first main job of the product (before the controller exists): it
exercises the installed plant FMU end to end and reports how well the trim
holds.  The plant starts at trim (init_trim) and its measured actuator states
are fed back as constant commands.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from orchestrator.fmu import FmuInstance
from plant import fmu_path, load_airframe

STEP = 0.002  # s, the co-simulation rate of 500 Hz


@dataclass
class HoverSummary:
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
    params = af.fmu_parameters()
    params.update({f"pos0[{i + 1}]": v for i, v in enumerate(pos0)})
    params["init_trim"] = True
    n = af.n_rotors
    steps = round(duration / STEP)
    with FmuInstance(fmu_path("MultirotorPlant"), "plant") as fmu:
        fmu.initialize(parameters=params)
        meas = fmu.signal(["omega", "alpha", "beta"])
        cmd = fmu.signal(["omega_cmd", "alpha_cmd", "beta_cmd"])
        outputs = fmu.signal(["pos", "vel", "euler"])
        trim = fmu.read(meas).copy()
        fmu.write(cmd, trim)
        table = np.empty((steps + 1, 1 + outputs.values.size))
        table[0, 0] = 0.0
        table[0, 1:] = fmu.read(outputs)
        t0 = time.perf_counter()
        for k in range(1, steps + 1):
            fmu.step(STEP)
            table[k, 0] = k * STEP
            table[k, 1:] = fmu.read(outputs)
        wall = time.perf_counter() - t0
    names = ["time", *outputs.names]
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
