"""The recorded outcome of a co-simulation run.

Every exchanged signal at every step lives in one float64 matrix ``data``
(rows = communication points, columns = scalar signals) with structured column
names, so nothing is copied per signal and any tool can read the CSV:

- ``time``                                  t_k = k * step, s
- ``ref.<input>[i]``                        references given to the controller
  (``pos_ref``, ``euler_ref``, ``vel_ref``, ``acc_ref``, ``euler_rate_ref``)
- ``dist.<input>[i]``                       plant disturbance/fault inputs
  (``f_d``, ``tau_d``, ``a_d``, ``efficiency``)
- ``plant.<output>[i]``                     every plant output (``pos``, ``euler``, ...)
- ``ctrl.<output>[i]``                      every controller output (commands and
  diagnostics: ``omega_cmd``, ``mu_c``, ``feasible``, ``guid_iter``, ``t_guid``, ...)

Row k holds the plant outputs y_k at t_k, the references at t_k and the
controller outputs computed from them (the command u_k applied over
[t_k, t_k+1] with the default coupling).  Integer and Boolean outputs are stored
as floats.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FORMAT_VERSION = 1


@dataclass
class RunResult:
    """Columns and data of one run, plus facts about the run."""

    columns: list[str]
    data: np.ndarray  # (n_rows, n_columns) float64
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._index = {name: i for i, name in enumerate(self.columns)}

    @property
    def time(self) -> np.ndarray:
        return self.data[:, self._index["time"]]

    def has(self, name: str) -> bool:
        return name in self._index or f"{name}[1]" in self._index

    def column(self, name: str) -> np.ndarray:
        """One scalar column by its full name, e.g. ``plant.pos[3]``."""
        return self.data[:, self._index[name]]

    def get(self, name: str) -> np.ndarray:
        """A signal group: ``plant.pos`` -> (n_rows, 3); scalars -> (n_rows,)."""
        if name in self._index:
            return self.data[:, self._index[name]]
        idx = [i for c, i in self._index.items() if c.startswith(name + "[")]
        if not idx:
            raise KeyError(f"no signal {name!r} in the result")
        return self.data[:, idx]

    # -- files ---------------------------------------------------------------

    def optional(self, name: str) -> np.ndarray | None:
        """:meth:`get`, or None when the run did not record the signal."""
        return self.get(name) if self.has(name) else None

    @property
    def n_rotors(self) -> int:
        """The airframe's rotor count: from the metadata, else the recorded rotor vectors'
        width, else the FMUs' 8 rotor slots."""
        n = self.meta.get("n_rotors")
        if n is not None:
            return int(n)
        for name in ("ctrl.omega_cmd", "plant.omega"):
            if self.has(name):
                return int(self.get(name).reshape(len(self.time), -1).shape[1])
        return 8

    def write_csv(self, path: Path) -> None:
        header = ",".join(self.columns)
        np.savetxt(path, self.data, delimiter=",", header=header, comments="", fmt="%.17g")

    def write_npz(self, path: Path) -> None:
        """Compact binary: compressed numpy archive with the columns and metadata."""
        np.savez_compressed(path, data=self.data, columns=np.array(self.columns),
                            meta=np.array(json.dumps(self.meta, default=str)),
                            format_version=np.array(FORMAT_VERSION))

    @classmethod
    def read_npz(cls, path: Path) -> RunResult:
        with np.load(path, allow_pickle=False) as z:
            if int(z["format_version"]) != FORMAT_VERSION:
                raise ValueError(f"{path}: result format {int(z['format_version'])}, "
                                 f"expected {FORMAT_VERSION}")
            return cls(columns=[str(c) for c in z["columns"]], data=np.array(z["data"]),
                       meta=json.loads(str(z["meta"])))

    @classmethod
    def read_csv(cls, path: Path) -> RunResult:
        with open(path) as f:
            columns = f.readline().strip().split(",")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        return cls(columns=columns, data=data)
