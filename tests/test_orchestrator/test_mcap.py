"""results.mcap (``fullpose run --mcap``) read back with the mcap package's own reader and
checked, message by message, against the exact CSV of the same run; each topic's messages
validate against the JSON Schema the file carries (jsonschema, independent of our writer)."""

from __future__ import annotations

import json
import subprocess
import sys

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from orchestrator.output.run_result import RunResult


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    out = tmp_path_factory.mktemp("mcap") / "r"
    res = subprocess.run([sys.executable, "-m", "orchestrator.cli", "run",
                          "rotor_failure_detected", "--duration", "2.5", "--no-plots", "--csv",
                          "--mcap", "--out", str(out)], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    assert "results.mcap" in res.stdout
    return out, RunResult.read(out / "results.csv")


def test_every_row_of_every_signal_exactly(written):
    out, exact = written
    with open(out / "results.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert sorted(topics) == ["/ctrl", "/dist", "/plant", "/ref"]
        assert all(c.message_encoding == "json" for c in topics.values())
        schemas = {c.topic: json.loads(summary.schemas[c.schema_id].data)
                   for c in topics.values()}
        assert all(s.encoding == "jsonschema" for s in summary.schemas.values())
        got: dict[str, list[dict]] = {t: [] for t in topics}
        times: dict[str, list[int]] = {t: [] for t in topics}
        for _schema, channel, message in reader.iter_messages(log_time_order=True):
            got[channel.topic].append(json.loads(message.data))
            times[channel.topic].append(message.log_time)
    n = exact.data.shape[0]
    for topic, msgs in got.items():
        assert len(msgs) == n, topic
        np.testing.assert_array_equal(np.array(times[topic]) / 1e9, np.round(exact.time, 9))
        for m in msgs[:: max(1, n // 50)]:
            jsonschema.validate(m, schemas[topic])
    for i, name in enumerate(exact.columns):
        if name == "time":
            continue
        source, signal = name.split(".", 1)
        base, _, index = signal.partition("[")
        values = [m[base][int(index[:-1]) - 1] if index else m[base] for m in got[f"/{source}"]]
        np.testing.assert_array_equal(np.array(values, dtype=float), exact.data[:, i], name)
        if name in exact.integer:
            assert all(isinstance(v, int) for v in values), name


def test_metadata_carries_the_run(written):
    out, _ = written
    with open(out / "results.mcap", "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    run_meta = RunResult.read(out).meta  # the Parquet file's (the CSV has none)
    assert json.loads(meta["fullpose"]["meta"]) == json.loads(json.dumps(run_meta, default=str))
    assert run_meta["scenario"] == "rotor_failure_detected"
