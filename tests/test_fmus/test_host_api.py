"""The host C API and its ctypes declarations agree.

The prototypes in ``fmu_src/host/*.h`` (the build compiles with -Wmissing-prototypes, so
every exported function is declared there) are parsed and compared with the signature
tables of the Python loaders: the same functions, the same number of arguments, compatible
argument types, and int results.  The libraries themselves export exactly those functions.
"""

from __future__ import annotations

import ctypes
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from controller import native as controller_native
from orchestrator.sim import native as orchestrator_native
from plant import native as plant_native
from plant.common.artifacts import library_path

HOST = Path(__file__).resolve().parents[2] / "fmu_src" / "host"

# header -> (package, library stem, the loader's signatures, the loader)
LIBRARIES = {
    "fp_multirotor_api.h": ("plant", "fp_multirotor", plant_native.SIGNATURES,
                            plant_native.multirotor),
    "fp_controller_api.h": ("controller", "fp_controller", controller_native.SIGNATURES,
                            controller_native.solver),
    "fp_cosim.h": ("orchestrator", "fp_cosim", orchestrator_native.SIGNATURES,
                   orchestrator_native.cosim),
}

_COMMENT = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)
_PROTOTYPE = re.compile(r"\bFP_API\s+([A-Za-z_][\w\s*]*?)\s*\b([A-Za-z_]\w*)\s*\(([^)]*)\)\s*;")
_QUALIFIERS = {"const", "volatile", "restrict"}
FUNCTION_POINTER_TYPEDEFS = {"FpFn"}

# C type (base type, pointer depth) -> the ctypes type that declares it exactly
EXACT = {
    ("int", 0): ctypes.c_int,
    ("long", 0): ctypes.c_long,
    ("size_t", 0): ctypes.c_size_t,
    ("double", 0): ctypes.c_double,
    ("void", 1): ctypes.c_void_p,
    ("double", 1): ctypes.POINTER(ctypes.c_double),
    ("int32_t", 1): ctypes.POINTER(ctypes.c_int32),
    ("int8_t", 1): ctypes.POINTER(ctypes.c_int8),
    ("long", 1): ctypes.POINTER(ctypes.c_long),
    ("char", 1): ctypes.c_char_p,
    ("unsigned char", 1): ctypes.c_char_p,
}


def c_type(declaration: str) -> tuple[str, int]:
    """(base type, pointer depth) of one parameter declaration, e.g.
    ``const unsigned int *const vrs[9]`` -> ("unsigned int", 2)."""
    text = declaration.strip()
    depth = text.count("[")
    text = re.sub(r"\[[^\]]*\]", "", text)
    depth += text.count("*")
    words = [w for w in re.findall(r"[A-Za-z_]\w*", text) if w not in _QUALIFIERS]
    if len(words) < 2:
        raise ValueError(f"unnamed or unparsable parameter: {declaration!r}")
    base = " ".join(words[:-1])  # the last word is the parameter's name
    if base in FUNCTION_POINTER_TYPEDEFS:
        depth += 1
    return base, depth


def prototypes(text: str) -> dict[str, tuple[str, list[tuple[str, int]]]]:
    """name -> (return type, parameter types) of every FP_API declaration in a header."""
    found = {}
    for ret, name, params in _PROTOTYPE.findall(_COMMENT.sub("", text)):
        params = params.strip()
        args = [] if params in ("", "void") else [c_type(p) for p in params.split(",")]
        assert name not in found, f"{name} declared twice"
        found[name] = (" ".join(ret.split()), args)
    return found


def compatible(c: tuple[str, int], py: object) -> bool:
    """A ctypes argument type can pass the C parameter: the exact type, or any pointer
    as c_void_p."""
    return EXACT.get(c) is py or (c[1] >= 1 and py is ctypes.c_void_p)


def header(name: str) -> dict[str, tuple[str, list[tuple[str, int]]]]:
    return prototypes((HOST / name).read_text())


def test_the_parser_reads_prototypes():
    """The parser on planted declarations: not vacuous, and strict about what it reads."""
    text = """
    /* FP_API int commented_out(void); */
    FP_API int f(void);
    FP_API int g(const double *x, int32_t *info, char *why,
                 int n);  // a comment
    FP_API int h(const FpFn fns[9], void *const comps[2], const unsigned int *const vrs[3],
                 long *failed, double t0);
    """
    found = prototypes(text)
    assert set(found) == {"f", "g", "h"}
    assert found["f"] == ("int", [])
    assert found["g"] == ("int", [("double", 1), ("int32_t", 1), ("char", 1), ("int", 0)])
    assert found["h"][1] == [("FpFn", 2), ("void", 2), ("unsigned int", 2), ("long", 1),
                             ("double", 0)]
    assert compatible(("double", 1), ctypes.POINTER(ctypes.c_double))
    assert compatible(("double", 1), ctypes.c_void_p)
    assert not compatible(("double", 0), ctypes.c_void_p)
    assert not compatible(("double", 1), ctypes.POINTER(ctypes.c_int32))


def test_every_host_header_has_a_loader():
    assert {p.name for p in HOST.glob("*.h")} - {"fp_api.h"} == set(LIBRARIES)


@pytest.mark.parametrize("name", sorted(LIBRARIES))
def test_ctypes_declarations_match_the_header(name):
    declared = header(name)
    signatures = LIBRARIES[name][2]
    assert declared, name
    assert set(signatures) == set(declared), name
    for fn, (ret, args) in declared.items():
        assert ret == "int", f"{fn} returns {ret}: host functions return int"
        py = list(signatures[fn])
        assert len(py) == len(args), f"{fn}: {len(py)} ctypes arguments, {len(args)} in C"
        bad = [(i + 1, c, t) for i, (c, t) in enumerate(zip(args, py, strict=True))
               if not compatible(c, t)]
        assert not bad, f"{fn}: arguments (position, C type, ctypes type) disagree: {bad}"


@pytest.mark.parametrize("name", sorted(LIBRARIES))
def test_loaded_library_is_declared_as_the_header_says(name):
    _, _, signatures, load = LIBRARIES[name]
    lib = load()
    for fn in header(name):
        f = getattr(lib, fn)
        assert f.restype is ctypes.c_int, fn
        assert list(f.argtypes) == list(signatures[fn]), fn


@pytest.mark.skipif(sys.platform != "linux", reason="reads ELF exports with nm")
@pytest.mark.parametrize("name", sorted(LIBRARIES))
def test_library_exports_exactly_its_header(name):
    package, stem, _, _ = LIBRARIES[name]
    nm = shutil.which("nm")
    if nm is None:
        pytest.fail("nm (binutils) is needed to inspect the binaries")
    out = subprocess.run([nm, "-D", "--defined-only", str(library_path(package, stem))],
                         capture_output=True, text=True, check=True).stdout
    exported = {line.split()[-1] for line in out.splitlines() if line.strip()}
    assert exported == set(header(name))
