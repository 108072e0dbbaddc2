"""A plugin that breaks the contract fails at definition, with one message.

The message says what to add; the same class used from YAML gives that message
at its line.
"""

from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass
from pathlib import Path

import pytest

from cbp.errors import PluginDefinitionError, ScenarioError
from cbp.plugin import Constraint, PluginParams, Task
from cbp.scenario import load_scenario


@dataclass(frozen=True, kw_only=True)
class _Params(PluginParams):
    height: float = 0.3


class _Mutable(PluginParams):  # not a frozen dataclass of its own
    pass


#: Each broken piece: (the class, the expected message).
BROKEN = {
    "no parameters": (
        "class HandAbove(Constraint):\n    dim = 1",
        r"plugin HandAbove has no parameter schema: declare its parameters as the "
        r"generic argument: class HandAbove\(Task\[HandAboveParams\]\)",
    ),
    "bad type_name": (
        "class HandAbove(Constraint[Params]):\n    type_name = 'HandAbove'",
        r"plugin HandAbove: type_name 'HandAbove' is not snake_case: .* e\.g\. "
        r"'hand_above', or leave it out for that default",
    ),
    "two schemas": (
        "class HandAbove(Constraint[Params]):\n    Params = Other",
        r"plugin HandAbove names two parameter schemas \(Other, Params\)",
    ),
    "unit not a string": (
        "class HandAbove(Constraint[Params]):\n    unit = 3",
        r"plugin HandAbove: unit must be a string such as 'm', 'rad' or 'm\|rad'",
    ),
    "gain out of range": (
        "class HandAbove(Constraint[Params]):\n    default_gain = 2.0",
        r"plugin HandAbove: default_gain must be a number in \[0, 1\], got 2\.0",
    ),
    "no Jacobian": (
        "class HandAbove(Constraint[Params]):\n"
        "    dim = 1\n"
        "    def compute_value(self, state): ...\n"
        "    def compute_bounds(self, state): ...",
        r"plugin HandAbove does not define compute_jacobian\(self, state\) -> df/dq "
        r"along tangent directions, shape \(dim, nv\)$",
    ),
    "no bounds": (
        "class HandAbove(Constraint[Params]):\n"
        "    dim = 1\n"
        "    def compute_value(self, state): ...\n"
        "    def compute_jacobian(self, state): ...",
        r"does not define compute_bounds\(self, state\) -> \(lower, upper\)",
    ),
    "bad constructor": (
        "class HandAbove(Constraint[Params]):\n"
        "    dim = 1\n"
        "    def __init__(self, params, robot): ...\n"
        "    def compute_value(self, state): ...\n"
        "    def compute_jacobian(self, state): ...\n"
        "    def compute_bounds(self, state): ...",
        r"plugin HandAbove: the constructor must accept \(params, robot, name=''\)",
    ),
}

_PRELUDE = """\
from dataclasses import dataclass
from cbp.plugin import Constraint, PluginParams

@dataclass(frozen=True, kw_only=True)
class Params(PluginParams):
    height: float = 0.3

@dataclass(frozen=True, kw_only=True)
class Other(PluginParams):
    pass

"""


@pytest.mark.parametrize("case", list(BROKEN))
def test_broken_plugin_fails_at_definition(case: str) -> None:
    """Defining the class raises PluginDefinitionError with the message."""
    body, message = BROKEN[case]
    with pytest.raises(PluginDefinitionError, match=message):
        exec(_PRELUDE + textwrap.dedent(body), {})


@pytest.mark.parametrize("case", list(BROKEN))
def test_broken_plugin_from_yaml_gives_the_same_message_at_its_line(
    case: str, tmp_path: Path
) -> None:
    """A scenario naming the class reports the same message at its 'type' line."""
    body, message = BROKEN[case]
    (tmp_path / "broken.py").write_text(_PRELUDE + textwrap.dedent(body))
    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        "name: s\n"
        "robot: {name: franka_panda}\n"
        "duration: 1.0\n"
        "constraints:\n"
        "  - type: 'broken:HandAbove'\n"
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(scenario)
    text = str(info.value)
    assert "line 5: constraints[0].type: " in text
    assert len(text.splitlines()) == 2  # the file, then one problem
    assert re.search(message.removesuffix("$"), text), text


def test_defaults_fill_in_what_is_optional() -> None:
    """type_name, unit and Params come from the class name and generic argument."""

    class HandAboveConstraint(Constraint[_Params]):
        dim = 1

        def compute_value(self, state):  # type: ignore[no-untyped-def]
            raise NotImplementedError

        def compute_jacobian(self, state):  # type: ignore[no-untyped-def]
            raise NotImplementedError

        def compute_bounds(self, state):  # type: ignore[no-untyped-def]
            raise NotImplementedError

    assert HandAboveConstraint.type_name == "hand_above"
    assert HandAboveConstraint.Params is _Params
    assert HandAboveConstraint.unit == ""


def test_a_mutable_schema_is_refused() -> None:
    """A Params that is not a frozen dataclass is refused, naming it."""
    with pytest.raises(PluginDefinitionError, match="_Mutable is not a frozen"):

        class Bad(Task[_Mutable]):  # type: ignore[type-var]
            dim = 1
