"""Scenario runs on the FMI 3.0 FMUs: the same model code behind the FMI 3.0 glue, flown by
the same master through the FMI 3.0 adapter of the step kernel, gives the FMI 2.0 run's
results bit for bit (every recorded column of every shipped scenario).  Oracle: the FMI 2.0
run of the same scenario."""

from dataclasses import replace

import numpy as np
import pytest

from orchestrator.master import run
from orchestrator.scenario.catalogue import list_scenarios, load_scenario
from orchestrator.sim.fmu import FmuError


def fmi3_available() -> bool:
    from controller import controller_fmu
    from plant import plant_fmu

    try:
        plant_fmu(3), controller_fmu(3)
    except Exception:
        return False
    return True


pytestmark = pytest.mark.skipif(not fmi3_available(), reason="FMI 3.0 FMUs not built")


def same(a, b) -> None:
    assert a.columns == b.columns
    assert a.data.shape == b.data.shape
    bad = [c for i, c in enumerate(a.columns)
           if not np.array_equal(a.data[:, i], b.data[:, i], equal_nan=True)]
    assert not bad, f"columns differ: {bad[:5]}"


@pytest.mark.parametrize("engine", ["native", "python"])
def test_hover_on_fmi3_is_the_fmi2_run_bit_for_bit(engine):
    sc = load_scenario("position_step")
    sc = replace(sc, duration=2.0)
    two = run(sc, progress=False, engine=engine)
    three = run(replace(sc, fmi=3), progress=False, engine=engine)
    assert three.meta["fmi"] == 3 and two.meta["fmi"] == 2
    same(two, three)


def test_a_refused_parameter_is_named_on_fmi3_too():
    sc = load_scenario("hover")
    bad = replace(sc, fmi=3, controller_parameters={**sc.controller_parameters,
                                                    "poly_margin": 2.0})
    with pytest.raises(FmuError) as e:
        run(bad, progress=False)
    assert "poly_margin" in str(e.value)


@pytest.mark.heavy
def test_every_shipped_scenario_is_bit_identical_on_fmi3():
    for sc in list_scenarios():
        same(run(sc, progress=False), run(replace(sc, fmi=3), progress=False))


def test_the_documented_fmpy_closed_loop_hovers(tmp_path, monkeypatch, capsys):
    """docs/fmpy.md's FMI 3.0 example, run as written on the built FMUs: it hovers at the
    default pose, the origin, within a micrometre (the controller holds its reference)."""
    import re
    import shutil
    from pathlib import Path

    from controller import controller_fmu
    from plant import plant_fmu

    text = (Path(__file__).resolve().parents[2] / "docs" / "fmpy.md").read_text()
    section = text[text.index("## FMI 3.0: the closed loop"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    (tmp_path / "fmi3").mkdir()
    shutil.copy(plant_fmu(3), tmp_path / "fmi3")
    shutil.copy(controller_fmu(3), tmp_path / "fmi3")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(code, "docs/fmpy.md", "exec"), namespace)
    assert np.allclose(namespace["pos"], [0.0, 0.0, 0.0], atol=1e-6), namespace["pos"]
