"""Benchmark: several vehicles from one process (mavlink_bridge.fleet), paced at speed 1
(prints figures, asserts nothing).

For each N of ``--counts`` (default 1, 3, 5) a Fleet of N hovering vehicles, one thread each,
flies ``--duration`` simulated seconds at ``--speed`` (default 1) with PX4's endpoints moved to
free ports: the shared ground-station port and an API port per vehicle, all drained by a
sink in another process (as QGroundControl and MAVSDK would be; it reads and drops, so the
bridges' sends are real and cost the host what a ground station costs).  Reported per vehicle:
the worst lag behind wall time, chunks late by more than a chunk period, the achieved speed and
the vehicle thread's CPU time per simulated second; per run, the process's CPU share.
``--busy K`` adds K Python busy-loop processes for the runs (2: both cores of the CI host
busy, as tests/bench/bench_pacing.py's loaded case).

Usage: python tests/bench/bench_fleet.py [--duration 20] [--counts 1,3,5] [--speed 1]
       [--repeat 1] [--busy 0]
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing as mp
import os
import random
import socket
import sys
import time
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"

from mavlink_bridge.bridge import BridgeConfig
from mavlink_bridge.fleet import Fleet, fleet_configs

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: the shared helpers
from helpers.mavlink_harness import free_port

# hovering vehicles (a ground start would have them resting on the gear, disarmed)
AIR = {"start": "air"} if "start" in {f.name for f in dataclasses.fields(BridgeConfig)} else {}


def _free_run(n: int) -> int:
    """A port P with P .. P + n - 1 free on 127.0.0.1 (the API ports P + i)."""
    for _ in range(200):
        base = random.randrange(20000, 60000 - n)
        socks = []
        try:
            for k in range(n):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", base + k))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError(f"no run of {n} free UDP ports")


def _sink(ports: list[int], ready: Any, stop: Any) -> None:
    """Read and drop every datagram sent to ports until stop is set."""
    import select

    socks = []
    for port in ports:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", port))
        s.setblocking(False)
        socks.append(s)
    ready.set()
    while not stop.is_set():
        readable, _, _ = select.select(socks, [], [], 0.1)
        for s in readable:
            try:
                while True:
                    s.recvfrom(65535)
            except (BlockingIOError, OSError):
                pass


def _busy(stop: Any) -> None:
    x = 0
    while not stop.is_set():
        for _ in range(10000):
            x += 1


def run_fleet(count: int, duration: float, speed: float) -> dict[str, Any]:
    """One Fleet of count vehicles for duration simulated s: per-vehicle figures."""
    gcs, api = free_port(), _free_run(count)
    base = BridgeConfig(speed=speed, duration=duration, **AIR)
    configs = fleet_configs(base, count, [f"udpout:127.0.0.1:{gcs}",
                                          f"udpout:127.0.0.1:{api}+i"])
    ready, stop = mp.Event(), mp.Event()
    sink = mp.Process(target=_sink, args=([gcs, *range(api, api + count)], ready, stop),
                      daemon=True)
    sink.start()
    ready.wait(10)
    try:
        with Fleet(configs) as fleet:
            cpu0, wall0 = time.process_time(), time.perf_counter()
            fleet.run()
            cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
            vehicles = [{"sid": b.config.system_id, "max_lag_ms": 1e3 * b.stats.max_lag,
                         "late": b.stats.late_chunks, "chunks": b.stats.chunks,
                         "speed": b.stats.achieved_speed,
                         "cpu_ms_per_s": 1e3 * c / max(b.stats.sim_time, 1e-9)}
                        for b, c in zip(fleet.bridges, fleet.cpu_time, strict=True)]
    finally:
        stop.set()
        sink.join(5)
    return {"vehicles": vehicles, "cpu_share": cpu / wall}


def main() -> None:
    """Fly each count --repeat times, printing a row per vehicle and a summary per count."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, help="simulated s per run")
    parser.add_argument("--counts", default="1,3,5", help="fleet sizes, comma-separated")
    parser.add_argument("--speed", type=float, default=1.0, help="simulated s per wall s")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each count")
    parser.add_argument("--busy", type=int, default=0, help="busy-loop processes meanwhile")
    args = parser.parse_args()
    counts = [int(c) for c in args.counts.split(",")]
    print(f"host: {os.cpu_count()} cpus, load average {os.getloadavg()[0]:.2f} at start; "
          f"{args.duration:g} s per run at speed {args.speed:g}, {args.busy} busy loops")
    print(f"{'N':>3s} {'sys':>4s} {'max lag ms':>10s} {'late chunks':>14s} {'speed':>6s} "
          f"{'cpu ms/s':>9s}")
    summary = []
    stop = mp.Event()
    busy = [mp.Process(target=_busy, args=(stop,), daemon=True) for _ in range(args.busy)]
    for b in busy:
        b.start()
    try:
        for _ in range(args.repeat):
            for n in counts:
                r = run_fleet(n, args.duration, args.speed)
                for v in r["vehicles"]:
                    print(f"{n:3d} {v['sid']:4d} {v['max_lag_ms']:10.2f} "
                          f"{v['late']:6d}/{v['chunks']:<7d} {v['speed']:6.3f} "
                          f"{v['cpu_ms_per_s']:9.1f}", flush=True)
                summary.append((n, r))
    finally:
        stop.set()
        for b in busy:
            b.join(5)
    print(f"\nload average at end {os.getloadavg()[0]:.2f}")
    print(f"{'N':>3s} {'worst lag ms':>12s} {'late chunks':>12s} {'slowest speed':>14s} "
          f"{'process cpu share':>18s}")
    for n, r in summary:
        vs = r["vehicles"]
        print(f"{n:3d} {max(v['max_lag_ms'] for v in vs):12.2f} "
              f"{sum(v['late'] for v in vs):12d} {min(v['speed'] for v in vs):14.4f} "
              f"{100 * r['cpu_share']:17.1f}%")


if __name__ == "__main__":
    main()
