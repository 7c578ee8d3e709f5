"""Every row of the bad-input table in docs/errors.md, run as written with the installed
``fullpose`` command: its exit status and its message on stderr, no traceback, and nothing
lost or half-written (the previous results stay byte for byte, no temporary folder remains).

The table and the files it uses are read from the document itself, so the document cannot
drift from what the product does.
"""

import hashlib
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sysconfig
import time
from pathlib import Path

import numpy as np
import pytest

from orchestrator.output.run_result import RunResult

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "errors.md"
FULLPOSE = Path(sysconfig.get_path("scripts")) / ("fullpose.exe" if os.name == "nt" else "fullpose")
CELL = re.compile(r"(?<!\\)\|")


LATIN_1 = "(saved as Latin-1)"
"""A file's first line ending so: the file is written in Latin-1, not UTF-8."""


def doc_files() -> dict[str, str]:
    """The TOML files of the document: code blocks whose first line is ``# NAME``
    (``# NAME (saved as Latin-1)``: see :func:`write_doc_file`)."""
    files = {}
    for block in re.findall(r"```toml\n(.*?)```", DOC.read_text(), flags=re.S):
        first, _, _ = block.partition("\n")
        files[first.lstrip("# ").removesuffix(LATIN_1).strip()] = block
    return files


def write_doc_file(folder: Path, name: str, text: str) -> None:
    first, _, _ = text.partition("\n")
    (folder / name).write_bytes(text.encode("latin-1" if first.endswith(LATIN_1) else "utf-8"))


def doc_rows() -> list[dict]:
    rows = []
    lines = DOC.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| id |"))
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in CELL.split(line.strip())[1:-1]]
        ident, _, command, status, seen = cells
        rows.append({
            "id": ident,
            "command": re.search(r"`([^`]*)`", command).group(1),
            "interrupt": command.endswith("interrupted"),
            "status": int(status),
            "messages": [m.replace("\\|", "|") for m in re.findall(r"`([^`]*)`", seen)],
        })
    return rows


def pattern(message: str) -> re.Pattern:
    return re.compile(re.escape(message).replace(re.escape("..."), ".+?"))


def tree_digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def previous_results(tmp_path_factory) -> Path:
    """Results of an earlier run (the folder the table's ``prev`` holds)."""
    out = tmp_path_factory.mktemp("prev") / "prev"
    res = subprocess.run([str(FULLPOSE), "run", "hover_varying_orientation", "--duration", "2",
                          "--no-plots", "--out", str(out)], capture_output=True, text=True,
                         timeout=300, check=False)
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture
def workdir(tmp_path, previous_results) -> Path:
    for name, text in doc_files().items():
        write_doc_file(tmp_path, name, text)
    (tmp_path / "afile").write_text("not a folder\n")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("the user's own notes\n")
    shutil.copytree(previous_results, tmp_path / "prev")
    return tmp_path


def run_row(row: dict, cwd: Path) -> subprocess.CompletedProcess:
    args = shlex.split(row["command"])
    assert args[0] == "fullpose"
    if not FULLPOSE.is_file():
        pytest.fail(f"{FULLPOSE} missing: `pip install .` installs the fullpose command")
    cmd = [str(FULLPOSE), *args[1:]]
    if not row["interrupt"]:
        return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=600,
                              check=False)
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().startswith("running")  # the run has started ...
    time.sleep(1.0)  # ... and is stepping (a 100 s run takes several seconds)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


ROWS = doc_rows()


def test_the_table_covers_every_kind_of_bad_input_the_issue_names():
    ids = {r["id"] for r in ROWS}
    assert {"plant-param", "ctrl-param", "unstable-gains", "lost-position", "radians",
            "huge-duration", "out-under-file", "interrupted"} <= ids
    assert {"int-range", "int-32-bits", "not-utf8", "deep-nesting", "airframe-overflow",
            "signal-overflow", "millimetres"} <= ids
    assert {"airframe-thrust", "airframe-speed", "airframe-grams"} <= ids
    assert set(doc_files()) == {"radians.toml", "far.toml", "unstable.toml", "weak.toml",
                                "fast.toml", "feeble.toml", "spin.toml", "mm.toml",
                                "latin1.toml", "deep.toml", "overflow.toml"}


@pytest.mark.parametrize("row", ROWS, ids=[r["id"] for r in ROWS])
def test_bad_input_row(row, workdir):
    before = {name: tree_digest(workdir / name) for name in ("prev", "mine")}
    res = run_row(row, workdir)
    assert res.returncode == row["status"], res.stdout + res.stderr
    assert "Traceback" not in res.stderr + res.stdout
    for message in row["messages"]:
        assert pattern(message).search(res.stderr), (message, res.stderr)
    # nothing lost: results of an earlier run and the user's files are as they were ...
    for name, digest in before.items():
        assert tree_digest(workdir / name) == digest, name
    # ... and nothing half-written beside them
    assert not [p.name for p in workdir.iterdir() if p.name.startswith(".")]
    assert not (workdir / "loop.ssp").exists()  # a refused export writes no archive
    if row["id"].startswith("lost"):
        check_lost_results(workdir / "lost")


def check_lost_results(out: Path) -> None:
    """A lost run's results: whole, ending where the vehicle was lost, with the outcome."""
    doc = json.loads((out / "metrics.json").read_text())
    m = doc["metrics"]
    assert m["outcome"] == "lost" and m["lost"]["time"] > 0 and m["lost"]["reason"]
    assert all("not comparable" in line for line in doc["paper"][:1])
    result = RunResult.read(out)
    err = np.linalg.norm(result.get("plant.pos") - result.get("ref.pos_ref"), axis=1)
    euler = result.get("plant.euler")
    tilt = np.degrees(np.arccos(np.cos(euler[:, 0]) * np.cos(euler[:, 1])))
    beyond = (err > 10.0) | (tilt > 90.0)
    # the run stopped at the first sample beyond the bounds: the last one, and only it
    assert beyond[-1] and not beyond[:-1].any()
    assert result.time[-1] == pytest.approx(m["lost"]["time"])
    assert result.time[-1] < 20.0  # stopped early
    assert np.all(np.isfinite(result.data))
