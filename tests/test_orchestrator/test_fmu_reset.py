"""fmi2Reset as sweep workers use it: a reset instance is a fresh one.

The oracle is always a freshly loaded and instantiated FMU: after ``FmuInstance.reset()``
an instance that has flown another case (other parameters, a lost vehicle, a refused
initialization) must read the same start values, hold the same model state after
initialization (its serialized FMU state, i.e. the whole model struct, byte for byte) and
give a bit-identical closed-loop run.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from controller import controller_fmu
from orchestrator import sweep
from orchestrator.master import CoSimulation
from orchestrator.output.run_result import RunResult
from orchestrator.runner import prepare
from orchestrator.scenario.model import Scenario
from orchestrator.sim.fmu import FmuError, FmuInstance
from plant import plant_fmu

DURATION = 2.0


@pytest.fixture(scope="module")
def params() -> dict[str, dict[str, float]]:
    return sweep.designs()


@pytest.fixture(scope="module")
def hover() -> Scenario:
    return prepare("hover", DURATION)


@pytest.fixture()
def pair() -> Iterator[tuple[FmuInstance, FmuInstance]]:
    plant, ctrl = FmuInstance(plant_fmu(), "plant"), FmuInstance(controller_fmu(), "controller")
    yield plant, ctrl
    plant.close()
    ctrl.close()


def _case(hover: Scenario, params: dict[str, dict[str, float]], index: int,
          design: str = "hinf", **changes: float) -> Scenario:
    case = {**sweep.sample_cases(index + 1, 5)[index], **changes}
    return sweep.perturbed(hover, case, design, params[design], DURATION)


def _reused(sc: Scenario, pair: tuple[FmuInstance, FmuInstance]) -> RunResult:
    for inst in pair:
        inst.reset()
    return CoSimulation(sc, fmus=pair).run()


def _assert_same_run(got: RunResult, want: RunResult) -> None:
    assert got.columns == want.columns
    assert got.data.shape == want.data.shape
    assert got.data.tobytes() == want.data.tobytes()  # bit for bit, NaNs included
    strip = {"wall_time"}
    assert {k: v for k, v in got.meta.items() if k not in strip} == \
        {k: v for k, v in want.meta.items() if k not in strip}


def _refused(sc: Scenario, pair: tuple[FmuInstance, FmuInstance]) -> None:
    with pytest.raises(FmuError, match="tau_motor"):
        _reused(sc, pair)


def _lost(sc: Scenario, pair: tuple[FmuInstance, FmuInstance]) -> None:
    res = _reused(sc, pair)
    assert res.meta["outcome"]["outcome"] == "lost"


def test_a_reset_instance_runs_as_a_fresh_one_after_any_previous_case(hover, params, pair):
    """Case B on a fresh pair, and on one pair after: B itself, another case A (other plant,
    other design), a lost vehicle, a refused initialization (plant in Error)."""
    b = _case(hover, params, 1)
    fresh = CoSimulation(b).run()
    assert fresh.meta["outcome"] == {"outcome": "completed"} and fresh.meta["warnings"] > 0
    _assert_same_run(_reused(b, pair), fresh)  # a pair's first run
    _assert_same_run(_reused(b, pair), fresh)  # the same case again
    a = _case(hover, params, 0, "baseline_matched")
    assert CoSimulation(a).run().data.tobytes() != fresh.data.tobytes()  # A is another run
    _reused(a, pair)
    _assert_same_run(_reused(b, pair), fresh)
    _lost(_case(hover, params, 0, dist_amp=300.0), pair)
    _assert_same_run(_reused(b, pair), fresh)
    _refused(_case(hover, params, 0, tau_motor_scale=-1.0), pair)
    _assert_same_run(_reused(b, pair), fresh)


def test_each_run_of_a_reused_pair_reports_its_own_messages(hover, params, pair):
    """The FMU messages (warnings counted in the result) are the run's, not accumulated."""
    b = _case(hover, params, 2)
    fresh = CoSimulation(b).run()
    for _ in range(3):
        res = _reused(b, pair)
        assert res.meta["warnings"] == fresh.meta["warnings"] > 0
        assert res.meta["first_warnings"] == fresh.meta["first_warnings"]
    assert any(inst.messages for inst in pair)  # the last run's, until the next reset
    for inst in pair:
        inst.reset()
        assert inst.messages == []


def _all_values(inst: FmuInstance) -> dict[str, str]:
    """Every variable's value as its repr (exact for floats, NaN and -0.0 included)."""
    return {name: repr(inst.get(name)) for name, v in inst.variables.items()
            if v.type in ("Real", "Integer", "Boolean")}


def _initialized_state(inst: FmuInstance) -> bytes:
    inst.exit_initialization()
    state = inst.slave.getFMUstate()
    try:
        return bytes(inst.slave.serializeFMUstate(state))
    finally:
        inst.slave.freeFMUstate(state)


@pytest.mark.parametrize("which", ["plant", "controller"])
def test_reset_restores_every_start_value_and_the_whole_model(hover, params, pair, which):
    """In C, fmi2Reset clears the model and sets the defaults again (fmi2_glue.c): after a
    run with other parameters every variable reads as on a fresh instance, the parameters
    read their modelDescription start values, and after initialization the serialized
    state (the whole model struct, filter and noise states included) is byte-identical."""
    _reused(_case(hover, params, 0, "prototype_matched"), pair)  # other gains, other plant
    inst = pair[0] if which == "plant" else pair[1]
    inst.reset()
    path = plant_fmu() if which == "plant" else controller_fmu()
    with FmuInstance(path, which) as fresh:
        for i in (inst, fresh):
            i.enter_initialization(0.0)
        got, want = _all_values(inst), _all_values(fresh)
        assert got == want
        for name, v in fresh.variables.items():
            if v.causality == "parameter" and v.start is not None and v.type == "Real":
                assert got[name] == repr(float(v.start)), name
        assert _initialized_state(inst) == _initialized_state(fresh)
