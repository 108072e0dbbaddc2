"""The docs site's generated reference covers every field, command and plugin."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest

from cbp.robot import RobotDescription
from cbp.scenario import ScenarioSpec
from cbp.teleop.profiles import InputProfile

GEN = Path(__file__).resolve().parents[1] / "docs" / "gen" / "reference.py"


@pytest.fixture(scope="module")
def reference() -> ModuleType:
    """docs/gen/reference.py, imported from its file (docs/ is not a package)."""
    spec = importlib.util.spec_from_file_location("docs_reference", GEN)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _rows(page: str) -> dict[str, dict[str, str]]:
    """Table rows of each ``##`` section: {section heading: {key: description}}."""
    sections: dict[str, dict[str, str]] = {}
    current = ""
    for line in page.splitlines():
        if line.startswith("## "):
            current = line.removeprefix("## ").split(" {#")[0].strip("`")
            sections[current] = {}
        match = re.match(r"\| `([^`]+)` \|.*\| ([^|]*) \|$", line)
        if match and current:
            sections[current][match.group(1)] = match.group(2).strip()
    return sections


@pytest.mark.parametrize(
    ("root", "page"),
    [
        (ScenarioSpec, "scenario_page"),
        (RobotDescription, "robot_page"),
        (InputProfile, "input_profile_page"),
    ],
)
def test_every_schema_field_is_described(
    reference: ModuleType, root: type, page: str
) -> None:
    """Every field of the scenario and robot.yaml schemas has a described row."""
    rows = _rows(getattr(reference, page)())
    fields = reference.schema_fields(root)
    assert len(fields) > 10
    for path, name in fields:
        section = rows[path or "Top level"]
        assert section.get(name), f"{path}.{name} has no description"


def test_every_command_has_its_help(reference: ModuleType) -> None:
    """Every cbp command and subcommand has a section with its --help text."""
    page = reference.cli_page()
    commands = reference.cli_commands()
    assert {"run", "check", "robot init", "sweep"} <= set(commands)
    for command in commands:
        assert f"`cbp {command}`" in page
        assert f"usage: cbp {command}" in page


def test_every_plugin_parameter_is_listed(reference: ModuleType) -> None:
    """Every in-tree plugin has a section, and each of its parameters a described row."""
    page = reference.plugins_page()
    classes = reference.plugin_classes()
    assert len(classes) > 10
    for cls in classes:
        section = page.split(f"### `{cls.type_name}`\n", 1)[1].split("\n### ", 1)[0]
        for name in cls.Params.__dataclass_fields__:
            row = re.search(rf"^\| `{name}` \|.*\| ([^|]*) \|$", section, re.M)
            assert row, f"{cls.type_name}.{name} has no row"
            assert row.group(1).strip(), f"{cls.type_name}.{name} has no description"
