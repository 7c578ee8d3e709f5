"""A scenario as an SSP archive: the closed loop plus the scenario's signals, for any SSP tool.

    export_scenario_ssp(Path("scenario1.ssp"), load_scenario("hover_varying_orientation"))

The archive holds three components: ``ScenarioSignals`` (``orchestrator.export.signals``:
the scenario's references, rotor health and disturbances sampled at t_k = k * step into a
table the FMU plays), ``MultirotorPlant`` and ``FullPoseController``.  Every input of the
controller and the plant is connected by name: references and rotor health from the signals
to the controller, disturbances and efficiencies from the signals to the plant, measurements
from the plant to the controller, commands from the controller to the plant.  The SSVs hold
what ``fullpose run`` gives the FMUs (``CoSimulation.start_values``: the airframe, the
pose at the reference's start, the scenario's ``[plant]`` / ``[controller]`` overrides), and
for every connected input its value at t = 0, so the loop is consistent at t = 0 for a runner
that initialises inputs from start values.  The scenario's step and duration are the
archive's step and stop time, in every annotation the tested importers read
(``orchestrator.export.ssp``).

A fixed-step SSP master steps the three components from the same inputs and then exchanges
outputs (Jacobi): at t_k the controller samples r_k and y_k, the plant integrates [t_k,
t_k+1] with d_k and the controller's u_{k-1}.  That is ``fullpose run`` with ``coupling =
"jacobi"``, which the replay matches (tests/test_orchestrator/test_ssp_scenario.py: libcosim,
OMSimulator and fmpy within 1e-9 m).
"""

from __future__ import annotations

import io
import math
from dataclasses import replace
from pathlib import Path

from fmpy import read_model_description

from controller import controller_fmu
from orchestrator.export.signals import SIGNALS_FMU, scenario_table, signals_fmu_with
from orchestrator.export.ssp import (
    CONTROLLER,
    PLANT,
    Connection,
    Value,
    _connect,
    connection_table,
    consistent_start,
    write_archive,
)
from orchestrator.master import CoSimulation
from orchestrator.scenario.model import Scenario
from plant import plant_fmu

SIGNALS = SIGNALS_FMU


def scenario_connections(mds: dict[str, object]) -> list[Connection]:
    """Every connection of the three components, matched by name: the signals to the
    controller and the plant, then the loop (:func:`orchestrator.export.ssp.connection_table`).
    Every input of the controller and the plant is fed, or a ValueError names those left."""
    to_ctrl, loose_c = _connect(SIGNALS, mds[SIGNALS], CONTROLLER, mds[CONTROLLER])
    to_plant, loose_p = _connect(SIGNALS, mds[SIGNALS], PLANT, mds[PLANT])
    loop = connection_table(mds[PLANT], mds[CONTROLLER])
    fed = {(tc, tv) for _, _, tc, tv in to_ctrl + to_plant + loop}
    left = [f"{c}.{v}" for c, names in ((CONTROLLER, loose_c), (PLANT, loose_p))
            for v in names if (c, v) not in fed]
    if left:
        raise ValueError(f"inputs no component feeds: {', '.join(left)}")
    return to_ctrl + to_plant + loop


def export_scenario_ssp(path: Path, scenario: Scenario,
                        stop_time: float | None = None) -> Path:
    """Write ``scenario`` (until ``stop_time``, default its duration) as an SSP 1.0 archive
    whose fixed-step replay is ``fullpose run`` under Jacobi coupling; returns its path."""
    stop = scenario.duration if stop_time is None else float(stop_time)
    if not (math.isfinite(stop) and stop > 0):
        raise ValueError(f"stop time must be positive, got {stop_time}")
    table = scenario_table(scenario, stop)
    fmus = {SIGNALS: signals_fmu_with(table), PLANT: Path(plant_fmu()).read_bytes(),
            CONTROLLER: Path(controller_fmu()).read_bytes()}
    mds = {comp: read_model_description(io.BytesIO(data)) for comp, data in fmus.items()}
    connections = scenario_connections(mds)
    at0 = {name: float(table.values[0, i]) for i, name in enumerate(table.names)}
    # what `fullpose run` sets (a run's start values do not depend on its coupling)
    start = CoSimulation(replace(scenario, coupling="jacobi")).start_values()
    plant: dict[str, Value] = dict(start.plant)
    ctrl: dict[str, Value] = dict(start.controller)
    for fc, fv, tc, tv in connections:  # the signals' inputs at t = 0
        if fc == SIGNALS:
            (ctrl if tc == CONTROLLER else plant)[tv] = at0[fv]
    values = consistent_start(plant, ctrl, connections)
    n = round(stop / scenario.step)
    return write_archive(path, f"fullpose_{scenario.name}", fmus, mds, connections, values,
                         scenario.step, n * scenario.step, scenario.name)

