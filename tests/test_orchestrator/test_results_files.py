"""The results files (orchestrator/output/run_result.py) read by tools that are not ours.

Oracles: pyarrow's own Parquet reader (what pandas, polars and DuckDB use), Python's csv module
with ``float()``, and the in-memory recording the files were written from.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from orchestrator.output.run_result import ROW_GROUP, ResultsFileError, RunResult, round_float32

INTS = ("ctrl.guid_iter", "ctrl.feasible")


def sample(rows: int = int(2.5 * ROW_GROUP)) -> RunResult:
    rng = np.random.default_rng(7)
    columns = ["time", "plant.pos[1]", "plant.pos[2]", "ctrl.t_step", *INTS]
    data = np.empty((rows, len(columns)))
    data[:, 0] = np.arange(rows) * 0.002
    data[:, 1] = np.cumsum(rng.standard_normal(rows)) * 1e-3 + 3.0
    data[:, 2] = rng.standard_normal(rows) * 1e-12  # round-off sized values
    data[:, 3] = rng.uniform(1e-6, 3e-5, rows)
    data[:, 4] = rng.integers(0, 20, rows)
    data[:, 5] = rng.integers(0, 2, rows)
    data[7, 1] = -0.0  # signed zero and extremes survive too
    data[8, 1] = 1e300
    data[9, 1] = 5e-324
    return RunResult(columns, data, {"scenario": "synthetic", "step": 0.002},
                     integer=frozenset(INTS))


def test_parquet_is_typed_streamed_and_readable_without_fullpose(tmp_path: Path):
    r = sample()
    path = tmp_path / "results.parquet"
    r.write_parquet(path)
    f = pq.ParquetFile(path)
    assert f.metadata.num_row_groups == math.ceil(r.data.shape[0] / ROW_GROUP)
    types = {fld.name: fld.type for fld in f.schema_arrow}
    assert types["time"] == pa.float64() and types["plant.pos[2]"] == pa.float32()
    assert types["plant.pos[1]"] == pa.float64()  # it holds 1e300: float32 would make it inf
    assert all(types[c] == pa.int32() for c in INTS)
    table = pq.read_table(path)
    assert table.column_names == r.columns
    for name in r.columns:
        got = table.column(name).to_numpy()
        assert np.array_equal(got.astype(np.float64), r.stored(name)), name
    meta = json.loads(table.schema.metadata[b"fullpose.meta"])
    assert meta == r.meta
    precision = json.loads(table.schema.metadata[b"fullpose.precision"])
    assert precision == {"rounded_bits": 16, "rounded": ["ctrl.t_step"]}
    # a position keeps float32's relative 2**-24 (0.2 um at 3 m); the rest is rounded to 16
    # significant bits, a relative 2**-16: below any bound a test or plot has
    back = RunResult.read(path)
    np.testing.assert_allclose(back.get("plant.pos[2]"), r.get("plant.pos[2]"),
                               rtol=2.0**-24, atol=0)
    np.testing.assert_allclose(back.get("ctrl.t_step"), r.get("ctrl.t_step"),
                               rtol=2.0**-16, atol=0)
    assert back.integer == r.integer and back.meta == r.meta
    # rounding is idempotent: what was read back is written back unchanged
    back.write_parquet(tmp_path / "again.parquet")
    assert np.array_equal(RunResult.read(tmp_path / "again.parquet").data, back.data)


def test_rounding_to_16_bits_against_the_float64_values():
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.standard_normal(20000) * 10.0 ** rng.integers(-30, 30, 20000),
                        [0.0, -0.0, np.inf, -np.inf, np.nan, 3.4028235e38, -3.4028235e38]])
    x32 = x.astype(np.float32)
    y = round_float32(x32)
    normal = np.isfinite(x32) & (np.abs(x32) >= np.finfo(np.float32).tiny)
    # nearest at 16 bits: within half a unit of the 16th bit, relative 2**-16
    assert np.all(np.abs(y[normal].astype(np.float64) - x32[normal])
                  <= 2.0**-16 * np.abs(x32[normal].astype(np.float64)))
    assert np.all(y.view(np.uint32)[normal] & 0xFF == 0)  # the 8 low bits are gone
    assert np.isnan(y[-3]) and y[-5] == np.inf and y[-4] == -np.inf
    assert np.all(np.isfinite(y[-2:])) and math.copysign(1.0, float(y[-6])) == -1.0
    assert np.array_equal(round_float32(y), y, equal_nan=True)
    # round half to even: 1 + 2**-16 lies halfway between two 16-bit neighbours
    assert round_float32(np.float32([1 + 2.0**-16]))[0] == 1.0


def test_values_beyond_float32_keep_their_column_in_float64(tmp_path: Path):
    r = sample(100)
    r.data[3, 3] = np.nan  # a non-finite value does not widen a column
    r.write_parquet(tmp_path / "r.parquet")
    back = RunResult.read(tmp_path / "r.parquet")
    assert back.data[8, 1] == 1e300 and back.data[9, 1] == 5e-324  # no inf, no flush to 0
    assert math.copysign(1.0, back.data[7, 1]) == -1.0
    assert r.precision("ctrl.t_step") == "float32r16" and np.isnan(back.data[3, 3])


def test_csv_is_exact_and_parsed_by_the_csv_module(tmp_path: Path):
    r = sample(5000)
    path = tmp_path / "results.csv"
    r.write_csv(path)
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == r.columns
    values = np.array([[float(x) for x in row] for row in rows[1:]])
    assert np.array_equal(values, r.data)  # float64 exactly: shortest round-trip repr
    assert all(rows[5][r.columns.index(c)].lstrip("-").isdigit() for c in INTS)
    assert np.array_equal(RunResult.read(path).data, r.data)


def test_npz_of_earlier_versions_still_reads(tmp_path: Path):
    r = sample(300)
    r.write_npz(tmp_path / "results.npz")
    back = RunResult.read(tmp_path)  # a folder with only the npz
    assert np.array_equal(back.data, r.data) and back.columns == r.columns
    r.write_parquet(tmp_path / "results.parquet")
    assert RunResult.read(tmp_path).integer == r.integer  # the Parquet file is preferred


@pytest.mark.parametrize("content, suffix, reason", [
    (None, ".parquet", "file not found"),
    (b"not parquet", ".parquet", "not a readable Parquet file"),
    (b"x", ".txt", "not a results file"),
    (b"a,b\n1,x\n", ".csv", "is not numeric"),
])
def test_unreadable_results_name_the_file(tmp_path: Path, content: bytes | None, suffix: str,
                                          reason: str):
    path = tmp_path / f"results{suffix}"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(ResultsFileError, match=reason) as e:
        RunResult.read(path)
    assert str(path) in str(e.value)


def test_foreign_parquet_is_refused(tmp_path: Path):
    path = tmp_path / "other.parquet"
    pq.write_table(pa.table({"x": [1.0, 2.0]}), path)
    with pytest.raises(ResultsFileError, match="not a fullpose results file"):
        RunResult.read(path)
    with pytest.raises(ResultsFileError, match=r"no results\.parquet"):
        RunResult.read(tmp_path)


def test_writing_and_reading_results_imports_no_pandas(tmp_path: Path):
    """pyarrow's numpy conversions import pandas when it is installed (half a second of
    the main job): the results files go through the values buffers instead."""
    pytest.importorskip("pandas")  # (where pandas is absent there is nothing to avoid)
    code = f"""
import sys
from tests.test_orchestrator.test_results_files import sample
r = sample(1000)
r.write_parquet(r"{tmp_path}/r.parquet")
r.write_csv(r"{tmp_path}/r.csv")
from orchestrator.output.run_result import RunResult
RunResult.read(r"{tmp_path}/r.parquet")
RunResult.read(r"{tmp_path}/r.csv")
print("pandas" in sys.modules)
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[2])
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


def test_a_foreign_column_with_nulls_or_text_is_refused_by_name(tmp_path: Path):
    table = pa.table({"time": pa.array([0.0, 0.002, None]), "x": pa.array([1.0, 2.0, 3.0])},
                     metadata={"fullpose.format": "3"})
    pq.write_table(table, tmp_path / "nulls.parquet")
    with pytest.raises(ResultsFileError, match=r"column 'time' has 1 empty values"):
        RunResult.read(tmp_path / "nulls.parquet")
    (tmp_path / "text.csv").write_text("time,x\n0,a\n0.002,b\n")
    with pytest.raises(ResultsFileError, match=r"column 'x' is not numeric"):
        RunResult.read(tmp_path / "text.csv")


@pytest.mark.parametrize("rows", [0, 1])
def test_runs_of_no_row_and_one_row_round_trip(tmp_path: Path, rows: int):
    data = np.array([[0.0, 3.0 + 1e-9, 4.0, 1.0]])[:rows]
    r = RunResult(["time", "plant.pos[1]", *INTS], data, integer=frozenset(INTS))
    for name in ("r.parquet", "r.csv"):
        getattr(r, "write_" + name.split(".")[1])(tmp_path / name)
        back = RunResult.read(tmp_path / name)
        assert back.columns == r.columns and back.data.shape == r.data.shape, name
        stored = np.stack([r.stored(c) for c in r.columns], axis=1) if rows else r.data
        assert np.array_equal(back.data, stored if name.endswith("parquet") else r.data,
                              equal_nan=True)
