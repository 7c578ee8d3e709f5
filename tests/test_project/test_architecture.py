"""The walls of docs/architecture.md, enforced from the sources' own imports and includes.

* plant/ imports only plant; controller/ only plant and controller; orchestrator/ never
  mavlink_bridge/ (the ``fly`` command joins the CLI through an entry point);
* no production module imports a private name (``_x``) of another module;
* C model code never includes an FMI header (only the glue and the host kernel do); the plant
  and controller models never include each other's headers.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from helpers.graphs import strongly_connected

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("plant", "controller", "orchestrator", "mavlink_bridge")
MAY_IMPORT = {
    "plant": {"plant"},
    "controller": {"plant", "controller"},
    "orchestrator": {"plant", "controller", "orchestrator"},
    "mavlink_bridge": {"plant", "controller", "orchestrator", "mavlink_bridge"},
}


def _modules(package: str) -> list[Path]:
    return sorted(p for p in (ROOT / package).rglob("*.py") if "fmus" not in p.parts)


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> list[tuple[int, str, list[str]]]:
    """(line, imported module, imported names) of every import, at any depth (lazy ones
    inside functions count too)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module, [a.name for a in node.names]))
    return out


def test_every_package_has_modules():
    for package in PACKAGES:
        assert _modules(package), package


@pytest.mark.parametrize("package", PACKAGES)
def test_packages_import_only_the_layers_below(package):
    bad = []
    for path in _modules(package):
        for line, module, _ in _imports(path):
            top = module.split(".")[0]
            if top in PACKAGES and top not in MAY_IMPORT[package]:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("package", PACKAGES)
def test_no_module_imports_another_modules_private_names(package):
    bad = []
    for path in _modules(package):
        me = _module_name(path)
        for line, module, names in _imports(path):
            if module.split(".")[0] not in PACKAGES or module == me:
                continue
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            private += [p for p in module.split(".")[1:] if p.startswith("_")
                        and not p.startswith("__")]
            if private:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {module}: {private}")
    assert not bad, "\n".join(bad)


def _module_graph() -> dict[str, set[str]]:
    """Module -> the modules of the four packages it imports (at any depth).  ``from pkg
    import sub`` is an import of the submodule ``pkg.sub`` (as import-linter and pydeps
    count it), ``from mod import name`` of ``mod``."""
    paths = {_module_name(p): p for package in PACKAGES for p in _modules(package)}
    graph: dict[str, set[str]] = {m: set() for m in paths}
    for me, path in paths.items():
        for _, module, names in _imports(path):
            targets = [f"{module}.{n}" for n in names if f"{module}.{n}" in paths]
            if len(targets) < len(names) or not names:
                targets.append(module)
            graph[me] |= {t for t in targets if t in paths and t != me}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The groups of modules that import each other around a circle, each sorted."""
    return [sorted(group) for group in strongly_connected(graph)]


def test_no_import_circles():
    """No two modules import each other, directly or around a circle (lazy imports count)."""
    assert _cycles(_module_graph()) == []


def test_the_circle_check_sees_a_circle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
SRC = ROOT / "fmu_src"
MODEL_DIRS = ("plant", "controller", "common")
GLUE = {SRC / "common" / name for name in ("fmi2_glue.c", "fmi2_values.c", "fmi2_fmustate.c",
                                          "fmi2_resources.c", "fmi2_me.c",
                                          "fmi2_glue_internal.h",
                                          "fmi3_glue.c", "fmi3_values.c", "fmi3_fmustate.c",
                                          "fmi3_resources.c", "fmi3_glue_internal.h",
                                          "fmi3_me.c")}


def _c_files(folder: str) -> list[Path]:
    return sorted(p for p in (SRC / folder).glob("*") if p.suffix in (".c", ".h"))


def _owner(header: str) -> str | None:
    """The folder of fmu_src/ holding a header (None: not ours, e.g. the FMI headers)."""
    for folder in (*MODEL_DIRS, "host", "tools"):
        if (SRC / folder / header).is_file():
            return folder
    return None


def test_model_code_never_includes_fmi_headers():
    bad = [f"{p.relative_to(ROOT)} includes {h}" for d in MODEL_DIRS for p in _c_files(d)
           if p not in GLUE for h in _INCLUDE.findall(p.read_text()) if h.startswith("fmi")]
    assert not bad, "\n".join(bad)


def test_plant_and_controller_models_never_include_each_other():
    bad = []
    for me, other in (("plant", "controller"), ("controller", "plant")):
        for p in _c_files(me):
            bad += [f"{p.relative_to(ROOT)} includes {h} ({other}/)"
                    for h in _INCLUDE.findall(p.read_text()) if _owner(h) == other]
    assert not bad, "\n".join(bad)


def test_common_code_belongs_to_neither_model():
    bad = [f"{p.relative_to(ROOT)} includes {h}" for p in _c_files("common")
           for h in _INCLUDE.findall(p.read_text()) if _owner(h) in ("plant", "controller")]
    assert not bad, "\n".join(bad)


def test_the_walls_test_sees_a_breach(tmp_path):
    """The checks above on a planted breach: they are not vacuous."""
    breach = tmp_path / "x.py"
    breach.write_text("def f():\n    from mavlink_bridge.bridge import Bridge\n"
                      "from plant._native import core\n")
    found = _imports(breach)
    assert (2, "mavlink_bridge.bridge", ["Bridge"]) in found
    assert (3, "plant._native", ["core"]) in found
    assert _INCLUDE.findall('#include "fmi2Functions.h"\n  # include "wls.h"') == [
        "fmi2Functions.h", "wls.h"]


def test_constants_shared_by_c_and_python_agree():
    """Layouts written in both languages: the rotor slots and the sat_flags bits
    (common/multirotor.h) against controller.fmu_parameters, and the polytope caps
    (controller/controller.h)."""
    from controller import fmu_parameters as fp

    rotor_h = (SRC / "common" / "multirotor.h").read_text()
    assert int(re.search(r"#define FP_MAX_ROTORS (\d+)", rotor_h).group(1)) == fp.MAX_ROTORS
    bits = dict(re.findall(r"FP_SAT_(\w+) = (\d+)", rotor_h))
    assert {k.lower(): int(v) for k, v in bits.items()} == fp.SAT_FLAG_SHIFT
    text = (SRC / "controller" / "controller.h").read_text()
    for macro, value in (("FP_POLYTOPE_MAX_FACETS", fp.POLY_FACETS),
                         ("FP_FAIL_POLYTOPE_FACETS", fp.FAIL_FACETS)):
        assert int(re.search(rf"#define {macro} (\d+)", text).group(1)) == value



def test_the_package_table_of_architecture_md_lists_every_module():
    """docs/architecture.md's package table names every module of the four Python packages
    (by its path below the package) and nothing that does not exist: the layout a newcomer
    reads there is the layout on disk."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    for package in PACKAGES:
        listed = set()
        for row in re.findall(rf"^\| `{package}/[^|]*` \|(.*)\|$", text, re.M):
            listed |= set(re.findall(r"`([\w/]+\.py)`", row))
        on_disk = {p.relative_to(ROOT / package).as_posix() for p in _modules(package)
                   if p.name != "__init__.py"}
        assert listed - on_disk == set(), f"{package}: listed but missing"
        assert on_disk - listed == set(), f"{package}: not in docs/architecture.md"


ORCHESTRATOR_FLOORS = {
    "output": {"output"},
    "mission": {"mission"},
    "sim": {"output", "sim"},
    "scenario": {"output", "sim", "mission", "scenario"},
    "export": {"output", "sim", "export"},
    "pil": {"sim", "pil"},
}
"""What each orchestrator subpackage may import of its siblings (docs/architecture.md)."""


@pytest.mark.parametrize("sub", sorted(ORCHESTRATOR_FLOORS))
def test_orchestrator_subpackages_import_only_the_floors_below(sub):
    bad = []
    for path in sorted((ROOT / "orchestrator" / sub).rglob("*.py")):
        for line, module, names in _imports(path):
            parts = module.split(".")
            if parts[0] != "orchestrator":
                continue
            targets = [parts[1]] if len(parts) > 1 else names
            for target in targets:
                if target not in ORCHESTRATOR_FLOORS[sub]:
                    bad.append(f"{path.relative_to(ROOT)}:{line} imports orchestrator.{target}")
    assert not bad, "\n".join(bad)
