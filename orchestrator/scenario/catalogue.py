"""The shipped scenarios and loading a scenario file by name or path."""

from __future__ import annotations

from pathlib import Path

from orchestrator.scenario.model import Scenario
from orchestrator.scenario.parser import parse_scenario
from orchestrator.scenario.reader import ScenarioError
from plant.common.toml_reader import read_toml, resolve_file, shipped_names


def scenario_names() -> list[str]:
    """Names of the scenario files shipped with the package."""
    return shipped_names("orchestrator", "scenarios")


def list_scenarios() -> list[Scenario]:
    """The shipped scenarios, loaded."""
    return [load_scenario(name) for name in scenario_names()]


def resolve_scenario(name_or_path: str | Path) -> Path:
    """The scenario file a name or path stands for (a shipped name, or a file)."""
    return resolve_file(name_or_path, "orchestrator", "scenarios", "scenario", ScenarioError)


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load and validate a scenario file, or a shipped scenario by name."""
    path = resolve_scenario(name_or_path)
    return parse_scenario(read_toml(path, ScenarioError), str(path), default_name=path.stem,
                          base_dir=path.parent)


def check_scenario(path: str | Path) -> Scenario:
    """Validate a scenario completely (the same as loading it: nothing is deferred)."""
    return load_scenario(path)
