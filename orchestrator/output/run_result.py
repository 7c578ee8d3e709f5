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
    every other signal float32 at one of two precisions (:meth:`RunResult.precision`):

    - the pose signals that tracking errors are differences of (:data:`POSE_SIGNALS`:
      position, attitude and their references) keep all 24 bits of a float32, a relative
      6e-8 (0.2 um at 3 m, 1e-7 rad);
    - every other signal (rates, accelerations, forces, actuators, diagnostics, compute
      times) is rounded to :data:`ROUNDED_BITS` significant bits, a relative 1.5e-5 (60 uN
      of a 4 N force, 0.015 rad/s of 1,000 rad/s, 11 urad of a 0.7 rad servo angle): below
      a plot's resolution and every test's bound, and the 8 low bits it drops are the noise
      that no lossless coder shrinks (they made a 100 s run 12.7 MB instead of 7.8).

    Rounding is to nearest-even and idempotent, so a file read back and written again is
    unchanged.  The run's metadata, the layout version and which columns are rounded are in
    the file's key-value metadata (``fullpose.meta``, ``fullpose.format``,
    ``fullpose.precision``).  Written in row groups of :data:`ROW_GROUP` rows, so writing
    needs memory for one row group only.  Readable as is by pandas, polars, DuckDB, Arrow in
    every language, MATLAB's ``parquetread`` and PlotJuggler.  For every value to the bit,
    ``--csv``.
``results.csv`` (on request)
    Header of column names, every value in float64 with the shortest representation that
    reads back to the same double (integers as integers): exact, ~20x larger.
``results.mcap`` (on request)
    The same for Foxglove and PlotJuggler (orchestrator/output/mcap_export.py); not read back here.
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
PARQUET_FORMAT = 3
"""Version of the Parquet layout written here (``fullpose.format`` in the file); 2 (every
real column in full float32) is still read."""
READ_FORMATS = frozenset({2, PARQUET_FORMAT})
RESULTS_FILE = "results.parquet"
CSV_FILE = "results.csv"
ROW_GROUP = 65536
"""Rows per Parquet row group (and per CSV chunk): the memory a write needs beyond the data."""
EXACT_FLOAT = frozenset({"time"})
"""Real columns stored in float64; every other real column is stored in float32."""
POSE_SIGNALS = frozenset({"plant.pos", "plant.pos_true", "plant.euler", "plant.euler_true",
                          "plant.quat", "plant.quat_true", "ref.pos_ref", "ref.euler_ref",
                          "ctrl.pos_ref_s", "ctrl.euler_ref_s"})
"""Signals kept in full float32: the ones a tracking error is the difference of, where
millimetres are read off metres (the paper's 2 cm bound at any range a scenario flies)."""
ROUNDED_BITS = 16
"""Significant bits kept of every other real signal in ``results.parquet``."""


def round_float32(x: np.ndarray, bits: int = ROUNDED_BITS) -> np.ndarray:
    """float32 values rounded to nearest-even at ``bits`` significant bits (of float32's
    24); NaN and infinities pass unchanged, and a value that would round past float32's
    largest finite is truncated instead, so no finite value becomes infinite."""
    drop = 24 - bits
    x = np.asarray(x, dtype=np.float32)
    if drop <= 0:
        return x
    u = np.ascontiguousarray(x).view(np.uint32)
    low = np.uint32((1 << drop) - 1)
    bias = np.uint32((1 << (drop - 1)) - 1) + ((u >> np.uint32(drop)) & np.uint32(1))
    out = ((u + bias) & ~low).view(np.float32)
    finite = np.isfinite(x)
    if not finite.all() or not np.isfinite(out).all():
        truncated = (u & ~low).view(np.float32)
        out = np.where(finite, np.where(np.isfinite(out), out, truncated), x)
    return out


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
        """The time column (s)."""
        return self.data[:, self._index["time"]]

    def has(self, name: str) -> bool:
        """Whether the result has a column name (a scalar, or a vector's first element)."""
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
        """How a column is stored in ``results.parquet``: ``int32``; ``float64`` (``time``,
        and any column with a finite value beyond float32's range, e.g. a diverging run's);
        ``float32`` (the pose signals); ``float32r16`` (every other real column: float32
        rounded to :data:`ROUNDED_BITS` significant bits)."""
        if name in self.integer:
            return "int32"
        if name in EXACT_FLOAT or name in self._wide():
            return "float64"
        return "float32" if name.split("[", 1)[0] in POSE_SIGNALS else f"float32r{ROUNDED_BITS}"

    def stored(self, name: str) -> np.ndarray:
        """One column as ``results.parquet`` holds it (and :meth:`read` gives it back), in
        float64."""
        return _as_stored(self.column(name), self.precision(name)).astype(np.float64)

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

        kinds = {"int32": pa.int32(), "float64": pa.float64()}
        rounded = [c for c in self.columns if self.precision(c).startswith("float32r")]
        meta = {"fullpose.format": str(PARQUET_FORMAT),
                "fullpose.meta": json.dumps(self.meta, default=str),
                "fullpose.precision": json.dumps(
                    {"rounded_bits": ROUNDED_BITS, "rounded": rounded})}
        return pa.schema([pa.field(c, kinds.get(self.precision(c), pa.float32()))
                          for c in self.columns],
                         metadata=meta)

    def _batch(self, schema: pa.Schema, a: int, b: int) -> pa.RecordBatch:
        """Rows a..b-1 as Arrow arrays of the schema's types, each column converted straight
        from the row-major recording (no transposed copy of the block: half the memory
        traffic, which the figure workers drawing beside the write contend for)."""
        import pyarrow as pa

        block = self.data[a:b]
        arrays = [_arrow(_as_stored(block[:, i], self.precision(f.name)))
                  for i, f in enumerate(schema)]
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
                arrays = [_arrow(block[:, i].astype(np.int64)) if c in self.integer
                          else _arrow(block[:, i]) for i, c in enumerate(self.columns)]
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
        """Reads back exactly what :meth:`write_parquet` stored (:meth:`stored`: float32
        columns widened to float64 exactly)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            table = pq.ParquetFile(path).read(use_pandas_metadata=False)
        except (OSError, pa.ArrowException) as e:
            raise ResultsFileError(f"{path}: not a readable Parquet file ({e})") from None
        kv = table.schema.metadata or {}
        version = kv.get(b"fullpose.format")
        if version is None:
            raise ResultsFileError(f"{path}: not a fullpose results file (no fullpose.format)")
        if int(version) not in READ_FORMATS:
            raise ResultsFileError(f"{path}: results format {int(version)}, expected one of "
                                   f"{sorted(READ_FORMATS)}")
        data = np.empty((table.num_rows, table.num_columns))
        integer = set()
        for i, f in enumerate(table.schema):
            _numpy_into(table.column(i), data[:, i], path, f.name)
            if pa.types.is_integer(f.type):
                integer.add(f.name)
        meta = json.loads(kv.get(b"fullpose.meta", b"{}"))
        return cls(columns=list(table.column_names), data=data, meta=meta,
                   integer=frozenset(integer))

    @classmethod
    def read_npz(cls, path: Path) -> RunResult:
        """A results file of earlier versions (numpy archive)."""
        with np.load(path, allow_pickle=False) as z:
            if int(z["format_version"]) != FORMAT_VERSION:
                raise ResultsFileError(f"{path}: result format {int(z['format_version'])}, "
                                       f"expected {FORMAT_VERSION}")
            integer = frozenset(str(c) for c in z["integer"]) if "integer" in z else frozenset()
            return cls(columns=[str(c) for c in z["columns"]], data=np.array(z["data"]),
                       meta=json.loads(str(z["meta"])), integer=integer)

    @classmethod
    def read_csv(cls, path: Path) -> RunResult:
        """A results.csv written by write_csv."""
        import pyarrow as pa
        import pyarrow.csv as pacsv

        try:
            table = pacsv.read_csv(path)
        except (OSError, pa.ArrowException) as e:
            raise ResultsFileError(f"{path}: not a readable results CSV ({e})") from None
        data = np.empty((table.num_rows, table.num_columns))
        for i, f in enumerate(table.schema):
            _numpy_into(table.column(i), data[:, i], path, f.name)
        # (which columns were Integer outputs is not in a CSV: a whole-valued real column
        # reads as integers too, so none is marked)
        return cls(columns=list(table.column_names), data=data)


# pyarrow's own numpy conversions (pa.array, Array.to_numpy) import pandas when it is
# installed, to look for pandas objects: half a second of the main job's writing, paid by
# every user who has pandas.  Numeric columns without nulls need none of it: their values
# buffer is the numpy array.

_NUMPY_OF = {"double": np.float64, "float": np.float32, "int64": np.int64, "int32": np.int32,
             "int16": np.int16, "int8": np.int8, "uint64": np.uint64, "uint32": np.uint32,
             "uint16": np.uint16, "uint8": np.uint8}
"""numpy's type of each Arrow numeric type, by its name (``str(pa.float32())`` is "float")."""


def _as_stored(col: np.ndarray, kind: str) -> np.ndarray:
    """A column in the type and precision ``kind`` (:meth:`RunResult.precision`) gives it in
    ``results.parquet``."""
    if kind == "int32":
        return col.astype(np.int32)
    if kind == "float64":
        return np.ascontiguousarray(col, dtype=np.float64)
    single = col.astype(np.float32)
    return single if kind == "float32" else round_float32(single)


def _arrow(values: np.ndarray) -> pa.Array:
    """A 1-D numeric numpy array as an Arrow array over the same memory (no nulls)."""
    import pyarrow as pa

    v = np.ascontiguousarray(values)
    return pa.Array.from_buffers(pa.from_numpy_dtype(v.dtype), len(v), [None, pa.py_buffer(v)])


def _numpy_into(column: Any, out: np.ndarray, path: Path, name: str) -> None:
    """``out[:] =`` an Arrow numeric column (a ChunkedArray), chunk by chunk; a column that
    is not numeric or holds nulls (not a results file of ours) is refused by name."""
    k = 0
    for chunk in column.chunks:
        if len(chunk) == 0:  # (a header-only CSV's columns have no type)
            continue
        dtype = _NUMPY_OF.get(str(chunk.type))
        if dtype is None:
            raise ResultsFileError(f"{path}: column {name!r} is not numeric ({chunk.type})")
        if chunk.null_count:
            raise ResultsFileError(f"{path}: column {name!r} has {chunk.null_count} empty "
                                   "values")
        n = len(chunk)
        values = np.frombuffer(chunk.buffers()[1], dtype=dtype, count=n,
                               offset=chunk.offset * np.dtype(dtype).itemsize)
        out[k:k + n] = values
        k += n
