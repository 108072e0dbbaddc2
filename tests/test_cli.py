"""The ``cbp`` command's small promises: version, check --set, extras, examples."""

from __future__ import annotations

import json
import re
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

from cbp.cli import main

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def test_version_is_the_installed_distributions(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`cbp --version` prints the version pip installed."""
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"cbp {version('cbp')}"


def test_check_takes_set(capsys: pytest.CaptureFixture[str]) -> None:
    """`cbp check --set` checks the overridden value, as run would use it."""
    path = str(SCENARIOS / "panda_reach.yaml")
    assert main(["check", path, "--set", "duration=4"]) == 0
    assert main(["check", path, "--set", "duration=-1"]) == 2
    err = capsys.readouterr().err
    assert "--set duration: duration: must be in (0, 86400] s, got -1.0" in err


@pytest.mark.parametrize(
    ("command", "module"),
    [("view", "viser"), ("teleop", "viser"), ("view", "yourdfpy")],
)
def test_a_missing_viewer_extra_is_one_line_naming_it(
    command: str,
    module: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
) -> None:
    """Without viser or yourdfpy, view and teleop say which extra to install (exit 2)."""
    monkeypatch.setitem(sys.modules, module, None)  # import raises ModuleNotFoundError
    target = str(tmp_path) if command == "view" else str(SCENARIOS / "cat_boards.yaml")
    assert main([command, target]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"cbp {command} needs the viewer extra ({module} is not installed): "
        "pip install 'cbp[viewer]'\n"
    )


def _suggested(out: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    assert main(["examples", str(out)]) == 0
    match = re.search(r"run one with: cbp run (\S+)", capsys.readouterr().out)
    assert match is not None
    return Path(match.group(1))


def test_examples_suggest_a_scenario_that_is_there(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`cbp examples` suggests cat_boards.yaml, which it copied."""
    suggested = _suggested(tmp_path / "ex", capsys)
    assert suggested == tmp_path / "ex" / "cat_boards.yaml"
    assert suggested.is_file()


@pytest.mark.slow
def test_the_suggested_example_reaches(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The example `cbp examples` suggests reaches its goal without contact."""
    suggested = _suggested(tmp_path / "ex", capsys)
    out = tmp_path / "out"
    assert main(["-q", "run", str(suggested), "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())["cat"]
    assert metrics["reached"]
    assert metrics["peak_contact_force_n"] == 0.0
