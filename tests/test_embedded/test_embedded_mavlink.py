"""The controller on the emulated Cortex-M7, flown from a ground station: ``fullpose fly
--pil`` over real MAVLink 2 on UDP (pymavlink as the ground station), at wall-clock speed.

Oracles: the MAVLink messages the bridge sends (HEARTBEAT modes and arming, COMMAND_ACK,
STATUSTEXT) and the position against the commanded one within the paper's 2 cm; that the
samples ran on the target: its own count of them.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from helpers.mavlink_harness import Flight
from pymavlink.dialects.v20 import common as mav

from orchestrator.pil.build import build_embedded, missing_tools
from orchestrator.pil.instance import PilController

os.environ["MAVLINK20"] = "1"
MISSING = missing_tools()
pytestmark = [pytest.mark.embedded, pytest.mark.skipif(
    bool(MISSING),
    reason=f"{', '.join(MISSING)} absent: bash tests/tools/install_embedded_tools.sh")]

nan = math.nan
TAKEOFF, LOITER, LAND = ((4 << 16) | (s << 24) for s in (2, 3, 6))
ARMED = mav.MAV_MODE_FLAG_SAFETY_ARMED


@pytest.fixture(scope="module")
def image(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_embedded(tmp_path_factory.mktemp("m7")).elf


@pytest.fixture
def flight(image: Path) -> Iterator[Flight]:
    f = Flight(speed=1.0, start="ground", duration=120.0, airframe="y6", pil=image)
    yield f
    f.close()


def test_the_y6_takes_off_and_lands_with_its_controller_on_the_cortex_m7(flight: Flight) -> None:
    f = flight
    ctrl = f.bridge.session.ctrl_inst
    assert isinstance(ctrl, PilController)
    rest = np.array(f.bridge.state["plant"]["pos"], float)
    f.command(400, 1, expect=0)
    f.gcs.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", 1.0, mav.MAV_PARAM_TYPE_REAL32)
    f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    f.command(22, 0, 0, 0, nan, nan, nan, nan, expect=0)
    f.wait("HEARTBEAT", 3.0, lambda m: m.custom_mode == TAKEOFF)
    f.wait("HEARTBEAT", 20.0, lambda m: m.custom_mode == LOITER)
    f.wait("HEARTBEAT", 2.0)  # a second in the hold
    f.wait("HEARTBEAT", 2.0)
    p = np.array(f.bridge.state["plant"]["pos"], float)
    assert abs(p[2] - (rest[2] - 1.0)) < 0.02 and np.hypot(*(p[:2] - rest[:2])) < 0.02
    f.command(21, 0, 0, 0, nan, nan, nan, nan, expect=0)
    f.wait("HEARTBEAT", 30.0, lambda m: not m.base_mode & ARMED)
    f.wait("STATUSTEXT", 3.0, lambda m: m.text == "disarmed: landed")
    # every sample of the flight ran on the target: 500 a simulated second
    flown = f.bridge.session.time
    assert len(ctrl.samples.ticks) >= 0.99 * flown / 0.002
    summary = ctrl.summary()
    assert summary["heap_bytes_in_samples"] == 0
