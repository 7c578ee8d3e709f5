"""A scenario as an SSP archive (``fullpose export-ssp OUT --scenario NAME``): the closed loop
and the scenario's signals, replayed by any SSP tool as ``fullpose run`` flies it.

    export_scenario_ssp(Path("s1.ssp"), load_scenario("hover_varying_orientation"))

The signals are what the master feeds the FMUs (``orchestrator.master``): the references,
the rotor health the controller is told and the disturbances, sampled at t_k = k * step by
the scenario's own functions; the start values are the run's (``CoSimulation.start_values``:
the airframe, the pose at the reference's start, the scenario's overrides).  The archive
(``orchestrator.export.ssp_signals``) replayed at its step with Jacobi coupling, as libcosim,
OMSimulator and fmpy's runner step it, equals ``fullpose run`` with ``coupling = "jacobi"``
(tests/test_orchestrator/test_ssp_scenario.py, test_omsimulator.py: within 1e-9 m).  With
``fmi=3`` (or the scenario's ``fmi = 3``) the archive is SSP 2.0 of the FMI 3.0 FMUs, whose
replay (``orchestrator.export.ssp_replay``) equals the FMI 2.0 archive's to the bit
(tests/test_orchestrator/test_ssp_fmi3.py).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from orchestrator.export.signals import SignalTable, signal_table
from orchestrator.export.ssp_signals import export_signals_ssp
from orchestrator.master import CoSimulation
from orchestrator.scenario.model import Scenario


def scenario_table(scenario: Scenario, stop_time: float | None = None) -> SignalTable:
    """The scenario's references, rotor health and disturbances at t_k = k * step, k = 0 ..
    round(stop_time / step) (default: its duration), as the master samples them."""
    if scenario.mission is not None:
        raise ValueError(f"scenario {scenario.name} flies a [mission]: its references depend "
                         "on the flight (each leg waits for the vehicle), so they cannot be "
                         "a table played by a ScenarioSignals FMU; export a scenario with "
                         "[reference] signals")
    stop = scenario.duration if stop_time is None else float(stop_time)
    n = round(stop / scenario.step) if math.isfinite(stop) else 0
    if not (stop > 0 and n >= 1):
        raise ValueError(f"stop time must be at least one step ({scenario.step} s), "
                         f"got {stop_time}")
    times = np.arange(n + 1, dtype=float) * scenario.step
    refs = scenario.references(times)
    refs["rotor_health"] = scenario.health(times)
    return signal_table(times, refs, scenario.disturbances(times))


def export_scenario_ssp(path: Path, scenario: Scenario, stop_time: float | None = None,
                        fmus: Path | None = None, fmi: int | None = None) -> Path:
    """Write ``scenario`` (until ``stop_time``, default its duration) as an SSP archive
    whose fixed-step replay is ``fullpose run`` under Jacobi coupling; returns its path.
    ``fmi``: 2 (SSP 1.0, the FMI 2.0 FMUs) or 3 (SSP 2.0, the FMI 3.0 FMUs); default the
    scenario's ``fmi``.  ``fmus``: a folder to take the FMUs from (e.g. ``fullpose build-fmus
    --out``: binaries for every platform), else the installed ones."""
    table = scenario_table(scenario, stop_time)
    start = CoSimulation(scenario).start_values()  # (the same for either coupling)
    return export_signals_ssp(path, f"fullpose_{scenario.name}", table, start.plant,
                              start.controller, scenario.step, scenario.name, fmus,
                              scenario.fmi if fmi is None else fmi)
