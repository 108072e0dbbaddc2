# SPDX-License-Identifier: Apache-2.0
"""The sweep file: what to run, and its expansion into runs with stable ids.

A sweep file (YAML, loaded strictly like a scenario: every problem reported with
its line) names the base scenarios or generated scenes, the methods, and the
values to vary::

    name: cat_step_limits
    scenarios: [../scenarios/cat_boards.yaml]   # relative to this file
    scenes: {count: 20, seed: 0}                # and/or generated clutter scenes
    methods: [cat, ik]
    set: {duration: 6}                          # fixed for every run
    grid:                                       # every combination
      method.cat.step_dt: [0.005, 0.01]
    samples:                                    # and seeded random draws
      count: 4
      seed: 0
      values:
        method.cat.max_rejections: {choice: [2, 3, 5]}
        collision.activation_distance: {uniform: [0.05, 0.15]}
    clock: virtual                              # or wall
    retries: 2

Keys are anything ``cbp run --set`` accepts. Each run is one (scenario, method,
grid point, sample); its id is a hash of the scenario document after includes
and overrides, the method and the seed (the generated scene's, else 0), so the
same run has the same id in any sweep and a rerun finds it done.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from cbp.errors import ScenarioError, require
from cbp.methods import METHODS
from cbp.scenario.spec import ScenarioSpec
from cbp.schema import Document

__all__ = [
    "RunSpec",
    "SampleSpec",
    "ScenesSpec",
    "SweepSpec",
    "expand",
    "load_sweep",
]


@dataclass(frozen=True, kw_only=True)
class ScenesSpec:
    """Generated cluttered scenes (:mod:`cbp.scenes`)."""

    count: int
    """How many scenes."""
    seed: int = 0
    """The first seed tried; a scene that does not load is skipped."""

    def __post_init__(self) -> None:
        """At least one scene."""
        require(self, ">= 1", "count")


@dataclass(frozen=True, kw_only=True)
class SampleSpec:
    """Seeded random draws of settings.

    Each value is ``{uniform: [low, high]}``, ``{log_uniform: [low, high]}``,
    ``{integers: [low, high]}`` (both ends included) or ``{choice: [a, b, ...]}``.
    """

    count: int
    """Draws; each is combined with every grid point."""
    values: dict[str, dict[str, Any]]
    """Distribution of each key."""
    seed: int = 0
    """Seed of the draws: the same seed gives the same values."""


@dataclass(frozen=True, kw_only=True)
class SweepSpec:
    """A sweep file (see the module docstring)."""

    name: str
    """Names the sweep in its report."""
    methods: list[str]
    """Methods to run on every scenario (``cbp run --method`` names)."""
    scenarios: list[str] = field(default_factory=list)
    """Scenario files, relative to the sweep file."""
    scenes: ScenesSpec | None = None
    """Generated cluttered scenes, written under ``DIR/scenes``."""
    set: dict[str, Any] = field(default_factory=dict)
    """Values set in every run."""
    grid: dict[str, list[Any]] = field(default_factory=dict)
    """Values whose every combination runs."""
    samples: SampleSpec | None = None
    """Random draws of values, combined with the grid."""
    clock: Literal["wall", "virtual"] = "virtual"
    """How trajectory executors count their planning budget
    (:mod:`cbp.executors.clock`): ``virtual`` gives the same results on any
    machine and load."""
    retries: int = 2
    """A run whose worker dies is tried this many more times, then recorded as
    failed."""


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep.

    Attributes:
        id: stable id (see the module docstring).
        scenario: the scenario file (absolute).
        method: the executor.
        seed: the generated scene's seed, else 0.
        overrides: ``--set`` values (YAML text) by key.
        values: the swept values of this run, by key (for the results table).
    """

    id: str
    scenario: str
    method: str
    seed: int
    overrides: dict[str, str]
    values: dict[str, Any]


DISTRIBUTIONS = ("uniform", "log_uniform", "integers", "choice")


def load_sweep(path: str | Path) -> SweepSpec:
    """Read and check a sweep file.

    Raises:
        ScenarioError: every problem in the file, located.
    """
    doc = Document.from_file(path)
    spec: SweepSpec = doc.build(SweepSpec, doc.root, "")
    doc.raise_if_problems()
    problems = []
    for i, method in enumerate(spec.methods):
        if method not in METHODS:
            problems.append(
                f"methods[{i}]: unknown method '{method}'; expected one of "
                + ", ".join(METHODS)
            )
    if not spec.scenarios and spec.scenes is None:
        problems.append("name at least one scenario in 'scenarios' or 'scenes'")
    for key, values in spec.grid.items():
        if not values:
            problems.append(f"grid.{key}: give at least one value")
    if spec.samples is not None:
        for key, dist in spec.samples.values.items():
            problems += _check_distribution(f"samples.values.{key}", dist)
    if spec.retries < 0:
        problems.append(f"retries: must be >= 0, got {spec.retries}")
    if problems:
        raise ScenarioError(str(path), problems)
    return spec


def _check_distribution(where: str, dist: dict[str, Any]) -> list[str]:
    if len(dist) != 1 or next(iter(dist)) not in DISTRIBUTIONS:
        return [f"{where}: expected one of {{{', '.join(DISTRIBUTIONS)}: ...}}"]
    kind, args = next(iter(dist.items()))
    if kind == "choice":
        ok = isinstance(args, list) and len(args) > 0
        return [] if ok else [f"{where}.choice: give a non-empty list"]
    if not (
        isinstance(args, list)
        and len(args) == 2
        and all(isinstance(a, int | float) for a in args)
        and args[0] <= args[1]
    ):
        return [f"{where}.{kind}: give [low, high] with low <= high"]
    if kind == "log_uniform" and args[0] <= 0:
        return [f"{where}.log_uniform: low must be > 0"]
    return []


def expand(spec: SweepSpec, path: Path, scenes: list[Path]) -> list[RunSpec]:
    """Every run of ``spec`` (read from ``path``) on its scenarios and ``scenes``.

    Args:
        spec: the sweep.
        path: the sweep file (scenario paths are relative to its folder).
        scenes: generated scene files, with the seed in their name
            (``clutter_<seed>.yaml``).

    Raises:
        ScenarioError: an override does not apply to a scenario.
    """
    bases = [((path.parent / s).resolve(), 0) for s in spec.scenarios]
    bases += [(p.resolve(), int(p.stem.rsplit("_", 1)[-1])) for p in scenes]
    points = [
        dict(zip(spec.grid, combination, strict=True))
        for combination in itertools.product(*spec.grid.values())
    ]
    draws = _draws(spec.samples) if spec.samples is not None else [{}]
    runs: dict[str, RunSpec] = {}  # identical runs (repeated draws) run once
    for (scenario, seed), method, point, draw in itertools.product(
        bases, spec.methods, points, draws
    ):
        values = {**point, **draw}
        overrides = {k: _yaml(v) for k, v in {**spec.set, **values}.items()}
        if "timing" in _settings_fields(method):
            overrides.setdefault(f"method.{method}.timing.clock", spec.clock)
        overrides["method.name"] = method
        key = run_id(scenario, overrides, method, seed)
        runs.setdefault(
            key, RunSpec(key, str(scenario), method, seed, overrides, values)
        )
    return list(runs.values())


def run_id(scenario: Path, overrides: dict[str, str], method: str, seed: int) -> str:
    """Hash of the scenario document after includes and overrides, method, seed.

    Raises:
        ScenarioError: the file or an override has a problem.
    """
    doc = Document.from_file(scenario)
    doc.resolve_includes()
    for key, text in overrides.items():
        doc.override(key, text)
    doc.build(ScenarioSpec, doc.root, "")  # keys and types, as cbp run checks them
    doc.raise_if_problems()
    data = doc.plain(doc.root) if doc.root is not None else None
    text = json.dumps([data, method, seed], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _draws(samples: SampleSpec) -> list[dict[str, Any]]:
    """``samples.count`` draws of every value, from ``samples.seed``."""
    rng = np.random.default_rng(samples.seed)
    draws = []
    for _ in range(samples.count):
        draw: dict[str, Any] = {}
        for key, dist in samples.values.items():
            kind, args = next(iter(dist.items()))
            if kind == "uniform":
                draw[key] = float(rng.uniform(args[0], args[1]))
            elif kind == "log_uniform":
                draw[key] = float(np.exp(rng.uniform(np.log(args[0]), np.log(args[1]))))
            elif kind == "integers":
                draw[key] = int(rng.integers(args[0], args[1], endpoint=True))
            else:
                draw[key] = args[int(rng.integers(len(args)))]
        draws.append(draw)
    return draws


def _settings_fields(method: str) -> set[str]:
    return {f.name for f in dataclasses.fields(METHODS[method].settings)}


def _yaml(value: Any) -> str:
    """A value as ``--set`` text (JSON is YAML)."""
    return json.dumps(value)
