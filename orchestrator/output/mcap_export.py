"""``results.mcap`` (``fullpose run --mcap``): a run as MCAP, the log format Foxglove and
PlotJuggler open as they are.

Why MCAP beside the Parquet results: Foxglove reads MCAP and not Parquet; PlotJuggler reads
both.  One topic per source of signals (``/ref``, ``/dist``, ``/plant``, ``/ctrl``), one
message per 2 ms row, log time = the run's time in nanoseconds.  Messages are JSON with a
JSON Schema per topic (the encoding both tools decode without generated code): a vector
signal is an array (``/plant`` ``pos[0]`` is x), a scalar a number, Integer and Boolean
outputs integers.  Values are the recording's float64 in their shortest exact form; a
non-finite value (none in a completed run) is written as null.  zstd-compressed chunks.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from orchestrator.output.run_result import RunResult

MCAP_FILE = "results.mcap"
PROFILE = ""  # no ROS: plain JSON messages


def _groups(result: RunResult) -> dict[str, dict[str, list[int]]]:
    """{source: {signal: [column indices]}} in recording order (``time`` left out)."""
    out: dict[str, dict[str, list[int]]] = {}
    for i, name in enumerate(result.columns):
        if "." not in name:
            continue
        source, signal = name.split(".", 1)
        base = signal.split("[", 1)[0]
        out.setdefault(source, {}).setdefault(base, []).append(i)
    return out


def _schema(result: RunResult, signals: dict[str, list[int]]) -> dict[str, Any]:
    props: dict[str, Any] = {}
    for base, cols in signals.items():
        integer = all(result.columns[c] in result.integer for c in cols)
        item = {"type": ["integer" if integer else "number", "null"]}
        single = len(cols) == 1 and "[" not in result.columns[cols[0]]
        props[base] = item if single else {"type": "array", "items": item,
                                           "minItems": len(cols), "maxItems": len(cols)}
    return {"type": "object", "properties": props, "required": list(props)}


def _value(x: float, integer: bool) -> float | int | None:
    if not math.isfinite(x):
        return None
    return int(x) if integer else x


def write_mcap(result: RunResult, path: Path) -> None:
    """Writes ``result`` as MCAP (module docstring)."""
    from mcap.writer import CompressionType, Writer

    t_ns = np.round(np.asarray(result.time) * 1e9).astype(np.int64)
    data = result.data
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile=PROFILE, library="fullpose")
        topics = []
        for source, signals in _groups(result).items():
            sid = w.register_schema(name=f"fullpose.{source}", encoding="jsonschema",
                                    data=json.dumps(_schema(result, signals)).encode())
            cid = w.register_channel(topic=f"/{source}", message_encoding="json",
                                     schema_id=sid)
            layout = [(base, cols, len(cols) == 1 and "[" not in result.columns[cols[0]],
                       all(result.columns[c] in result.integer for c in cols))
                      for base, cols in signals.items()]
            topics.append((cid, layout))
        w.add_metadata("fullpose", {"meta": json.dumps(result.meta, default=str)})
        # each topic's message as one format string: %r is the shortest exact repr of a
        # finite float (json's own), %d an integer; rows with a non-finite value take the
        # slower road through json.dumps
        forms = [(cid, _template(layout), [c for _b, cols, _s, _i in layout for c in cols],
                  layout) for cid, layout in topics]
        finite = np.all(np.isfinite(data), axis=1)
        for k in range(data.shape[0]):
            row = data[k].tolist()
            when = int(t_ns[k])
            for cid, form, order, layout in forms:
                if finite[k]:
                    text = form % tuple([row[c] for c in order])
                else:
                    text = json.dumps({base: (_value(row[cols[0]], integer) if single
                                              else [_value(row[c], integer) for c in cols])
                                       for base, cols, single, integer in layout})
                w.add_message(cid, log_time=when, publish_time=when, data=text.encode())
        w.finish()


def _template(layout: list[tuple[str, list[int], bool, bool]]) -> str:
    parts = []
    for base, cols, single, integer in layout:
        one = "%d" if integer else "%r"
        value = one if single else "[" + ",".join([one] * len(cols)) + "]"
        parts.append(json.dumps(base) + ":" + value)
    return "{" + ",".join(parts) + "}"

