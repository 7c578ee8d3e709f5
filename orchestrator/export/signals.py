"""The ScenarioSignals FMU and its table: a scenario's references and disturbances as an FMU
that any FMI 2.0 importer plays.

    table = signal_table(times, references, disturbances)  # SignalTable: times, named columns
    fmu_bytes = signals_fmu_with(table)                    # the FMU with the table in resources/

The FMU (``fmu_src/signals/``) has one output per controller reference input and plant
disturbance input, named like it (``pos_ref[1]`` ... ``euler_rate_ref[3]``,
``rotor_health[1..8]``, ``f_d``, ``tau_d``, ``a_d``, ``efficiency[1..8]``), and plays the
table in ``resources/signals.fptable``: at a communication point t each output holds the
value of the last row at or before t (rows on the master's grid: exactly row k at t_k).  The
table of a scenario (``orchestrator.scenario_ssp``) is the one the orchestrator's master
feeds the FMUs: the scenario's signals sampled at t_k = k * step by the same functions, so an
importer stepping at the scenario's step gives the controller and the plant the same inputs,
to the bit.

The file format (binary, little-endian, so that every double reads back exactly in every
locale) is documented in ``fmu_src/common/fp_table.h``; :func:`encode_table` writes it and
:func:`decode_table` reads it back.
"""

from __future__ import annotations

import io
import struct
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orchestrator.export.archive import add_entry
from plant import find_artifact

SIGNALS_FMU = "ScenarioSignals"
"""Model name of the signal-player FMU (``orchestrator/fmus/ScenarioSignals.fmu``)."""
TABLE_RESOURCE = "resources/signals.fptable"
"""Where the FMU reads its table (``SIGNALS_RESOURCE`` in ``fmu_src/signals/signals.h``)."""
MAGIC = b"FPTABLE1"
NAME_SIZE = 32
MAX_COLUMNS = 64
REFERENCE_GROUPS = ("pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref",
                    "rotor_health")
"""The controller inputs the FMU feeds, in the order of its outputs."""
DISTURBANCE_GROUPS = ("f_d", "tau_d", "a_d", "efficiency")
"""The plant inputs the FMU feeds."""


def signals_fmu(fmi: int = 2) -> Path:
    """Path of the installed (or ``FULLPOSE_BUILD_DIR``-built) ScenarioSignals FMU (FMI 2.0, or
    3.0 with ``fmi=3``), without a table (it refuses to instantiate until one is added:
    :func:`signals_fmu_with`)."""
    from plant import fmu_file

    return find_artifact("orchestrator", "fmus", fmu_file(SIGNALS_FMU, fmi))


@dataclass(frozen=True)
class SignalTable:
    """Samples of named signals: ``times`` (rows,), ``values`` (rows, columns)."""

    names: tuple[str, ...]
    times: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        rows = self.times.shape[0]
        if self.times.ndim != 1 or rows < 1:
            raise ValueError("a signal table needs at least one row of times")
        if self.values.shape != (rows, len(self.names)):
            raise ValueError(f"values must be {rows} x {len(self.names)}, "
                             f"got {self.values.shape}")
        if not 1 <= len(self.names) <= MAX_COLUMNS:
            raise ValueError(f"a signal table has 1..{MAX_COLUMNS} columns, "
                             f"got {len(self.names)}")
        for name in self.names:
            if not name or len(name.encode()) >= NAME_SIZE:
                raise ValueError(f"column name {name!r}: 1..{NAME_SIZE - 1} bytes")
        if not (np.all(np.isfinite(self.times)) and np.all(np.isfinite(self.values))):
            raise ValueError("a signal table holds finite numbers only")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError("the times of a signal table must increase")

    def column(self, name: str) -> np.ndarray:
        """The samples of one signal."""
        return self.values[:, self.names.index(name)]


def _columns(signals: Mapping[str, np.ndarray], groups: tuple[str, ...]
             ) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for g in groups:
        block = signals[g]
        for i in range(block.shape[1]):
            out[f"{g}[{i + 1}]"] = block[:, i]
    return out


def signal_table(times: np.ndarray, references: Mapping[str, np.ndarray],
                 disturbances: Mapping[str, np.ndarray]) -> SignalTable:
    """The table of the signals a master feeds at ``times``: ``references`` (the controller's
    inputs of :data:`REFERENCE_GROUPS`) and ``disturbances`` (the plant's of
    :data:`DISTURBANCE_GROUPS`), each (len(times), n), one column per element."""
    cols = {**_columns(references, REFERENCE_GROUPS),
            **_columns(disturbances, DISTURBANCE_GROUPS)}
    return SignalTable(tuple(cols), np.asarray(times, dtype=float),
                       np.column_stack(list(cols.values())))


def encode_table(table: SignalTable) -> bytes:
    """The table file's bytes (``fmu_src/common/fp_table.h``)."""
    head = MAGIC + struct.pack("<II", len(table.times), len(table.names))
    names = b"".join(n.encode().ljust(NAME_SIZE, b"\0") for n in table.names)
    body = np.column_stack([table.times, table.values]).astype("<f8", copy=False)
    return head + names + np.ascontiguousarray(body).tobytes()


def decode_table(data: bytes) -> SignalTable:
    """A table file's contents (the inverse of :func:`encode_table`)."""
    if data[:8] != MAGIC:
        raise ValueError("not a signal table")
    rows, cols = struct.unpack_from("<II", data, 8)
    at = 16 + cols * NAME_SIZE
    names = tuple(data[16 + i * NAME_SIZE:16 + (i + 1) * NAME_SIZE].rstrip(b"\0").decode()
                  for i in range(cols))
    body = np.frombuffer(data, dtype="<f8", offset=at).reshape(rows, cols + 1)
    return SignalTable(names, body[:, 0].astype(float), body[:, 1:].astype(float))


def signals_fmu_with(table: SignalTable, fmu: Path | None = None) -> bytes:
    """The ScenarioSignals FMU (``fmu``, default the installed one) with ``table`` as its
    ``resources/signals.fptable``: every other entry byte for byte, in its order."""
    buf = io.BytesIO()
    with zipfile.ZipFile(fmu or signals_fmu()) as src, zipfile.ZipFile(buf, "w") as dst:
        for info in src.infolist():
            if not info.is_dir() and info.filename != TABLE_RESOURCE:
                add_entry(dst, info.filename, src.read(info), zipfile.ZIP_DEFLATED)
        add_entry(dst, TABLE_RESOURCE, encode_table(table), zipfile.ZIP_DEFLATED)
    return buf.getvalue()


__all__ = ["DISTURBANCE_GROUPS", "REFERENCE_GROUPS", "SIGNALS_FMU",
           "SignalTable", "decode_table", "encode_table", "signal_table", "signals_fmu",
           "signals_fmu_with"]
