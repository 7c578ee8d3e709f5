"""Real ground tools against the bridge on 127.0.0.1: MAVProxy (headless) and MAVSDK.

The bridge runs in a thread of the test process (a `fullpose fly` subprocess in the
MAVProxy test); each test picks free UDP ports at runtime and every wait is bounded.
"""

import os
import time
from pathlib import Path

import pytest
from helpers import mavlink_harness as harness

os.environ["MAVLINK20"] = "1"


pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.clients
def test_mavproxy_headless_sees_mode_attitude_and_position(tmp_path):
    # MAVProxy without a console or map: commands on stdin, no default modules (no GUI)
    out, _ = harness.mavproxy_session(  # hovering at 3 m from the start (--start air)
        tmp_path, ["--start", "air"], "",
        [("status ATTITUDE", 1.0), ("status LOCAL_POSITION_NED", 1.0)])
    assert "Detected vehicle 1:1" in out, out
    assert "Mode LOITER" in out, out  # PX4 AUTO.LOITER = the bridge's HOLD
    assert "ATTITUDE {" in out and "roll :" in out, out
    assert "LOCAL_POSITION_NED {" in out and "z : -3.0" in out, out


@pytest.mark.clients
def test_mavsdk_arms_starts_offboard_and_reaches_a_position():
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.offboard import Offboard, PositionNedYaw
    from mavsdk.plugins.telemetry import FlightMode, Telemetry

    with harness.mavsdk_session() as (bridge, system, plugins):
        action, offboard, telemetry = Action(system), Offboard(system), Telemetry(system)
        plugins += [action, offboard, telemetry]
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
