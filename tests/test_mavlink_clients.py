"""Real ground tools against the bridge on 127.0.0.1: MAVProxy (headless) and MAVSDK.

The bridge runs in a thread of the test process (a `fullpose fly` subprocess in the
MAVProxy test); each test picks free UDP ports at runtime and every wait is bounded.
"""

import os
import threading
import time
from pathlib import Path

import mavlink_harness as harness
import pytest
from mavlink_harness import free_port

os.environ["MAVLINK20"] = "1"

from mavlink_bridge.bridge import Bridge, BridgeConfig

ROOT = Path(__file__).resolve().parents[1]


def start(config):
    bridge = Bridge(config)
    thread = threading.Thread(target=bridge.run, daemon=True)
    thread.start()
    return bridge, thread


def finish(bridge, thread):
    bridge.stop()
    thread.join(timeout=10)
    bridge.close()
    assert not thread.is_alive()


@pytest.mark.clients
def test_mavproxy_headless_sees_mode_attitude_and_position(tmp_path):
    # MAVProxy without a console or map: commands on stdin, no default modules (no GUI)
    out, _ = harness.mavproxy_session(
        tmp_path, [], "", [("status ATTITUDE", 1.0), ("status LOCAL_POSITION_NED", 1.0)])
    assert "Detected vehicle 1:1" in out, out
    assert "Mode LOITER" in out, out  # PX4 AUTO.LOITER = the bridge's HOLD
    assert "ATTITUDE {" in out and "roll :" in out, out
    assert "LOCAL_POSITION_NED {" in out and "z : -3.0" in out, out


@pytest.mark.clients
def test_mavsdk_arms_starts_offboard_and_reaches_a_position():
    from mavsdk import ComponentType, Configuration, ConnectionResult, Mavsdk
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.offboard import Offboard, PositionNedYaw
    from mavsdk.plugins.telemetry import FlightMode, Telemetry

    port = free_port()
    bridge, thread = start(BridgeConfig(urls=[f"udpout:127.0.0.1:{port}"], speed=2.0,
                                        duration=120.0))
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        result = sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        assert result == ConnectionResult.SUCCESS, result
        system = sdk.first_autopilot(10.0)
        assert system is not None, "no autopilot discovered"
        action, offboard, telemetry = Action(system), Offboard(system), Telemetry(system)
        latest = {}
        telemetry.subscribe_position_velocity_ned(lambda pv, _: latest.update(pv=pv))
        action.arm()
        target = PositionNedYaw(1.0, -0.5, -3.5, 4.0)
        offboard.set_position_ned(target)  # PX4 needs a setpoint before offboard
        offboard.start()
        deadline = time.monotonic() + 30.0
        reached = False
        while time.monotonic() < deadline:
            pv = latest.get("pv")
            if pv is not None:
                p = pv.position
                err = ((p.north_m - 1.0) ** 2 + (p.east_m + 0.5) ** 2 +
                       (p.down_m + 3.5) ** 2) ** 0.5
                if err < 0.05:
                    reached = True
                    break
            time.sleep(0.05)
        assert reached, f"position not reached: {latest.get('pv')}"
        assert telemetry.flight_mode() == FlightMode.OFFBOARD
        assert telemetry.armed()
        assert abs(bridge.session.state()["plant"]["euler"][2] - 0.0698) < 0.01
        offboard.stop()
        action.disarm()
    finally:
        for plugin in ("action", "offboard", "telemetry"):
            obj = locals().get(plugin)
            if obj is not None:
                obj.destroy()
        sdk.destroy()
        finish(bridge, thread)
