# SPDX-License-Identifier: Apache-2.0
"""Where the robots, configurations and example scenarios that ship with cbp are.

In a source checkout they are the repository's ``robots/`` and ``scenarios/``
folders; an installed wheel carries the same folders as package data under
``cbp/_data/`` (``pyproject.toml``, ``force-include``). :func:`data_dir` finds
either, so ``cbp`` works the same from a checkout, an editable install or a
wheel installed anywhere.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["config_path", "data_dir", "is_file", "shipped_configs"]


def is_file(path: Path) -> bool:
    """Whether ``path`` is a file; False also for names the OS refuses.

    ``Path.is_file`` raises on a name too long for the file system (a fuzzed or
    mistyped scenario value is one).
    """
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """The shipped folder ``name`` (``robots`` or ``scenarios``)."""
    installed = _PACKAGE / "_data" / name
    if installed.is_dir():
        return installed
    return _PACKAGE.parent / name


def shipped_configs() -> list[str]:
    """Names of the configurations a scenario can include by name (``cat``)."""
    return sorted(p.stem for p in (data_dir("scenarios") / "configs").glob("*.yaml"))


def config_path(name: str) -> Path | None:
    """The shipped configuration ``name`` (``include: cat``), or None."""
    if "/" in name or "\\" in name or "\0" in name or name.endswith((".yaml", ".yml")):
        return None
    path = data_dir("scenarios") / "configs" / f"{name}.yaml"
    return path if is_file(path) else None
