"""Every command with a user's own airframe file and the shipped non-paper ones (X8, Y6), as
a user types them: `run`, `check`, `view`, `sweep`, `export-ssp` take `--airframe`; a
results folder carries the airframe it flew, so its figures and 3-D view survive the
airframe file being edited or deleted; mistakes are one line, exit status 2."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import cli

import plant
from orchestrator.output.run_result import RunResult
from plant.airframe import Airframe


@pytest.fixture(scope="module")
def my_frame(tmp_path_factory) -> Path:
    """The user's airframe: the shipped X8 file renamed and made heavier."""
    folder = tmp_path_factory.mktemp("frame")
    text = (Path(plant.__file__).parent / "airframes" / "x8_coaxial.toml").read_text()
    path = folder / "my_x8.toml"
    path.write_text(text.replace('name = "x8_coaxial"', 'name = "my_x8"')
                    .replace("mass = 1.6", "mass = 1.9"))
    return path


@pytest.fixture(scope="module")
def flown(my_frame, tmp_path_factory):
    """`fullpose run position_step --airframe my_x8.toml` with its figures."""
    out = tmp_path_factory.mktemp("run") / "results"
    res = cli("run", "position_step", "--airframe", str(my_frame), "--duration", "4",
              "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert "airframe my_x8" in res.stdout
    return out


def test_run_records_the_airframe_it_flew(flown, my_frame):
    result = RunResult.read(flown)
    flew = plant.load_airframe(my_frame)
    assert result.meta["airframe_record"] == flew.record()
    assert result.meta["airframe_digest"] == flew.digest()
    back = Airframe.from_record(result.meta["airframe_record"])
    assert back.digest() == flew.digest() and back.mass == 1.9
    pos = result.get("plant.pos")
    assert abs(pos[-1, 0] - 1.0) < 0.02  # the 1 m step, flown on the heavier X8
    for png in ("tracking.png", "force_set.png", "actuators.png"):
        assert (flown / png).stat().st_size > 10_000, png
    # the force sets it flew: the X8's design-time ones (a heavier X8 has the same rotors),
    # S(0) the vertical thrust segment that holds the heavier weight (statics)
    sets = json.loads((flown / "force_sets.json").read_text())
    assert sets["source"] == "design" and len(sets["failures"]) == 8
    A, b = np.array(sets["s0"]["A"]), np.array(sets["s0"]["b"])
    assert np.all(A @ [0.0, 0.0, -1.9 * 9.81] <= b + 1e-9)
    assert not np.all(A @ [0.0, 0.0, -8.1 * flew.k_t * flew.omega_max ** 2] <= b + 1e-9)


def test_view_reads_the_recorded_airframe_after_the_file_is_gone(flown, my_frame, tmp_path):
    pytest.importorskip("rerun", reason="the view extra: pip install '.[view]'")
    moved = tmp_path / "kept.toml"
    shutil.move(my_frame, moved)  # the file the run named no longer exists
    try:
        rrd = tmp_path / "replay.rrd"
        res = cli("view", str(flown), "--save", str(rrd))
        assert res.returncode == 0, res.stderr
        assert rrd.stat().st_size > 0
    finally:
        shutil.move(moved, my_frame)


@pytest.mark.parametrize("airframe", ["x8_coaxial", "y6"])
def test_check_and_sweep_on_the_shipped_non_paper_airframes(airframe, tmp_path):
    res = cli("check", "position_step", "--airframe", airframe)
    assert res.returncode == 0, res.stderr
    assert f"airframe {airframe}" in res.stdout
    res = cli("sweep", "--cases", "2", "--duration", "2", "--designs", "hinf",
              "--airframe", airframe, "--out", str(tmp_path / "sweep"))
    assert res.returncode == 0, res.stderr
    assert "stable 100 %" in res.stdout


def test_export_ssp_of_the_y6_gives_both_fmus_the_y6(tmp_path):
    """Both components' parameter sets carry the Y6's numbers (read back from the SSV
    files with lxml), the same in both FMUs."""
    from lxml import etree

    out = tmp_path / "y6.ssp"
    res = cli("export-ssp", str(out), "--airframe", "y6")
    assert res.returncode == 0, res.stderr
    ns = {"ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}
    values = {}
    with zipfile.ZipFile(out) as z:
        for name in z.namelist():
            if name.endswith(".ssv"):
                root = etree.fromstring(z.read(name))
                values[name] = {p.get("name"): next(iter(p)).get("value")
                                for p in root.findall("ssv:Parameters/ssv:Parameter", ns)}
    assert len(values) == 2
    y6 = plant.load_airframe("y6")
    for params in values.values():
        assert int(params["n_rotors"]) == 6
        got = np.array([[float(params[f"rotor_pos[{i},{j}]"]) for j in (1, 2, 3)]
                        for i in range(1, 7)])
        assert np.array_equal(got, y6.positions)
        assert float(params["mass"]) == y6.mass


@pytest.mark.parametrize("args,names", [
    (["run", "hover", "--airframe", "no_such_frame"], "no_such_frame"),
    (["check", "hover", "--airframe", "no_such_frame"], "no_such_frame"),
    (["sweep", "--cases", "1", "--airframe", "no_such_frame"], "no_such_frame"),
])
def test_a_wrong_airframe_is_one_line_and_exit_2(args, names, tmp_path):
    res = cli(*args, "--out", str(tmp_path / "out")) if args[0] != "check" else cli(*args)
    assert res.returncode == 2, res.stdout + res.stderr
    assert res.stderr.startswith("fullpose: error:") and names in res.stderr
    assert "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_an_unknown_airframe_field_suggests_the_right_one(tmp_path):
    bad = tmp_path / "typo.toml"
    text = (Path(plant.__file__).parent / "airframes" / "y6.toml").read_text()
    bad.write_text(text.replace("gravity = 9.81", "gravty = 9.81"))
    res = cli("check", "hover", "--airframe", str(bad))
    assert res.returncode == 2
    assert "gravty" in res.stderr and "did you mean 'gravity'" in res.stderr


def test_a_fault_on_a_rotor_the_airframe_lacks_is_refused(tmp_path):
    scenario = tmp_path / "six.toml"
    scenario.write_text('duration = 1.0\nairframe = "paper_hexacopter"\n'
                        "[reference.position]\nz = -3.0\n"
                        "[[fault]]\ntime = 0.5\nrotor = 6\nefficiency = 0.0\n")
    res = cli("run", str(scenario), "--airframe", "quadrotor", "--out", str(tmp_path / "o"))
    assert res.returncode == 2
    assert "fault.rotor" in res.stderr and "quadrotor" in res.stderr
    assert not (tmp_path / "o").exists()
