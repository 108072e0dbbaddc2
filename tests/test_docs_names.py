"""Every code name the docs give exists: dotted ``cbp.`` names and repository paths."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted(
    [*ROOT.glob("docs/**/*.md"), ROOT / "CONTRIBUTING.md", ROOT / "README.md"]
)
#: A dotted name in backticks: `cbp.run.build_run`, `cbp.run.build_run()`.
DOTTED = re.compile(r"`(cbp(?:\.[A-Za-z_]\w*)+)(?:\([^`]*\))?`")
#: A repository path in backticks: `cbp/run/loop.py`, `tests/run/`.
#: Names that are not Python's: the plugin registries' entry point groups, and
#: where the wheel puts the shipped robots and scenarios (pyproject.toml).
NOT_PYTHON = {"cbp.tasks", "cbp.constraints"}
INSTALLED_ONLY = {"cbp/_data/"}
PATH = re.compile(
    r"`((?:cbp|tests|benchmarks|scenarios|docs|plugins|robots)/[^`\s<>*{}]*)`"
)


def _resolves(dotted: str) -> bool:
    """Whether ``dotted`` is a module, or an attribute path from one."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for name in parts[k:]:
            if not hasattr(obj, name):
                # A dataclass field or an annotated attribute is a name too.
                fields = getattr(obj, "__dataclass_fields__", {})
                annotations = getattr(obj, "__annotations__", {})
                return name in fields or name in annotations
            obj = getattr(obj, name)
        return True
    return False


def test_every_dotted_cbp_name_in_the_docs_exists() -> None:
    """`cbp.x.y` in a page is a module or something a module defines."""
    from cbp.plugins.constraints import CONSTRAINTS
    from cbp.plugins.tasks import TASKS

    assert {TASKS.group, CONSTRAINTS.group} == NOT_PYTHON
    missing = [
        f"{page.relative_to(ROOT)}:{n}: {name}"
        for page in PAGES
        for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1)
        for name in DOTTED.findall(line)
        if name not in NOT_PYTHON and not _resolves(name)
    ]
    assert not missing, "\n".join(missing)


def test_every_repository_path_in_the_docs_exists() -> None:
    """`cbp/...`, `tests/...` and the like in a page name files that are there."""
    pyproject = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert all(f'= "{p}' in pyproject for p in INSTALLED_ONLY)
    missing = [
        f"{page.relative_to(ROOT)}:{n}: {path}"
        for page in PAGES
        for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1)
        for path in PATH.findall(line)
        if path not in INSTALLED_ONLY
        and not (ROOT / path.rstrip("/").split(":")[0]).exists()
    ]
    assert not missing, "\n".join(missing)
