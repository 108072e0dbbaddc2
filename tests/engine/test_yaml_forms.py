# SPDX-License-Identifier: Apache-2.0
"""Every YAML tag and number form gives a value or a located problem."""

from __future__ import annotations

from pathlib import Path

import pytest

from cbp.errors import ScenarioError
from cbp.scenario import load_scenario
from cbp.schema import Document

ROOT = Path(__file__).resolve().parents[2]
REACH = ROOT / "scenarios" / "panda_reach.yaml"
BOARDS = ROOT / "scenarios" / "cat_boards.yaml"


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("1.5e1", 15.0),
        ("1.0e12", 1e12),
        ("1e-3", 1e-3),
        (".5e3", 500.0),
        ("-2.5E-2", -0.025),
        ("1.0e+3", 1000.0),
        ("0x1f", 31),
        ("1_000", 1000),
    ],
)
def test_yaml_1_2_number_forms_read_as_numbers(text: str, value: float) -> None:
    """Exponents with or without a dot or a sign read as numbers, as in YAML 1.2."""
    doc = Document(f"a: {text}\n")
    assert doc.plain(doc.root) == {"a": value}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("a: 1\nb: !!timestamp hello\n", "line 2: cannot read 'hello' as timestamp"),
        ("a: 2020-01-01\n", "line 1: '2020-01-01' reads as a date"),
        ("a:\n  b: !!bool maybe\n", "line 2: cannot read 'maybe' as bool"),
        ("a: !!int 1.5\n", "line 1: cannot read '1.5' as int"),
        ("a: 1\nb: !!str {c: 1}\n", "line 2: the tag '!!str' cannot be given to a"),
        ("a: !!int [1]\n", "line 1: the tag '!!int' cannot be given to a list"),
        ("a: !!map x\n", "line 1: cannot read 'x' as map"),
        ("a: 1\nb: x\x07\n", "line 2, column 5: malformed YAML: unacceptable"),
        ("a: 1\nb: " + "[" * 3000 + "\n", "line 2: malformed YAML: nested too deeply"),
        ("a:\n  " + "[" * 70 + "]" * 70 + "\n", "line 2: nested more than 64 levels"),
    ],
)
def test_every_tag_problem_is_located(text: str, message: str) -> None:
    """A tag its value does not fit, a date, a control character: a line each."""
    with pytest.raises(ScenarioError) as info:
        Document(text, "f.yaml")
    assert message in str(info.value)


def test_an_alias_bomb_is_refused_at_the_line_that_expands_too_far() -> None:
    """The first value that expands past the limit is named by its line."""
    lines = ["a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    for name, prev in zip("bcdef", "abcde", strict=True):
        lines.append(f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 10) + "]")
    lines.append("g: [*f, *f]")
    with pytest.raises(ScenarioError, match=r"line 6: this value holds 111111"):
        Document("\n".join(lines) + "\n", "f.yaml")


@pytest.mark.parametrize(
    ("path", "key", "value", "message"),
    [
        (BOARDS, "collision.contacts_per_link", "1000000000", "must be in [1, 64]"),
        (BOARDS, "method.cat.max_steps", "1000000000000000", "magnitude at most"),
        (BOARDS, "method.cat.max_steps", "1000000000", "must be in [1, 100000]"),
        (BOARDS, "method.hybrid.seed", "-1", "must be >= 0"),
        (BOARDS, "method.hybrid.tries", "100000", "must be in [1, 1000]"),
        (REACH, "simulation.record_every", "100000", "must be in [1, 10000]"),
    ],
)
def test_integer_fields_are_bounded(
    path: Path, key: str, value: str, message: str
) -> None:
    """Counts that size memory or loops have an upper bound, named in the error."""
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, overrides={key: value})
    assert key.rsplit(".", 1)[-1] in str(info.value)
    assert message in str(info.value)
