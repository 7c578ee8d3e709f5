"""LiveSession: the closed loop stepped on demand matches a scenario run bit for bit."""

import numpy as np
import pytest

from orchestrator.master import run
from orchestrator.runner import prepare
from orchestrator.sim.live import LiveSession


@pytest.mark.parametrize("coupling", ["gauss-seidel", "jacobi"])
def test_live_session_equals_the_scenario_run(coupling):
    import dataclasses

    sc = dataclasses.replace(prepare("position_step", duration=3.0), coupling=coupling)
    ref = run(sc)
    pos = ref.get("plant.pos")
    with LiveSession("paper_hexacopter", pos0=(0.0, 0.0, -3.0), chunk=7,
                     coupling=coupling) as live:
        steps = 0
        while steps < 1500:
            n = min(7, 1500 - steps, 500 - steps if steps < 500 else 7)
            if steps == 500:
                live.set_reference(pos_ref=[1.0, 0.0, -3.0])
            live.advance(n)
            steps += n
            np.testing.assert_array_equal(live.state()["plant"]["pos"], pos[steps])
        assert live.time == pytest.approx(3.0)


def test_live_inputs_are_validated():
    with LiveSession(chunk=2) as live:
        with pytest.raises(ValueError):
            live.set_reference(pos_ref=[0.0, float("nan"), -3.0])
        with pytest.raises(KeyError):
            live.set_reference(position=[0.0, 0.0, -3.0])
        with pytest.raises(KeyError):
            live.set_controller_parameter("mass", 1.0)  # fixed, not tunable
        live.set_controller_parameter("K_pos_D[1]", 1.0)
        live.set_disturbance(a_d=[0.5, 0.0, 0.0])
        for _ in range(50):
            live.advance()
        s = live.state()
        assert s["plant"]["pos"][0] > 0.0  # pushed along +x by the disturbance
        assert s["ctrl"]["feasible"][0] == 1.0
