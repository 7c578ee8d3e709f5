"""The closed loop with its input signals as an SSP archive: plant, controller and the
ScenarioSignals FMU (``orchestrator.export.signals``) playing a table of references and
disturbances; the FMI 2.0 FMUs in SSP 1.0, or the FMI 3.0 ones in SSP 2.0 (``fmi=3``, array
connectors: ``orchestrator.export.ssp``).

    export_signals_ssp(path, "fullpose_s1", table, plant_values, controller_values, step=0.002)

The archive holds three components: ``ScenarioSignals`` (the table), ``MultirotorPlant`` and
``FullPoseController``.  Every input of the controller and the plant is connected by name:
references and rotor health from the signals to the controller, disturbances and efficiencies
from the signals to the plant, measurements from the plant to the controller, commands from
the controller to the plant.  The SSVs hold the start values given and, for every connected
input, its value at t = 0 (the plant's initial outputs and trim for the loop,
``orchestrator.export.ssp.consistent_start``; the table's first row for the signals), so
the loop is consistent at t = 0 for a runner that initialises inputs from start values.  The
step and the stop time (the table's last row) go into every annotation the tested importers
read (``orchestrator.export.ssp``).

A fixed-step SSP master steps the three components from the same inputs and then exchanges
outputs (Jacobi): at t_k the controller samples r_k and y_k, the plant integrates [t_k,
t_k+1] with d_k and the controller's u_{k-1}.
"""

from __future__ import annotations

import io
from collections.abc import Mapping
from pathlib import Path

from fmpy import read_model_description
from fmpy.model_description import ModelDescription

from orchestrator.export.signals import SIGNALS_FMU, SignalTable, signals_fmu_with
from orchestrator.export.ssp import (
    CONTROLLER,
    PLANT,
    Connection,
    Value,
    check_fmi,
    connect_by_name,
    connection_table,
    consistent_start,
    element_connections,
    fmu_file,
    write_archive,
)
from orchestrator.sim.engine import HELD_INPUTS

SIGNALS = SIGNALS_FMU


def signal_connections(mds: Mapping[str, ModelDescription]) -> list[Connection]:
    """Every connection of the three components, matched by name: the signals to the
    controller and the plant, then the loop (:func:`orchestrator.export.ssp.connection_table`).
    Every input of the controller and the plant is fed but the held ones (the controller's
    ``armed``: its start value, true), or a ValueError names those left."""
    to_ctrl, loose_c = connect_by_name(SIGNALS, mds[SIGNALS], CONTROLLER, mds[CONTROLLER])
    to_plant, loose_p = connect_by_name(SIGNALS, mds[SIGNALS], PLANT, mds[PLANT])
    loop = connection_table(mds[PLANT], mds[CONTROLLER])
    fed = {(tc, tv) for _, _, tc, tv in to_ctrl + to_plant + loop}
    left = [f"{c}.{v}" for c, names in ((CONTROLLER, loose_c), (PLANT, loose_p))
            for v in names if (c, v) not in fed and v not in HELD_INPUTS]
    if left:
        raise ValueError(f"inputs no component feeds: {', '.join(left)}")
    return to_ctrl + to_plant + loop


def export_signals_ssp(path: Path, name: str, table: SignalTable,
                       plant_values: Mapping[str, Value],
                       controller_values: Mapping[str, Value], step: float,
                       label: str | None = None, fmus: Path | None = None,
                       fmi: int = 2) -> Path:
    """Write the loop fed by ``table`` (rows on the grid t_k = k * ``step``) as an SSP archive
    (SSP 1.0 with the FMI 2.0 FMUs, SSP 2.0 with the FMI 3.0 ones for ``fmi=3``) whose stop
    time is the table's last row; returns its path.  ``plant_values``, ``controller_values``
    by FMI 2.0 element names.  ``fmus``: a folder to take the three FMUs from
    (``orchestrator.export.ssp.fmu_file``), else the installed ones."""
    fmi = check_fmi(fmi)
    data = {SIGNALS: signals_fmu_with(table, fmu_file(SIGNALS, fmus, fmi)),
            PLANT: fmu_file(PLANT, fmus, fmi).read_bytes(),
            CONTROLLER: fmu_file(CONTROLLER, fmus, fmi).read_bytes()}
    mds = {comp: read_model_description(io.BytesIO(b)) for comp, b in data.items()}
    connections = signal_connections(mds)
    flat = element_connections(connections, mds)
    at0 = {n: float(table.values[0, i]) for i, n in enumerate(table.names)}
    plant, ctrl = dict(plant_values), dict(controller_values)
    for fc, fv, tc, tv in flat:  # the signals' inputs at t = 0
        if fc == SIGNALS:
            (ctrl if tc == CONTROLLER else plant)[tv] = at0[fv]
    values = consistent_start(plant, ctrl, flat, fmi)
    return write_archive(path, name, data, mds, connections, values, step,
                         float(table.times[-1]), label or name)
