"""Benchmark: the bridge's pacing under load (prints figures, asserts nothing).

Three cases, each a bridge at speed 1 flying a position setpoint in OFFBOARD for
``--duration`` simulated seconds beside a 20 Hz ground station: the host idle, the host busy
(``--busy`` Python busy loops in other processes, default 2: both cores of the CI machine),
and busy with a fuzzer process sending ``--rate`` datagrams/s (default 2,500: random bytes,
mutated and truncated setpoints, NaN setpoints and valid setpoints, as the fuzz test of
tests/test_mavlink_bridge/test_mavlink_bridge.py).  Reported per run: the worst lag behind
wall time, chunks late by more than a chunk period, datagrams handled, the bridge thread's
CPU time per simulated second, and whether OFFBOARD survived (the ground station's
setpoints compete with the flood).  ``--count-only`` adds each case with input bounded by
count only (RX_TIME_LATE = RX_TIME_SHARE = inf), the comparison behind the time budget.

Usage: python tests/bench/bench_pacing.py [--duration 10] [--busy 2] [--rate 2500] [--repeat 3]
       [--count-only]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import os
import socket
import statistics
import sys
import threading
import time
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil

from mavlink_bridge import bridge as bridge_mod
from mavlink_bridge.bridge import Bridge, BridgeConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: the shared helpers
from helpers.mavlink_harness import POS_ONLY, fuzz_datagrams


def _busy(stop: mp.synchronize.Event) -> None:
    x = 0
    while not stop.is_set():
        for _ in range(10000):
            x += 1


def _fuzz(port: int, rate: float, stop: mp.synchronize.Event) -> None:
    datagrams = fuzz_datagrams(mavutil.mavlink.MAVLink(None, 255, 190))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    t0, sent = time.perf_counter(), 0
    while not stop.is_set():
        if sent > (time.perf_counter() - t0) * rate:
            time.sleep(0.0005)
            continue
        data = next(datagrams)
        try:
            sock.sendto(data, ("127.0.0.1", port))
        except OSError:
            pass
        sent += 1


def run_case(duration: float, busy: int, rate: float, budget: bool) -> dict[str, Any]:
    saved = bridge_mod.RX_TIME_LATE, bridge_mod.RX_TIME_SHARE
    if not budget:
        bridge_mod.RX_TIME_LATE = bridge_mod.RX_TIME_SHARE = math.inf
    gcs_port = _free_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{gcs_port}", source_system=255,
                                     source_component=190, dialect="common")
    b = Bridge(BridgeConfig(urls=[f"udpout:127.0.0.1:{gcs_port}"], speed=1.0,
                            duration=duration))
    dest = b.endpoints[0].sock.getsockname()[1]
    stop = mp.Event()
    procs = [mp.Process(target=_busy, args=(stop,), daemon=True) for _ in range(busy)]
    if rate > 0:
        procs.append(mp.Process(target=_fuzz, args=(dest, rate, stop), daemon=True))
    b.armed, b.mode, b.last_setpoint = True, "OFFBOARD", 0.0
    keep = threading.Event()

    def setpoints() -> None:  # a ground station streaming at 20 Hz from a thread
        while not keep.is_set():
            gcs.mav.set_position_target_local_ned_send(0, 1, 1, 1, POS_ONLY, 0.3, 0.0, -3.0,
                                                       0, 0, 0, 0, 0, 0, 0, 0)
            while gcs.recv_match(blocking=False) is not None:
                pass
            time.sleep(0.05)

    try:
        for p in procs:
            p.start()
        th = threading.Thread(target=setpoints, daemon=True)
        th.start()
        time.sleep(0.5)  # the load is up
        cpu0 = time.thread_time()
        stats = b.run()
        cpu = time.thread_time() - cpu0  # the bridge's own thread (the GCS thread apart)
        keep.set()
        th.join(2)
        return {"max_lag_ms": 1e3 * stats.max_lag, "late": stats.late_chunks,
                "cpu_ms_per_s": 1e3 * cpu / max(stats.sim_time, 1e-9),
                "chunks": stats.chunks, "datagrams": stats.datagrams,
                "speed": stats.achieved_speed,
                "lost": sum("offboard lost" in t for t in b.events), "mode": b.mode}
    finally:
        stop.set()
        for p in procs:
            p.join(5)
        b.close()
        gcs.close()
        bridge_mod.RX_TIME_LATE, bridge_mod.RX_TIME_SHARE = saved


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


CASES = (("idle", 0, 0.0), ("busy", None, 0.0), ("busy + fuzzer", None, None))
"""(name, busy processes (None: --busy), fuzz rate (None: --rate)) of each case."""


def main() -> None:
    """Run the cases, interleaved --repeat times, with the shipped input budget (and with
    --count-only, the count-only bound too); print a row per run and the summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="simulated s per case")
    parser.add_argument("--busy", type=int, default=2, help="busy-loop processes")
    parser.add_argument("--rate", type=float, default=2500.0, help="fuzz datagrams/s")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each case, interleaved")
    parser.add_argument("--count-only", action="store_true",
                        help="also run each case with input bounded by count only")
    args = parser.parse_args()
    print(f"host: {os.cpu_count()} cpus, load average {os.getloadavg()[0]:.2f} at start; "
          f"{args.duration:g} s per case at speed 1")
    print(f"{'case':14s} {'budget':10s} {'max lag ms':>10s} {'late chunks':>14s} "
          f"{'datagrams':>10s} {'cpu ms/s':>9s} {'speed':>6s}  mode (offboard losses)")
    results: dict[tuple[str, bool], list[dict[str, Any]]] = {}
    budgets = (True, False) if args.count_only else (True,)
    for _ in range(args.repeat):
        for name, busy, rate in CASES:
            busy = args.busy if busy is None else busy
            rate = args.rate if rate is None else rate
            for budget in budgets:
                r = run_case(args.duration, busy, rate, budget)
                results.setdefault((name, budget), []).append(r)
                print(f"{name:14s} {'time+count' if budget else 'count':10s} "
                      f"{r['max_lag_ms']:10.1f} {r['late']:6d}/{r['chunks']:<7d} "
                      f"{r['datagrams']:10d} {r['cpu_ms_per_s']:9.1f} {r['speed']:6.3f}  "
                      f"{r['mode']} ({r['lost']})", flush=True)
    print(f"\nover {args.repeat} runs; busy = {args.busy} busy-loop processes, fuzzer "
          f"{args.rate:g} datagrams/s; load average at end {os.getloadavg()[0]:.2f}")
    print(f"{'case':14s} {'budget':10s} {'worst lag ms':>12s} {'median':>8s} "
          f"{'bridge cpu ms per simulated s (mean)':>37s}")
    for (name, budget), rs in results.items():
        lags = sorted(r["max_lag_ms"] for r in rs)
        cpu = statistics.fmean(r["cpu_ms_per_s"] for r in rs)
        print(f"{name:14s} {'time+count' if budget else 'count':10s} {lags[-1]:12.1f} "
              f"{statistics.median(lags):8.1f} {cpu:37.1f}")


if __name__ == "__main__":
    main()
