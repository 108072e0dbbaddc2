# SPDX-License-Identifier: Apache-2.0
"""Sweep files are refused or expanded: located errors, never a traceback or a hang.

Like the scenario loader's fuzz tests (``tests/engine/test_loader_fuzz.py``):
two property-based tests damage sweep files, one in their structure and one in
their bytes, and require :func:`~cbp.sweep.load_sweep` and, for sweeps of at
most :data:`EXPANDED` runs, :func:`~cbp.sweep.spec.expand` to succeed or raise
:class:`~cbp.errors.CbpError` within :data:`HANG` s. The examples are
derandomized; ``make fuzz`` runs 10,000 of each with fresh randomness. A
failing file is written to ``out/fuzz/``; add it to
``tests/sweep/fuzz_cases/`` with the fix and a ``.expected`` message, where
:func:`test_regression_cases` keeps it refused.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from cbp.errors import ScenarioError
from cbp.sweep import load_sweep
from cbp.sweep.spec import expand, sweep_size
from tests.engine.test_loader_fuzz import (
    EXTRA_KEYS,
    FUZZ,
    TOKENS,
    damage_bytes,
    damage_structure,
    refused_or_loaded,
)

ROOT = Path(__file__).resolve().parents[2]
CASES = Path(__file__).parent / "fuzz_cases"
#: A load and expansion taking more CPU time than this is a hang [s].
HANG = 10
#: Sweeps of at most this many runs are expanded too (each run's overrides are
#: applied to its scenario).
EXPANDED = 40
SOURCES = [CASES / "base.yaml", *sorted((ROOT / "scenarios" / "sweeps").glob("*.yaml"))]
SWEEP_KEYS = ["grid", "samples", "set", "scenes", "values", "count", "choice", "name"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of ``scenarios/`` with a folder for sweeps beside its scenarios."""
    target = tmp_path_factory.mktemp("sweep_fuzz") / "scenarios"
    shutil.copytree(ROOT / "scenarios", target)
    shutil.copytree(CASES, target / "fuzz_sweeps")
    return target / "fuzz_sweeps"


def _load_and_expand(path: Path) -> None:
    spec = load_sweep(path)
    if sweep_size(spec) <= EXPANDED:
        expand(spec, path, [])


def refuse_or_expand(path: Path) -> None:
    """Load (and expand, if small) ``path``; anything but a CbpError within HANG fails."""
    refused_or_loaded(path, _load_and_expand, HANG, "sweep")


@FUZZ
@given(data=st.data())
def test_damaged_sweep_structure_is_refused_or_loaded(
    folder: Path, data: st.DataObject
) -> None:
    """Values replaced by other types and sizes, keys removed or added: no traceback."""
    source = data.draw(st.sampled_from(SOURCES), label="sweep")
    keys = SWEEP_KEYS + EXTRA_KEYS
    doc = damage_structure(data, yaml.safe_load(source.read_text()), keys)
    case = folder / "fuzz_case.yaml"
    case.write_text(yaml.safe_dump(doc, allow_unicode=True))
    refuse_or_expand(case)


@FUZZ
@given(data=st.data())
def test_damaged_sweep_bytes_are_refused_or_loaded(
    folder: Path, data: st.DataObject
) -> None:
    """Special YAML tokens, random bytes and cut lines: no traceback, no hang."""
    source = data.draw(st.sampled_from(SOURCES), label="sweep")
    tokens = [*TOKENS, b"1e400", b"-.inf", b"1000000000000", b"../../", b"[]"]
    case = folder / "fuzz_case.yaml"
    case.write_bytes(damage_bytes(data, source.read_bytes(), tokens))
    refuse_or_expand(case)


def test_the_base_sweep_loads_and_expands(folder: Path) -> None:
    """The base document of the fuzz tests is a valid sweep (8 distinct runs)."""
    path = folder / "base.yaml"
    assert len(expand(load_sweep(path), path, [])) == 8  # draws set solver.name


@pytest.mark.parametrize(
    "case",
    sorted(p for p in CASES.glob("*.yaml") if p.name != "base.yaml"),
    ids=lambda p: p.stem,
)
def test_regression_cases(case: Path, folder: Path) -> None:
    """Each saved sweep file is refused with a located message naming the problem."""
    expected = case.with_suffix(".expected").read_text().strip()
    path = folder / case.name
    with pytest.raises(ScenarioError) as info:
        expand(load_sweep(path), path, [])
    assert expected in str(info.value)
