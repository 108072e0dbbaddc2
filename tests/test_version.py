"""The package's version is the CHANGELOG's latest release, everywhere it is stated."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import cbp

ROOT = Path(__file__).resolve().parents[1]


def _releases() -> list[str]:
    """Section titles of the CHANGELOG (``Unreleased``, ``0.2.0``...), in order."""
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    return re.findall(r"^## \[([^\]]+)\]", text, re.M)


def test_versions_agree_with_the_latest_release() -> None:
    """The version in pyproject.toml and cbp.__version__ are the latest release's."""
    releases = _releases()
    assert releases[0] == "Unreleased"
    latest = releases[1]
    with (ROOT / "pyproject.toml").open("rb") as f:
        assert tomllib.load(f)["project"]["version"] == latest
    assert cbp.__version__ == latest


def test_released_sections_are_dated_and_ordered() -> None:
    """Each released section is 'X.Y.Z - YYYY-MM-DD', newest first, each once."""
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    released = re.findall(
        r"^## \[(\d+)\.(\d+)\.(\d+)\] - \d{4}-\d{2}-\d{2}$", text, re.M
    )
    assert len(released) == len(_releases()) - 1
    versions = [tuple(int(p) for p in v) for v in released]
    assert versions == sorted(set(versions), reverse=True)
