"""Several vehicles from one `fullpose fly` (mavlink_bridge/fleet.py, docs/mavlink.md "Several
vehicles"): PX4 SITL's numbering (system id i+1, the shared ground-station port, API port
base+i), each vehicle flown to its own pose over real UDP while messages for one are ignored by
the others, MAVSDK telling them apart, the CLI, and a failing vehicle stopping the fleet.  The
vehicles run in threads of the test process (a `fullpose fly` subprocess for the CLI); ports
are picked free at runtime and every wait is bounded in wall time."""

import dataclasses
import math
import os
import random
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"

from helpers.mavlink_harness import free_port
from pymavlink import mavutil

from mavlink_bridge.bridge import BridgeConfig
from mavlink_bridge.fleet import (
    DEFAULT_URLS,
    MAX_VEHICLES,
    Fleet,
    FleetError,
    fleet_configs,
    instance_urls,
)
from mavlink_bridge.geodesy import Origin
from mavlink_bridge.setpoints import Limits

pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

ROOT = Path(__file__).resolve().parents[2]

# these tests fly from a hover: if BridgeConfig can start on the ground, ask for the air
AIR = {"start": "air"} if "start" in {f.name for f in dataclasses.fields(BridgeConfig)} else {}
POS0 = (0.0, 0.0, -3.0)
POS_YAW = 0b1001_1111_1000  # x, y, z and yaw used (velocity, acceleration, yaw rate ignored)

TARGETS = {1: (1.0, 0.5, -3.5, 0.3), 2: (-0.5, 1.0, -3.0, -0.5), 3: (0.5, -1.0, -4.0, 1.0)}
"""system id -> (x, y, z, yaw) each vehicle is sent to, in its own local frame."""


def free_port_run(n: int) -> int:
    """A port P with P .. P + n - 1 free on 127.0.0.1 (as the API ports base+i are)."""
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
    raise AssertionError(f"no run of {n} free UDP ports")


def test_configs_follow_px4_numbering_and_carry_every_other_field():
    base = BridgeConfig(pos0=(0.5, -1.0, -2.5), euler0=(0.0, 0.0, 0.4), speed=3.0,
                        duration=7.0, signing_key=bytes(range(32)),
                        bridge_parameters={"FPB_SP_XY_MAX": 50.0},
                        origin=Origin(46.5, 6.5, 400.0), limits=Limits(), **AIR)
    configs = fleet_configs(base, 3)
    assert [c.system_id for c in configs] == [1, 2, 3]
    assert [list(c.urls) for c in configs] == [
        ["udpout:127.0.0.1:14550", f"udpout:127.0.0.1:{14540 + i}"] for i in range(3)]
    # the first vehicle is the single vehicle `fullpose fly` flies (its default endpoints)
    assert configs[0].urls == ["udpout:127.0.0.1:14550", "udpout:127.0.0.1:14540"]
    for i, c in enumerate(configs):
        # every vehicle at the same local pose, its local frame's origin 2 m east per instance
        # at the same altitude (d: the Earth's curvature, 1.25 um at 4 m)
        n, e, d = base.origin.to_ned(c.origin.lat, c.origin.lon, c.origin.alt)
        assert abs(n) < 1e-6 and abs(e - 2.0 * i) < 1e-6 and abs(d) < 1e-5, (n, e, d)
        assert c.origin.alt == base.origin.alt
        for f in dataclasses.fields(BridgeConfig):  # any other field, a new one too
            if f.name not in ("system_id", "urls", "origin"):
                assert getattr(c, f.name) == getattr(base, f.name), f.name
        assert c.limits is not base.limits  # updated in place from FPB_ parameters
    assert configs[1].limits is not configs[2].limits
    # explicit endpoints: PORT+i per instance, any other URL shared
    urls = ["udpout:10.0.0.5:14550", "udpin:0.0.0.0:24540+i", "udpout:127.0.0.1:5000+i"]
    assert instance_urls(urls, 2) == ["udpout:10.0.0.5:14550", "udpin:0.0.0.0:24542",
                                      "udpout:127.0.0.1:5002"]
    assert [c.urls for c in fleet_configs(base, 2, urls)][1] == instance_urls(urls, 1)
    assert len(fleet_configs(base, MAX_VEHICLES, ["udpout:127.0.0.1:30000+i"])) == MAX_VEHICLES
    for count, templates, why in (
            (0, DEFAULT_URLS, "between 1 and"), (MAX_VEHICLES + 1, DEFAULT_URLS, "between 1 and"),
            (11, DEFAULT_URLS, "14550 is also the shared one"),  # 14540+10 = the GCS port
            (2, ["udpin:127.0.0.1:14550"], "cannot share its port"),
            (3, ["udpout:127.0.0.1:5000+i", "udpout:127.0.0.1:5001+i"], "5001 is also system 1's")):
        with pytest.raises(ValueError, match=why):
            fleet_configs(base, count, templates)


class Ground:
    """One ground station on the shared GCS port (it hears every vehicle and, as
    QGroundControl does, sends to all of them) and an offboard script per vehicle on its
    API port, all pymavlink over UDP."""

    def __init__(self, gcs_port: int, api_base: int, count: int) -> None:
        def listen(port: int) -> mavutil.mavfile:
            return mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255,
                                              source_component=190, dialect="common")

        self.gcs = listen(gcs_port)
        self.api = [listen(api_base + i) for i in range(count)]
        self.vehicles: list[tuple[str, int]] = []  # the vehicles' GCS endpoint addresses
        self.api_sources: list[set[int]] = [set() for _ in range(count)]
        self.gcs_heartbeats: set[int] = set()
        self.gcs_ack_sources: set[int] = set()
        self.latest: dict[tuple[int, str], object] = {}  # (system id, type) -> message
        self.acks: list[tuple[int, int, int]] = []  # (link: api index or -1, command, result)

    def close(self) -> None:
        for c in [self.gcs, *self.api]:
            c.close()

    def pump(self) -> None:
        """Everything received so far, sorted by link and sender."""
        for link, conn in [(-1, self.gcs), *enumerate(self.api)]:
            while (m := conn.recv_match(blocking=False)) is not None:
                kind, src = m.get_type(), m.get_srcSystem()
                if kind == "BAD_DATA":
                    continue
                if link >= 0:
                    self.api_sources[link].add(src)
                    self.latest[(src, kind)] = m
                elif kind == "HEARTBEAT":
                    self.gcs_heartbeats.add(src)
                if kind == "COMMAND_ACK":
                    self.acks.append((link, m.command, m.result))
                    if link < 0:
                        self.gcs_ack_sources.add(src)

    def poses(self) -> dict[int, tuple[float, ...]]:
        """The latest (x, y, z, yaw) each vehicle reported (for a failure's message)."""
        out = {}
        for sid in TARGETS:
            lp = self.latest.get((sid, "LOCAL_POSITION_NED"))
            att = self.latest.get((sid, "ATTITUDE"))
            if lp is not None and att is not None:
                out[sid] = tuple(round(v, 3) for v in (lp.x, lp.y, lp.z, att.yaw))
        return out

    def broadcast(self, msg) -> None:
        """From the GCS port to every vehicle (QGroundControl's UDP link sends each message
        to all the hosts it heard)."""
        data = msg.pack(self.gcs.mav)
        for addr in self.vehicles:
            self.gcs.port.sendto(data, addr)

    def setpoint(self, mav, sid: int):
        x, y, z, yaw = TARGETS[sid]
        return mav.set_position_target_local_ned_encode(0, sid, 1, 1, POS_YAW, x, y, z,
                                                        0, 0, 0, 0, 0, 0, yaw, 0)

    def command(self, mav, sid: int, cmd: int, *params: float):
        p = list(params) + [0.0] * (7 - len(params))
        return mav.command_long_encode(sid, 1, cmd, 0, *p)

    def tick(self) -> None:
        """Vehicles 1 and 3 get their setpoints on their API ports, vehicle 2 on the shared
        GCS port, sent to all three."""
        for i, sid in ((0, 1), (2, 3)):
            self.api[i].mav.send(self.setpoint(self.api[i].mav, sid))
        self.broadcast(self.setpoint(self.gcs.mav, 2))
        self.pump()

    def until(self, seconds: float, done) -> bool:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.tick()
            if done():
                return True
            time.sleep(0.05)
        return False


def test_three_vehicles_fly_to_their_own_poses_on_one_gcs_link():
    gcs_port, api_base = free_port(), free_port_run(3)
    base = BridgeConfig(pos0=POS0, speed=2.0, duration=120.0, **AIR)
    urls = [f"udpout:127.0.0.1:{gcs_port}", f"udpout:127.0.0.1:{api_base}+i"]
    g = Ground(gcs_port, api_base, 3)
    try:
        with Fleet(fleet_configs(base, 3, urls)) as fleet:
            g.vehicles = [b.endpoints[0].sock.getsockname() for b in fleet.bridges]
            fleet.start()
            # each vehicle on its own API port, all three on the shared GCS port
            assert g.until(10.0, lambda: g.gcs_heartbeats == {1, 2, 3} and all(
                (i + 1, "GLOBAL_POSITION_INT") in g.latest for i in range(3))), (
                g.gcs_heartbeats, g.api_sources)
            assert g.api_sources == [{1}, {2}, {3}]
            for i in range(3):  # side by side: 2 m east of one another, at one local pose
                gp = g.latest[(i + 1, "GLOBAL_POSITION_INT")]
                n, e, d = base.origin.to_ned(gp.lat * 1e-7, gp.lon * 1e-7, gp.alt * 1e-3)
                assert math.dist((n, e, d), (POS0[0], POS0[1] + 2.0 * i, POS0[2])) < 0.01, gp
            # arm and OFFBOARD: 1 and 3 over their API ports, 2 over the GCS port broadcast
            # to all (1 and 3 must ignore what is addressed to 2)
            for cmd, params in ((400, (1,)), (176, (1, 6, 0))):
                for i, sid in ((0, 1), (2, 3)):
                    g.api[i].mav.send(g.command(g.api[i].mav, sid, cmd, *params))
                g.broadcast(g.command(g.gcs.mav, 2, cmd, *params))
                assert g.until(5.0, lambda c=cmd: sorted(
                    link for link, command, result in g.acks
                    if command == c and result == 0) == [-1, 0, 2]), g.acks
            assert g.gcs_ack_sources == {2}  # no answer from 1 or 3 to what was 2's
            assert [b.mode for b in fleet.bridges] == ["OFFBOARD"] * 3
            assert all(b.armed for b in fleet.bridges)

            def reached() -> bool:
                for sid, (x, y, z, yaw) in TARGETS.items():
                    lp = g.latest.get((sid, "LOCAL_POSITION_NED"))
                    att = g.latest.get((sid, "ATTITUDE"))
                    if lp is None or att is None:
                        return False
                    if math.dist((lp.x, lp.y, lp.z), (x, y, z)) >= 0.05 or \
                            abs(att.yaw - yaw) >= math.radians(1.0):
                        return False
                return True

            assert g.until(40.0, reached), g.poses()
            time.sleep(0.5)  # settled, not passing through
            g.latest.clear()
            assert g.until(5.0, reached)
            for b in fleet.bridges:
                x, y, z, _ = TARGETS[b.config.system_id]
                assert math.dist(b.session.state()["plant"]["pos"], (x, y, z)) < 0.05
            # 1 and 3 received vehicle 2's setpoints and commands and left them alone
            assert fleet.bridges[0].stats.ignored > 10 and fleet.bridges[2].stats.ignored > 10
            assert g.api_sources == [{1}, {2}, {3}]
            fleet.stop()
            fleet.join()
            assert not fleet.alive() and not fleet.failures
            for s in fleet.stats:
                assert s.max_lag < 0.1, s.lines()
    finally:
        g.close()


def test_a_failing_vehicle_stops_the_fleet_and_is_named():
    base = BridgeConfig(pos0=POS0, speed=4.0, duration=60.0, **AIR)
    urls = [f"udpout:127.0.0.1:{free_port()}", f"udpout:127.0.0.1:{free_port_run(3)}+i"]
    with Fleet(fleet_configs(base, 3, urls)) as fleet:
        def broken(b) -> None:
            if b.session.time > 0.5:
                raise KeyError("rotor_7")

        fleet.bridges[1].on_chunk = broken
        t0 = time.monotonic()
        with pytest.raises(FleetError, match=r"system 2: KeyError: 'rotor_7' \(all 3 vehicles "
                                             r"stopped\)"):
            fleet.run()
        assert time.monotonic() - t0 < 10.0
        assert not fleet.alive()
        assert [sid for sid, _ in fleet.failures] == [2]
        for s in fleet.stats:  # every vehicle's summary is there, none ran to its duration
            assert 0.4 < s.sim_time < 10.0 and s.lines()[0].startswith("simulated")


def test_cli_flies_three_vehicles_and_refuses_bad_counts():
    fly = [sys.executable, "-m", "orchestrator.cli", "fly"]
    ports = ["--gcs", f"udpout:127.0.0.1:{free_port()}",
             "--gcs", f"udpout:127.0.0.1:{free_port_run(3)}+i"]
    r = subprocess.run([*fly, "--count", "3", "--duration", "1", "--speed", "max", *ports],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r
    for sid in (1, 2, 3):
        lines = [ln for ln in r.stdout.splitlines() if ln.startswith(f"[sys {sid}] ")]
        assert any("simulated           1.0" in ln for ln in lines), r.stdout
        assert any(" max lag " in ln for ln in lines) and any(" sent " in ln for ln in lines)
        assert sum(" mavlink endpoint " in ln for ln in lines) == 2
    assert r.stdout.count(" simulated ") == 3
    # PX4's numbering when no --gcs is given (only checked, not flown: 14540.. may be taken)
    for count, why in (("0", "--count 0: fly 1 to 16 vehicles"),
                       (str(MAX_VEHICLES + 1), "fly 1 to 16 vehicles"),
                       ("11", "is also the shared one"), ("x", "invalid int value")):
        r = subprocess.run([*fly, "--count", count, "--duration", "0.1"], cwd=ROOT,
                           capture_output=True, text=True, timeout=120)
        assert r.returncode != 0 and why in r.stderr, r
        assert "Traceback" not in r.stderr
    r = subprocess.run([*fly, "-n", "2", "--gcs", "udpin:127.0.0.1:14550", "--duration", "0.1"],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode != 0 and "write it PORT+i" in r.stderr and "Traceback" not in r.stderr


def test_ctrl_c_stops_every_vehicle_and_prints_each_summary():
    import signal

    proc = subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "fly", "-n", "3",
         "--gcs", f"udpout:127.0.0.1:{free_port()}",
         "--gcs", f"udpout:127.0.0.1:{free_port_run(3)}+i"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        started = [proc.stdout.readline() for _ in range(10)]  # the heading, 3 x 3 lines
        assert sum(" mavlink endpoint " in ln for ln in started) == 6, started
        time.sleep(1.5)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, (out, err)
    assert "Traceback" not in err
    for sid in (1, 2, 3):
        sim = [ln for ln in out.splitlines() if ln.startswith(f"[sys {sid}] simulated ")]
        assert len(sim) == 1 and float(sim[0].split()[3]) > 0.5, out  # about 1.5 s flown
        assert f"[sys {sid}] sent " in out


@pytest.mark.clients
def test_mavsdk_tells_the_vehicles_apart():
    from mavsdk import ComponentType, Configuration, ConnectionResult, Mavsdk
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.telemetry import Telemetry

    gcs_port, api_base = free_port(), free_port_run(3)
    base = BridgeConfig(pos0=POS0, speed=2.0, duration=120.0, **AIR)
    urls = [f"udpout:127.0.0.1:{gcs_port}", f"udpout:127.0.0.1:{api_base}+i"]
    sdks, plugins = [], []
    with Fleet(fleet_configs(base, 3, urls)) as fleet:
        fleet.start()
        try:
            def sdk(url: str) -> Mavsdk:
                s = Mavsdk(Configuration.create_with_component_type(
                    ComponentType.GROUND_STATION))
                sdks.append(s)
                assert s.add_any_connection(url) == ConnectionResult.SUCCESS
                return s

            # a ground station on the shared port (QGroundControl's place) sees all three
            gcs = sdk(f"udpin://127.0.0.1:{gcs_port}")
            deadline = time.monotonic() + 15.0
            while time.monotonic() < deadline and gcs.system_count() < 3:
                time.sleep(0.1)
            assert sorted(s.get_system_id() for s in gcs.get_systems()) == [1, 2, 3]
            # an offboard script on instance 1's API port (14541 in PX4's numbering)
            api = sdk(f"udpin://127.0.0.1:{api_base + 1}")
            system = api.first_autopilot(10.0)
            assert system is not None and system.get_system_id() == 2
            assert api.system_count() == 1
            action, telemetry = Action(system), Telemetry(system)
            plugins += [action, telemetry]
            seen = {}
            telemetry.subscribe_position(lambda p, _: seen.update(position=p))
            telemetry.subscribe_home(lambda p, _: seen.update(home=p))
            deadline = time.monotonic() + 15.0
            while time.monotonic() < deadline and not {"position", "home"} <= seen.keys():
                time.sleep(0.1)
            p, h = seen["position"], seen["home"]
            o = base.origin
            for lat, lon, want in ((h.latitude_deg, h.longitude_deg, (0.0, 2.0, 0.0)),
                                   (p.latitude_deg, p.longitude_deg, (0.0, 2.0, 0.0))):
                n, e, _ = o.to_ned(lat, lon, o.alt)  # its home and itself: 2 m east of 1's
                assert math.dist((n, e), want[:2]) < 0.05, (p, h)
            assert abs(p.absolute_altitude_m - (o.alt - POS0[2])) < 0.05, p  # hovering at 3 m
            action.arm()  # only vehicle 2 arms
            assert [b.armed for b in fleet.bridges] == [False, True, False]
            action.disarm()
        finally:
            for plugin in plugins:
                plugin.destroy()
            for s in sdks:
                s.destroy()
