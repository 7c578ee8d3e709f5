"""`fullpose fly` with vehicles other than the paper's: the X8 and the Y6 answer a real
MAVLink client (pymavlink over UDP), hover, fly a 1 m offboard step and, when a propeller
breaks (the plant's rotor efficiency set to 0 mid-flight, nobody telling the controller),
the controller detects it and flies on that vehicle's own failure set.  The bridge runs in
a thread at 4x speed; every wait is bounded in wall time."""

import os

import numpy as np
import pytest

os.environ["MAVLINK20"] = "1"

from helpers import mavlink_harness as harness

pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

stream = harness.stream


@pytest.mark.parametrize("airframe", ["x8_coaxial", "y6"])
def test_fly_a_step_and_survive_a_broken_propeller(airframe):
    f = harness.Flight(airframe=airframe, duration=60.0)
    try:
        assert f.bridge.airframe.name == airframe
        f.command(400, 1, expect=0)  # arm
        f.position(0.0, 0.0, -3.0)
        f.offboard(expect=0)
        stream(f, 1.0, lambda: f.position(1.0, 0.0, -3.0))  # 4 s simulated
        lp = f.wait("LOCAL_POSITION_NED", 3.0)
        assert abs(lp.x - 1.0) < 0.05 and abs(lp.z + 3.0) < 0.05
        efficiency = np.ones(8)
        efficiency[0] = 0.0
        f.bridge.session.set_disturbance(efficiency=efficiency)  # rotor 1's propeller gone
        stream(f, 1.0, lambda: f.position(1.0, 0.0, -3.0))
        state = f.bridge.session.state()["ctrl"]
        assert int(state["rotors_detected"][0]) == 1  # rotor 1 found, not told
        assert int(state["active_polytope"][0]) == 1  # flying on the X8's / Y6's own set
        assert float(state["rotor_eff_est"][0]) < 0.15  # lost: it cannot produce thrust
        # its motor idles at the probe speed (at most 30 % of its share of the weight at full
        # efficiency), which would show a thrust that came back
        af = f.bridge.airframe
        probe = np.sqrt(0.3 * af.mass * af.gravity / (af.n_rotors * af.k_t))
        assert 0.0 < float(state["omega_cmd"][0]) <= probe * (1 + 1e-9)
        lp = f.wait("LOCAL_POSITION_NED", 3.0)
        assert abs(lp.x - 1.0) < 0.05 and abs(lp.z + 3.0) < 0.05  # and still holds
    finally:
        f.close()
