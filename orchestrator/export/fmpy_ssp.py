"""fmpy's SSP runner made to play an exported archive as recorded.

    result = simulate_with_fmpy("scenario1.ssp")        # fmpy.ssp.simulation.simulate_ssp

fmpy 0.3.x's ``simulate_ssp`` needs two things an archive cannot give it (docs/fmpy.md):

* the recorded start, stop and step and the parameter bindings as arguments
  (:func:`orchestrator.export.ssp.fmpy_options` reads them from the archive);
* a consistent first step: it starts every connector at 0.0 and, at the first step, sets
  every connected input to that 0.0 instead of leaving the start values the archive gives
  (the controller sees the vehicle at the origin, at rest, with its rotors stopped, and the
  plant gets zero commands for 2 ms).  :func:`consistent_first_step` runs fmpy's own
  ``do_step`` for every later step and, for the first one, steps each component from the
  inputs it was initialised with.  That is what the other SSP runners do (libcosim,
  OMSimulator), and what makes fmpy's replay of a scenario equal ``fullpose run`` under
  Jacobi coupling (tests/test_orchestrator/test_ssp_scenario.py).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from orchestrator.export.ssp import fmpy_options


@contextmanager
def consistent_first_step() -> Iterator[None]:
    """Within the block, fmpy's ``simulate_ssp`` steps every component at the start time
    from its initialised inputs (their start values) instead of 0.0; later steps are
    fmpy's own.  Restores fmpy's ``do_step`` on leaving."""
    import fmpy.ssp.simulation as sim

    original = sim.do_step
    first: dict[int, bool] = {}

    def do_step(component: Any, time: float, step_size: float) -> None:
        if first.setdefault(id(component), True):
            first[id(component)] = False
            component.fmu.doStep(currentCommunicationPoint=time,
                                 communicationStepSize=step_size)
            for connector in component.connectors:
                if connector.kind == "output":
                    connector.value = sim.get_value(component, connector.name)
            return
        original(component, time, step_size)

    sim.do_step = do_step
    try:
        yield
    finally:
        sim.do_step = original


def simulate_with_fmpy(path: str | Path, **overrides: Any) -> Any:
    """fmpy's ``simulate_ssp`` on the archive with its recorded options
    (:func:`~orchestrator.export.ssp.fmpy_options`; ``overrides`` replace them, e.g.
    ``stop_time``) and a consistent first step; returns fmpy's structured array (``time``,
    the start of each step, and ``<component>.<variable>`` after it)."""
    from fmpy.ssp.simulation import simulate_ssp

    options = {**fmpy_options(path), **overrides}
    with consistent_first_step():
        return simulate_ssp(str(path), **options)
