"""Airframe files: shipped ones load, bad ones fail naming file and field."""

import math
import re
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
        # finite numbers no vehicle has (docs/airframes.md, "Plausible numbers"): a thrust of
        # 1e-296 N crashed Qhull (exit 139), 1e6..1e20 rpm failed in an LP naming nothing,
        # 1e150 rpm printed pages of Qhull's report
        ("k_t = 1.0e-4", "k_t = 1e-300", "propulsion.k_t",
         "1e-300 N/(rad/s)^2 gives a rotor a maximum thrust k_t omega_max^2 = 9.8696e-296 N "
         "at 3000 rpm, below 0.001 N, less than any rotor's"),
        ("k_t = 1.0e-4", "k_t = 2.0", "propulsion.k_t",
         "k_t omega_max^2 = 1.9739e+05 N at 3000 rpm, beyond 100000 N, more than any rotor's"),
        ("omega_max_rpm = 3000", "omega_max_rpm = 1e20", "propulsion.omega_max_rpm",
         "1e+20 rpm is beyond 500000 rpm, faster than any rotor turns"),
        ("omega_max_rpm = 3000", "omega_max_rpm = 1e6", "propulsion.omega_max_rpm",
         "1e+06 rpm is beyond 500000 rpm"),
        ("omega_max_rpm = 3000", "omega_max_rpm = 1e150", "propulsion.omega_max_rpm",
         "1e+150 rpm is beyond 500000 rpm"),
        ("omega_max_rpm = 3000", "omega_max_rpm = 0.5", "propulsion.omega_max_rpm",
         "0.5 rpm is below 1 rpm, slower than any rotor turns"),
        ("k_d = 1.0e-6", "k_d = 1e10", "propulsion.k_d",
         "drag torque per newton of thrust k_d / k_t = 1e+14 m, beyond 10 m"),
        ("mass = 1.0", "mass = 1e-300", "body.mass",
         "the thrust-to-weight ratio n k_t omega_max^2 / (m g) = 4 x 9.8696 N / 9.81e-300 N = "
         "4.0243e+300 is beyond 100"),
        ("mass = 1.0", "mass = 1000.0", "body.mass",  # grams written as kilograms
         "= 4 x 9.8696 N / 9810 N = 0.0040243 is below 0.1, not a vehicle's; is the mass in kg?"),
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


# ---------------------------------------------------------------------------
# Physical plausibility: the file's checks and both FMUs' fp_check_airframe (one rule set)

ROOT = Path(__file__).resolve().parents[2]


def test_the_plausibility_bounds_are_the_c_cores():
    """plant/airframe.py's bounds are the FP_* macros fp_check_airframe applies in both FMUs
    (fmu_src/common/multirotor.h), number for number."""
    from plant import airframe

    header = (ROOT / "fmu_src" / "common" / "multirotor.h").read_text()

    def macro(name: str) -> float:
        found = re.search(rf"#define {name} (\S+)", header)
        assert found, name
        return float(found.group(1))

    assert airframe.OMEGA_MAX_RPM_LIMITS == (macro("FP_OMEGA_MAX_RPM_MIN"),
                                             macro("FP_OMEGA_MAX_RPM_MAX"))
    assert airframe.ROTOR_THRUST_LIMITS == (macro("FP_ROTOR_THRUST_MIN"),
                                            macro("FP_ROTOR_THRUST_MAX"))
    assert airframe.DRAG_RATIO_MAX == macro("FP_DRAG_RATIO_MAX")
    assert airframe.THRUST_TO_WEIGHT_LIMITS == (macro("FP_THRUST_TO_WEIGHT_MIN"),
                                                macro("FP_THRUST_TO_WEIGHT_MAX"))


# The paper hexacopter (6 rotors, 0.6656 kg, g = 9.81) with its propulsion and mass changed to
# lie close inside and outside each bound (on it for the top speed): the change, and the field
# a file is refused on with how the FMUs' message begins (None: accepted).
THRUST = ("propulsion.k_t", "parameters k_t, omega_max: ")
WEIGHT = ("body.mass", "parameters mass, g, k_t, omega_max: ")
PAPER = {"k_t": 1.14e-4, "k_d": 1.14e-6, "omega_max_rpm": 2000.0, "mass": 0.6656}
BOUNDS = [
    ({"omega_max_rpm": 500000.0, "k_t": 1e-8, "k_d": 1e-10}, None),  # on the bound: accepted
    ({"omega_max_rpm": 500000.5, "k_t": 1e-8, "k_d": 1e-10},
     ("propulsion.omega_max_rpm", "parameter omega_max: ")),
    ({"omega_max_rpm": 1.0, "k_t": 400.0, "k_d": 4.0}, None),
    ({"omega_max_rpm": 0.999, "k_t": 400.0, "k_d": 4.0},
     ("propulsion.omega_max_rpm", "parameter omega_max: ")),
    ({"k_t": 1e-300}, THRUST),
    ({"k_t": 2.3e-8, "k_d": 2.3e-10, "mass": 1.3e-4}, None),  # 1.009 mN
    ({"k_t": 2.2e-8, "k_d": 2.2e-10, "mass": 1.3e-4}, THRUST),  # 0.965 mN
    ({"k_t": 2.27, "k_d": 2.27e-2, "mass": 13000.0}, None),  # 99.6 kN
    ({"k_t": 2.3, "k_d": 2.3e-2, "mass": 13000.0}, THRUST),  # 100.9 kN
    ({"k_d": 1.1e-3}, None),  # 9.6 m of drag torque per newton
    ({"k_d": 1.2e-3}, ("propulsion.k_d", "parameters k_d, k_t: ")),  # 10.5 m
    ({"mass": 0.031}, None),  # thrust-to-weight 98.7
    ({"mass": 0.030}, WEIGHT),  # 102
    ({"mass": 30.0}, None),  # 0.102: accepted by the rule (then no hover trim in the plant)
    ({"mass": 31.0}, WEIGHT),  # 0.0987
    ({"mass": 1e-300}, WEIGHT),
]
RULES = ("than any rotor", "thrust-to-weight ratio")
"""Words of the plausibility messages (and only of those)."""


def _bounds_case(change: dict[str, float]) -> tuple[str, dict[str, float | int | bool]]:
    """The airframe file's text and the FMU parameters of one case of BOUNDS."""
    from plant.airframe import RPM

    values = {**PAPER, **change}
    text = (ROOT / "plant" / "airframes" / "paper_hexacopter.toml").read_text()
    for key, value in values.items():
        text, found = re.subn(rf"^{key} = [^#\n]*", f"{key} = {value!r}  ", text, count=1,
                              flags=re.M)
        assert found == 1, key
    params = load_airframe("paper_hexacopter").fmu_parameters()
    params.update(k_t=values["k_t"], k_d=values["k_d"], mass=values["mass"],
                  omega_max=values["omega_max_rpm"] * RPM)
    return text, params


def _fmu_log(make_fmu, which: str, params: dict[str, float | int | bool]) -> str:
    """What the FMU logs initializing with these parameters ('' when it initializes)."""
    from fmpy.fmi1 import FMICallException
    from helpers import problems

    inst = make_fmu(which, initialize=False)
    try:
        inst.initialize(parameters=params)
    except FMICallException:
        return problems(inst) or "refused"
    return ""


@pytest.mark.parametrize(("change", "refused"), BOUNDS,
                         ids=[",".join(f"{k}={v:g}" for k, v in c.items()) for c, _ in BOUNDS])
def test_the_file_and_both_fmus_refuse_the_same_implausible_airframes(tmp_path, make_fmu,
                                                                      change, refused):
    text, params = _bounds_case(change)
    path = write(tmp_path, text)
    if refused is None:
        load_airframe(path)
    else:
        with pytest.raises(AirframeError) as err:
            load_airframe(path)
        assert str(err.value).startswith(f"{path}: field '{refused[0]}': ")
        assert any(words in str(err.value) for words in RULES), str(err.value)
    for which in ("plant", "controller"):
        log = _fmu_log(make_fmu, which, params)
        rule = [m for m in log.split(" | ") if any(words in m for words in RULES)]
        if refused is None:
            assert not rule, (which, log)
        else:
            assert rule and rule[0].startswith(refused[1]), (which, log)


def test_an_implausible_thrust_never_reaches_qhull_even_from_code():
    """An Airframe made in code skips the file's checks; the force sets refuse its thrust in
    one line naming it, rather than letting Qhull crash on 1e-296 N (exit 139)."""
    import dataclasses

    from controller.force_sets import ForceSetError, feasible_force_set

    af = dataclasses.replace(load_airframe("paper_hexacopter"), k_t=1e-300)
    with pytest.raises(ForceSetError, match=r"paper_hexacopter.toml: the feasible force set "
                       r"S\(tau\) of airframe 'paper_hexacopter': a rotor's maximum thrust "
                       r"k_t omega_max\^2 = 4.3865e-296 N is outside \[0.001, 100000\] N$"):
        feasible_force_set(af)
