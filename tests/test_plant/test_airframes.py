"""Airframe files: shipped ones load, bad ones fail naming file and field."""

import math
from pathlib import Path

import numpy as np
import pytest

import plant
from plant.airframe import AirframeError, load_airframe

GOOD = """
name = "custom"
[body]
mass = 1.0
inertia = [0.01, 0.01, 0.018]
[propulsion]
k_t = 1.0e-4
k_d = 1.0e-6
omega_max_rpm = 3000
time_constant = 0.02
[servo]
time_constant = 0.03
alpha_limits_deg = [-30, 30]
beta_limits_deg = [-20, 25]
[ring]
count = 4
radius = 0.2
first_azimuth_deg = 45
spin = [1, -1, 1, -1]
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "frame.toml"
    p.write_text(text)
    return p


def test_shipped_airframes():
    assert plant.list_airframes() == ["fixed_tilt_hexarotor", "paper_hexacopter", "quadrotor",
                                      "x8_coaxial", "y6"]


def test_paper_hexacopter_is_table_1():
    af = load_airframe("paper_hexacopter")
    assert af.mass == 0.6656
    np.testing.assert_array_equal(np.diag(af.inertia), [0.0041, 0.0048, 0.0599])
    assert af.k_t == 1.14e-4 and af.k_d == 1.14e-6
    assert af.omega_max == pytest.approx(2000 * 2 * math.pi / 60)
    assert af.tau_motor == pytest.approx(1 / 53.94) and af.tau_servo == pytest.approx(1 / 53.94)
    np.testing.assert_allclose(np.linalg.norm(af.positions, axis=1), 0.15)
    np.testing.assert_allclose(af.alpha_limits, np.radians([[-40, 40]] * 6))
    np.testing.assert_allclose(af.beta_limits, np.radians([[-40, 40]] * 6))
    assert af.tilting and list(af.spins) == [1, -1, 1, -1, 1, -1]
    # about 933 rpm to hover, as the prototype found
    assert af.hover_trim()[2][0] * 60 / (2 * math.pi) == pytest.approx(933, abs=1)


def test_fixed_tilt_and_quadrotor():
    hexa = load_airframe("fixed_tilt_hexarotor")
    assert not hexa.tilting
    np.testing.assert_allclose(np.abs(hexa.alpha_limits), math.radians(20))
    assert np.all(hexa.alpha_limits[:, 0] == hexa.alpha_limits[:, 1])  # no servos
    quad = load_airframe("quadrotor")
    assert quad.n_rotors == 4 and not quad.tilting
    np.testing.assert_array_equal(quad.alpha_limits, 0)


def test_fmu_parameters_cover_all_rotor_slots():
    p = load_airframe("quadrotor").fmu_parameters()
    assert p["n_rotors"] == 4
    assert p["rotor_pos[8,3]"] == 0.0 and p["rotor_dir[8]"] == 1
    assert p["inertia[3,3]"] == 0.013
    assert p["omega_max"] == pytest.approx(2000 * 2 * math.pi / 60)


def test_custom_file_and_explicit_rotor_list(tmp_path):
    af = load_airframe(write(tmp_path, GOOD))
    assert af.name == "custom" and af.n_rotors == 4
    np.testing.assert_allclose(af.beta_limits[0], np.radians([-20, 25]))
    text = GOOD.split("[ring]")[0] + "".join(
        f"[[rotor]]\nposition = [{x}, {y}, 0.0]\nspin = {s}\ngamma_deg = 10\n"
        for x, y, s in [(0.2, 0, 1), (0, 0.2, -1), (-0.2, 0, 1), (0, -0.2, -1)])
    af = load_airframe(write(tmp_path, text))
    np.testing.assert_allclose(af.gamma, math.radians(10))


@pytest.mark.parametrize(
    ("old", "new", "field", "reason"),
    [
        ("mass = 1.0", "mass = 0", "body.mass", "positive"),
        ("mass = 1.0", "mass = -2", "body.mass", "positive"),
        ("mass = 1.0", 'mass = "heavy"', "body.mass", "number"),
        ("mass = 1.0", "mass = nan", "body.mass", "finite"),
        ("mass = 1.0\n", "", "body.mass", "missing"),
        ("inertia = [0.01, 0.01, 0.018]", "inertia = [0.01, -0.01, 0.018]", "body.inertia",
         "positive definite"),
        ("inertia = [0.01, 0.01, 0.018]",
         "inertia = [[0.01, 0.002, 0], [0, 0.01, 0], [0, 0, 0.02]]", "body.inertia", "symmetric"),
        ("inertia = [0.01, 0.01, 0.018]", "inertia = [0.01, 0.01]", "body.inertia", "3 numbers"),
        ("k_t = 1.0e-4", "k_t = 0.0", "propulsion.k_t", "positive"),
        ("omega_max_rpm = 3000", "omega_max_rpm = 3000\nomega_min_rpm = 4000",
         "propulsion.omega_min_rpm", "exceeds"),
        ("alpha_limits_deg = [-30, 30]", "alpha_limits_deg = [30, -30]",
         "servo.alpha_limits_deg", "exceeds"),
        ("alpha_limits_deg = [-30, 30]", "alpha_limits_deg = [-30]", "servo.alpha_limits_deg",
         "2 numbers"),
        ("count = 4", "count = 9", "ring.count", "1..8"),
        ("count = 4", "count = 2.5", "ring.count", "integer"),
        ("spin = [1, -1, 1, -1]", "spin = [1, -1, 1, 0]", "ring.spin", "+1 or -1"),
        ("spin = [1, -1, 1, -1]", "spin = [1, -1, 1]", "ring.spin", "4 numbers"),
        ("radius = 0.2", "radius = 0.2\ncolour = 'red'", "ring.colour", "unknown field"),
        ("[ring]", "[rings]", "ring", "exactly one"),
        ('name = "custom"', "", "name", "missing"),
        # numbers a file may hold whose square overflows a double (an OverflowError
        # traceback in the force-set tools), or that are beyond a double themselves
        ("omega_max_rpm = 3000", "omega_max_rpm = 1e300", "propulsion.omega_max_rpm",
         "1.0472e+299 rad/s: its square, 1.0472e+299^2 (rad/s)^2, is beyond the range of a "
         "double"),
        ("k_t = 1.0e-4\nk_d = 1.0e-6\nomega_max_rpm = 3000",
         "k_t = 1e20\nk_d = 1.0e-6\nomega_max_rpm = 1e150", "propulsion.omega_max_rpm",
         "the rotor thrust k_t omega_max^2 = 1e+20 x 1.0966e+298"),
        ("k_d = 1.0e-6", "k_d = 1e305", "propulsion.omega_max_rpm",
         "the rotor drag torque k_d omega_max^2"),
        ("omega_max_rpm = 3000", "omega_max_rpm = 1e400", "propulsion.omega_max_rpm",
         "expected a finite number, got 1e400"),
    ],
)
def test_bad_files_name_file_and_field(tmp_path, old, new, field, reason):
    assert old in GOOD
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(AirframeError) as err:
        load_airframe(path)
    message = str(err.value)
    assert str(path) in message
    assert f"'{field}'" in message
    assert reason in message


def test_fixed_tilt_with_servos_is_rejected(tmp_path):
    path = write(tmp_path, GOOD.replace("spin = [1, -1, 1, -1]",
                                        "spin = [1, -1, 1, -1]\nalpha_deg = [5, 5, 5, 5]"))
    with pytest.raises(AirframeError, match="fixed tilt"):
        load_airframe(path)


def test_missing_and_unparsable_files(tmp_path):
    with pytest.raises(AirframeError, match="no such file"):
        load_airframe("no_such_frame")
    with pytest.raises(AirframeError, match="file not found"):
        load_airframe(tmp_path / "absent.toml")
    bad = tmp_path / "broken.toml"
    bad.write_text("name = \n")
    with pytest.raises(AirframeError, match="not valid TOML"):
        load_airframe(bad)
    # the file named, not only Python's words for it
    latin = tmp_path / "latin.toml"
    latin.write_bytes(GOOD.replace('"custom"', '"caf\xe9"').encode("latin-1"))
    with pytest.raises(AirframeError) as err:
        load_airframe(latin)
    assert str(err.value) == (f"{latin}: not UTF-8 text (byte 0xe9 at offset 12, line 2): "
                              "TOML files are UTF-8; save it as UTF-8")
    deep = tmp_path / "deep.toml"
    deep.write_text(GOOD.replace("[body]", "x = " + "[" * 3000 + "]" * 3000 + "\n[body]"))
    with pytest.raises(AirframeError, match=f"^{deep}: nested deeper than 32 levels"):
        load_airframe(deep)


def test_both_fmus_declare_the_one_airframe_table_with_equal_defaults():
    """The airframe table (common/airframe_vars.h), as the C core hands it to Python, is a
    set of parameters of both FMUs' modelDescriptions, with the same declared type, unit and
    range in both, and both FMUs' defaults are the paper hexacopter of its airframe file."""
    import math

    from controller import controller_fmu
    from plant.airframe import airframe_table
    from plant.common.model_description import fmu_variables

    rows = airframe_table()
    assert {r.name for r in rows} >= {"n_rotors", "mass", "inertia", "rotor_pos", "tau_servo"}
    fmus = [fmu_variables(plant.plant_fmu()), fmu_variables(controller_fmu())]
    paper = load_airframe("paper_hexacopter").fmu_parameters()
    assert set(paper) == {r.element(k) for r in rows for k in range(r.rows * r.cols)}
    for name, value in paper.items():
        p, c = (v[name] for v in fmus)
        assert p.causality == c.causality == "parameter", name
        assert (p.type, p.unit, p.min, p.max) == (c.type, c.unit, c.min, c.max), name
        assert math.isclose(float(p.start), float(c.start), rel_tol=1e-15, abs_tol=1e-15), name
        assert math.isclose(float(p.start), float(value), rel_tol=1e-12, abs_tol=1e-15), name
