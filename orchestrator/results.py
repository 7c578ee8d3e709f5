"""The recorded outcome of a co-simulation run, and its files.

Every exchanged signal at every step lives in one float64 matrix ``data``
(rows = communication points, columns = scalar signals) with structured column
names, so nothing is copied per signal:

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
as floats in memory and named in ``integer``.

Files (:meth:`RunResult.write`, :meth:`RunResult.read`):

``results.parquet`` (the default)
    Apache Parquet, one typed column per signal, zstd-compressed with the byte-stream-split
    encoding for floats: ``time`` float64 (exact), Integer and Boolean outputs int32 (exact),
    every other signal float32, i.e. the recording rounded to the nearest float32 (relative
    6e-8: 0.2 um at 3 m, 1e-7 rad, far below any sensor, test bound or plot), which is what
    makes a 100 s run 11 MB instead of 57.  The run's metadata and the precision of each
    column are in the file's key-value metadata (``fullpose.meta``, ``fullpose.format``).
    Written in row groups of :data:`ROW_GROUP` rows, so writing needs memory for one row
    group only.  Readable as is by pandas, polars, DuckDB, Arrow in every language, MATLAB's
    ``parquetread`` and PlotJuggler.
``results.csv`` (on request)
    Header of column names, every value in float64 with the shortest representation that
    reads back to the same double (integers as integers): exact, ~20x larger.
``results.mcap`` (on request)
    The same for Foxglove and PlotJuggler (orchestrator/mcap_export.py); not read back here.
``results.npz``
    The format of earlier versions (float64, numpy archive): still read.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pyarrow as pa

FORMAT_VERSION = 1
"""Version of the npz layout (read only)."""
PARQUET_FORMAT = 2
"""Version of the Parquet layout written here (``fullpose.format`` in the file)."""
RESULTS_FILE = "results.parquet"
CSV_FILE = "results.csv"
ROW_GROUP = 65536
"""Rows per Parquet row group (and per CSV chunk): the memory a write needs beyond the data."""
EXACT_FLOAT = frozenset({"time"})
"""Real columns stored in float64; every other real column is stored in float32."""


class ResultsFileError(ValueError):
    """A results file that cannot be read; the message names the file and why."""


@dataclass
class RunResult:
    """Columns and data of one run, plus facts about the run."""

    columns: list[str]
    data: np.ndarray  # (n_rows, n_columns) float64
    meta: dict[str, Any] = field(default_factory=dict)
    integer: frozenset[str] = frozenset()  # columns of Integer or Boolean outputs

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

    @property
    def has_truth(self) -> bool:
        """Whether the run recorded the plant's true state beside the measured one (a run
        with sensor noise, sampling or latency: ``plant.pos_true``, ``plant.euler_true``)."""
        return self.has("plant.pos_true") and self.has("plant.euler_true")

    def judged(self, name: str) -> str:
        """The signal to judge the flight by: ``plant.pos`` -> ``plant.pos_true`` when the
        true state is recorded, else ``name`` itself."""
        return f"{name}_true" if self.has_truth and self.has(f"{name}_true") else name

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

    def precision(self, name: str) -> str:
        """How a column is stored in ``results.parquet``: ``int32``, ``float64`` (``time``,
        and any column with a finite value beyond float32's range, e.g. a diverging run's)
        or ``float32``."""
        if name in self.integer:
            return "int32"
        return "float64" if name in EXACT_FLOAT or name in self._wide() else "float32"

    def _wide(self) -> frozenset[str]:
        wide = self.__dict__.get("_wide_columns")
        if wide is None:
            lim = float(np.finfo(np.float32).max)
            d = self.data
            with np.errstate(invalid="ignore"):  # (NaN compares False: checked below)
                fits = ((d.max(axis=0, initial=-lim) <= lim)
                        & (d.min(axis=0, initial=lim) >= -lim))
            found = []
            for i in np.flatnonzero(~fits):  # beyond, or NaN/inf somewhere: finite values
                col = d[:, i]
                finite = col[np.isfinite(col)]
                if finite.size and float(np.abs(finite).max()) > lim:
                    found.append(self.columns[i])
            wide = frozenset(found)
            self.__dict__["_wide_columns"] = wide
        return wide

    def _chunks(self) -> Iterator[tuple[int, int]]:
        n = self.data.shape[0]
        for a in range(0, max(n, 1), ROW_GROUP):
            yield a, min(a + ROW_GROUP, n)

    def _schema(self) -> pa.Schema:
        import pyarrow as pa

        kinds = {"int32": pa.int32(), "float64": pa.float64(), "float32": pa.float32()}
        meta = {"fullpose.format": str(PARQUET_FORMAT),
                "fullpose.meta": json.dumps(self.meta, default=str)}
        return pa.schema([pa.field(c, kinds[self.precision(c)]) for c in self.columns],
                         metadata=meta)

    def _batch(self, schema: pa.Schema, a: int, b: int, exact: bool = False) -> pa.RecordBatch:
        """Rows a..b-1 as Arrow arrays of the schema's types (``exact``: reals in float64)."""
        import pyarrow as pa

        block = self.data[a:b]
        arrays = []
        for i, f in enumerate(schema):
            col = block[:, i]
            if pa.types.is_integer(f.type):
                arrays.append(pa.array(col.astype(np.int32)))
            elif exact or pa.types.is_float64(f.type):
                arrays.append(pa.array(np.ascontiguousarray(col)))
            else:
                arrays.append(pa.array(col.astype(np.float32)))
        return pa.RecordBatch.from_arrays(arrays, schema=schema)

    def write_parquet(self, path: Path) -> None:
        """``results.parquet`` (see the module docstring), written row group by row group."""
        import pyarrow.parquet as pq

        schema = self._schema()
        import pyarrow as pa

        ints = [f.name for f in schema if pa.types.is_integer(f.type)]
        floats = [f.name for f in schema if not pa.types.is_integer(f.type)]
        with pq.ParquetWriter(path, schema, compression="zstd", compression_level=3,
                              use_byte_stream_split=floats, use_dictionary=ints,
                              write_statistics=False) as writer:
            for a, b in self._chunks():
                writer.write_batch(self._batch(schema, a, b), row_group_size=ROW_GROUP)

    def write_csv(self, path: Path) -> None:
        """``results.csv``: exact float64 values in their shortest round-trip form."""
        import pyarrow as pa
        import pyarrow.csv as pacsv

        fields = [pa.field(c, pa.int64() if c in self.integer else pa.float64())
                  for c in self.columns]
        schema = pa.schema(fields)
        options = pacsv.WriteOptions(include_header=False, quoting_style="none")
        with open(path, "wb") as f:
            f.write((",".join(self.columns) + "\n").encode())
            for a, b in self._chunks():
                block = self.data[a:b]
                arrays = [pa.array(block[:, i].astype(np.int64)) if c in self.integer
                          else pa.array(np.ascontiguousarray(block[:, i]))
                          for i, c in enumerate(self.columns)]
                pacsv.write_csv(pa.RecordBatch.from_arrays(arrays, schema=schema), f, options)

    def write_npz(self, path: Path) -> None:
        """The earlier float64 format: compressed numpy archive with columns and metadata."""
        np.savez_compressed(path, data=self.data, columns=np.array(self.columns),
                            meta=np.array(json.dumps(self.meta, default=str)),
                            format_version=np.array(FORMAT_VERSION),
                            integer=np.array(sorted(self.integer), dtype=str))

    @classmethod
    def read(cls, path: str | Path) -> RunResult:
        """A results file (``.parquet``, ``.npz``, ``.csv``) or a results folder (its
        ``results.parquet``, else ``results.npz``, else ``results.csv``)."""
        p = Path(path)
        if p.is_dir():
            for name in (RESULTS_FILE, "results.npz", CSV_FILE):
                if (p / name).is_file():
                    return cls.read(p / name)
            raise ResultsFileError(f"{p}: no {RESULTS_FILE}, results.npz or {CSV_FILE} in it")
        readers = {".parquet": cls.read_parquet, ".npz": cls.read_npz, ".csv": cls.read_csv}
        reader = readers.get(p.suffix.lower())
        if reader is None:
            raise ResultsFileError(f"{p}: not a results file (.parquet, .npz or .csv)")
        if not p.is_file():
            raise ResultsFileError(f"{p}: file not found")
        return reader(p)

    @classmethod
    def read_parquet(cls, path: Path) -> RunResult:
        """Reads back exactly what :meth:`write_parquet` stored (float32 columns widened to
        float64 exactly)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            table = pq.read_table(path)
        except (OSError, pa.ArrowException) as e:
            raise ResultsFileError(f"{path}: not a readable Parquet file ({e})") from None
        kv = table.schema.metadata or {}
        version = kv.get(b"fullpose.format")
        if version is None:
            raise ResultsFileError(f"{path}: not a fullpose results file (no fullpose.format)")
        if int(version) != PARQUET_FORMAT:
            raise ResultsFileError(f"{path}: results format {int(version)}, expected "
                                   f"{PARQUET_FORMAT}")
        data = np.empty((table.num_rows, table.num_columns))
        integer = set()
        for i, f in enumerate(table.schema):
            data[:, i] = table.column(i).to_numpy()
            if pa.types.is_integer(f.type):
                integer.add(f.name)
        meta = json.loads(kv.get(b"fullpose.meta", b"{}"))
        return cls(columns=list(table.column_names), data=data, meta=meta,
                   integer=frozenset(integer))

    @classmethod
    def read_npz(cls, path: Path) -> RunResult:
        with np.load(path, allow_pickle=False) as z:
            if int(z["format_version"]) != FORMAT_VERSION:
                raise ResultsFileError(f"{path}: result format {int(z['format_version'])}, "
                                       f"expected {FORMAT_VERSION}")
            integer = frozenset(str(c) for c in z["integer"]) if "integer" in z else frozenset()
            return cls(columns=[str(c) for c in z["columns"]], data=np.array(z["data"]),
                       meta=json.loads(str(z["meta"])), integer=integer)

    @classmethod
    def read_csv(cls, path: Path) -> RunResult:
        import pyarrow as pa
        import pyarrow.csv as pacsv

        try:
            table = pacsv.read_csv(path)
        except (OSError, pa.ArrowException) as e:
            raise ResultsFileError(f"{path}: not a readable results CSV ({e})") from None
        data = np.empty((table.num_rows, table.num_columns))
        for i, f in enumerate(table.schema):
            if not (pa.types.is_integer(f.type) or pa.types.is_floating(f.type)):
                raise ResultsFileError(f"{path}: column {f.name!r} is not numeric")
            data[:, i] = table.column(i).to_numpy()
        # (which columns were Integer outputs is not in a CSV: a whole-valued real column
        # reads as integers too, so none is marked)
        return cls(columns=list(table.column_names), data=data)
