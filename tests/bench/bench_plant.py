"""Benchmark: plant FMU cost per 2 ms step (prints figures, asserts nothing).

Side by side in one run, on the same FMU and the same hover:
  raw ctypes   fmi2DoStep called straight through ctypes (the FMU's own cost + one call)
  low-level    fmpy FMU2Slave: setReal(commands) + doStep + getReal(outputs) per step
  buffered     the same fmpy low-level functions (slave.fmi2SetReal, ...) with ctypes
               buffers built once, as the orchestrator calls them
  high-level   fmpy.simulate_fmu with a 2 ms output interval (per-step time from its
               step_finished callback)

Usage: python tests/bench/bench_plant.py [--seconds 20]
"""

from __future__ import annotations

import argparse
import ctypes
import time

import numpy as np
from fmpy import simulate_fmu

from orchestrator.sim.fmu import FmuInstance
from plant import plant_fmu

H = 0.002


def stats(name: str, ns: np.ndarray) -> dict[str, float]:
    us = ns / 1e3
    row = {"mean": float(us.mean()), "p99": float(np.percentile(us, 99)), "max": float(us.max())}
    print(f"{name:12s} mean {row['mean']:8.2f} us   p99 {row['p99']:8.2f} us   "
          f"max {row['max']:9.2f} us   ({ns.size} steps)")
    return row


def bench_raw(steps: int) -> np.ndarray:
    with FmuInstance(plant_fmu(), "raw") as fmu:
        fmu.initialize()
        do_step = fmu.slave.dll.fmi2DoStep
        do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
        do_step.restype = ctypes.c_int
        comp = fmu.slave.component
        out = np.empty(steps, dtype=np.int64)
        t = 0.0
        clock = time.perf_counter_ns
        for k in range(steps):
            t0 = clock()
            if do_step(comp, t, H, 1) != 0:
                raise RuntimeError("fmi2DoStep failed")
            out[k] = clock() - t0
            t = (k + 1) * H
    return out


def bench_low_level(steps: int) -> np.ndarray:
    with FmuInstance(plant_fmu(), "low") as fmu:
        fmu.initialize()
        meas = fmu.signal(["omega", "alpha", "beta"])
        cmd = fmu.signal(["omega_cmd", "alpha_cmd", "beta_cmd"])
        outputs = fmu.signal(["pos", "vel", "acc", "euler", "quat", "rate", "ang_acc", "omega",
                              "alpha", "beta", "f_b", "tau_b"])
        trim = list(fmu.read(meas))
        slave = fmu.slave
        out = np.empty(steps, dtype=np.int64)
        clock = time.perf_counter_ns
        for k in range(steps):
            t0 = clock()
            slave.setReal(cmd.refs, trim)
            slave.doStep(k * H, H)
            slave.getReal(outputs.refs)
            out[k] = clock() - t0
    return out


def bench_buffered(steps: int) -> np.ndarray:
    with FmuInstance(plant_fmu(), "buffered") as fmu:
        fmu.initialize()
        meas = fmu.signal(["omega", "alpha", "beta"])
        cmd = fmu.signal(["omega_cmd", "alpha_cmd", "beta_cmd"])
        outputs = fmu.signal(["pos", "vel", "acc", "euler", "quat", "rate", "ang_acc", "omega",
                              "alpha", "beta", "f_b", "tau_b"])
        trim = fmu.read(meas)
        cmd_values = (ctypes.c_double * len(cmd.names))(*trim)
        out_values = (ctypes.c_double * len(outputs.names))()
        slave = fmu.slave
        comp = slave.component
        set_real, get_real, do_step = slave.fmi2SetReal, slave.fmi2GetReal, slave.fmi2DoStep
        n_cmd, n_out = len(cmd.names), len(outputs.names)
        out = np.empty(steps, dtype=np.int64)
        clock = time.perf_counter_ns
        for k in range(steps):
            t0 = clock()
            set_real(comp, cmd.refs, n_cmd, cmd_values)
            do_step(comp, k * H, H, 1)
            get_real(comp, outputs.refs, n_out, out_values)
            out[k] = clock() - t0
    return out


def bench_high_level(steps: int) -> np.ndarray:
    stamps: list[int] = []
    clock = time.perf_counter_ns

    def step_finished(*_: object) -> bool:
        stamps.append(clock())
        return True

    simulate_fmu(str(plant_fmu()), stop_time=steps * H, step_size=H,
                 output_interval=H, fmi_type="CoSimulation", step_finished=step_finished)
    return np.diff(np.asarray(stamps, dtype=np.int64))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated time per run")
    args = parser.parse_args()
    steps = int(args.seconds / H)
    print(f"MultirotorPlant, paper hexacopter at hover, {steps} steps of 2 ms "
          f"(internal RK4 step 0.5 ms)")
    raw = stats("raw ctypes", bench_raw(steps))
    low = stats("low-level", bench_low_level(steps))
    buf = stats("buffered", bench_buffered(steps))
    high = stats("high-level", bench_high_level(steps))
    print(f"ratios (mean): low-level/raw {low['mean'] / raw['mean']:.1f}x, "
          f"buffered/raw {buf['mean'] / raw['mean']:.1f}x, "
          f"high-level/low-level {high['mean'] / low['mean']:.2f}x")
    print(f"real-time factor of the plant alone: raw {H * 1e6 / raw['mean']:.0f}x, "
          f"buffered {H * 1e6 / buf['mean']:.0f}x, low-level {H * 1e6 / low['mean']:.0f}x")


if __name__ == "__main__":
    main()
