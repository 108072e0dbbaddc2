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

Sizes are checked before anything is expanded: a sweep has at most
:data:`MAX_RUNS` runs (scenarios and scenes x methods x grid points x draws)
and :data:`MAX_SCENES` generated scenes; a distribution's bounds are finite
numbers of magnitude at most :data:`~cbp.schema.MAX_MAGNITUDE`; the name is one
folder name (it names the output folder, :func:`cbp.files.check_folder_name`).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml

from cbp.data import is_file
from cbp.errors import require, require_between
from cbp.files import check_folder_name
from cbp.methods import METHODS
from cbp.scenario.spec import ScenarioSpec
from cbp.schema import MAX_MAGNITUDE, Document, Node

__all__ = [
    "MAX_RUNS",
    "MAX_SCENES",
    "RunSpec",
    "SampleSpec",
    "ScenesSpec",
    "SweepSpec",
    "expand",
    "load_sweep",
]


#: Most runs in one sweep (scenarios and scenes x methods x grid points x draws).
MAX_RUNS = 10_000
#: Most generated scenes in one sweep.
MAX_SCENES = 1_000
#: Most retries of a run whose worker dies.
MAX_RETRIES = 100


@dataclass(frozen=True, kw_only=True)
class ScenesSpec:
    """Generated cluttered scenes (:mod:`cbp.scenes`)."""

    count: int
    """How many scenes (at most :data:`MAX_SCENES`)."""
    seed: int = 0
    """The first seed tried; a scene that does not load is skipped."""

    def __post_init__(self) -> None:
        """One to MAX_SCENES scenes; a seed >= 0."""
        require_between(self, 1, MAX_SCENES, "scenes", "count")
        require(self, ">= 0", "seed")


@dataclass(frozen=True, kw_only=True)
class SampleSpec:
    """Seeded random draws of settings.

    Each value is ``{uniform: [low, high]}``, ``{log_uniform: [low, high]}``,
    ``{integers: [low, high]}`` (both ends included) or ``{choice: [a, b, ...]}``.
    """

    count: int
    """Draws; each is combined with every grid point (at most :data:`MAX_RUNS`)."""
    values: dict[str, dict[str, Any]]
    """Distribution of each key."""
    seed: int = 0
    """Seed of the draws: the same seed gives the same values."""

    def __post_init__(self) -> None:
        """One to MAX_RUNS draws; a seed >= 0."""
        require_between(self, 1, MAX_RUNS, "draws", "count")
        require(self, ">= 0", "seed")


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
    (:mod:`cbp.run.budget`): ``virtual`` gives the same results on any
    machine and load."""
    retries: int = 2
    """A run whose worker dies is tried this many more times, then recorded as
    failed."""

    def __post_init__(self) -> None:
        """A name that is a folder name; 0 to MAX_RETRIES retries."""
        check_folder_name(self.name)
        require_between(self, 0, MAX_RETRIES, "retries", "retries")


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
    """Read and check a sweep file, its sizes before anything is expanded.

    Raises:
        ScenarioError: every problem in the file, each with its line.
    """
    doc = Document.from_file(path)
    spec: SweepSpec = doc.build(SweepSpec, doc.root, "")
    doc.raise_if_problems()

    def report(where: str, message: str) -> None:
        doc.report(_node_at(doc.root, where), where, message)

    for i, method in enumerate(spec.methods):
        if method not in METHODS:
            report(
                f"methods[{i}]",
                f"unknown method '{method}'; expected one of " + ", ".join(METHODS),
            )
    if not spec.methods:
        report("methods", "give at least one method")
    for i, scenario in enumerate(spec.scenarios):
        if not is_file(Path(path).parent / scenario):
            report(f"scenarios[{i}]", f"no scenario file {scenario!r} beside the sweep")
    if not spec.scenarios and spec.scenes is None:
        report("", "name at least one scenario in 'scenarios' or 'scenes'")
    for key, values in spec.grid.items():
        if not values:
            report(f"grid.{key}", "give at least one value")
    if spec.samples is not None:
        for key, dist in spec.samples.values.items():
            where = f"samples.values.{key}"
            problem = _distribution_problem(dist)
            if problem:
                report(where, problem)
    runs = sweep_size(spec)
    if runs > MAX_RUNS:
        report(
            "grid" if spec.grid else "samples" if spec.samples else "",
            f"the sweep has {runs} runs ({_size_terms(spec)}), more than the "
            f"{MAX_RUNS} accepted: split it into several sweeps",
        )
    doc.raise_if_problems()
    return spec


def sweep_size(spec: SweepSpec) -> int:
    """The number of runs ``spec`` expands into (before identical runs merge)."""
    bases = len(spec.scenarios) + (spec.scenes.count if spec.scenes else 0)
    points = math.prod(len(v) for v in spec.grid.values())
    draws = spec.samples.count if spec.samples is not None else 1
    return bases * len(spec.methods) * points * draws


def _size_terms(spec: SweepSpec) -> str:
    bases = len(spec.scenarios) + (spec.scenes.count if spec.scenes else 0)
    points = math.prod(len(v) for v in spec.grid.values())
    draws = spec.samples.count if spec.samples is not None else 1
    return (
        f"{bases} scenarios and scenes x {len(spec.methods)} methods x {points} "
        f"grid points x {draws} draws"
    )


def _node_at(root: Node | None, where: str) -> Node | None:
    """The node at a document path (``a.b[2]``; keys may hold dots), or nearest."""
    node = root
    rest = where
    while rest and node is not None:
        if isinstance(node, yaml.SequenceNode) and rest.startswith("["):
            index, _, rest = rest[1:].partition("]")
            rest = rest.removeprefix(".")
            if not index.isdigit() or int(index) >= len(node.value):
                return node
            node = node.value[int(index)]
            continue
        if not isinstance(node, yaml.MappingNode):
            return node
        # The longest key that starts the rest (keys such as 'a.b.c' hold dots).
        best = None
        for key_node, value_node in node.value:
            key = str(key_node.value)
            starts = rest == key or rest.startswith((f"{key}.", f"{key}["))
            if starts and (best is None or len(key) > len(best[0])):
                best = (key, value_node)
        if best is None:
            return node
        node = best[1]
        rest = rest[len(best[0]) :].removeprefix(".")
    return node


def _distribution_problem(dist: dict[str, Any]) -> str:
    """Why a ``samples.values`` entry is not a distribution, or an empty string."""
    if len(dist) != 1 or next(iter(dist)) not in DISTRIBUTIONS:
        return f"expected one of {{{', '.join(DISTRIBUTIONS)}: ...}}"
    kind, args = next(iter(dist.items()))
    if kind == "choice":
        ok = isinstance(args, list) and len(args) > 0
        return "" if ok else "choice: give a non-empty list"
    number = int if kind == "integers" else int | float
    if not (
        isinstance(args, list)
        and len(args) == 2
        and all(isinstance(a, number) and not isinstance(a, bool) for a in args)
    ):
        what = "integers" if kind == "integers" else "numbers"
        return f"{kind}: give [low, high], two {what}, got {args!r}"[:200]
    if not all(math.isfinite(a) and abs(a) <= MAX_MAGNITUDE for a in args):
        return (
            f"{kind}: the bounds must be finite, of magnitude at most "
            f"{MAX_MAGNITUDE:g}, got {args!r}"
        )
    if not args[0] <= args[1]:
        return f"{kind}: give [low, high] with low <= high, got {args!r}"
    if kind == "log_uniform" and args[0] <= 0:
        return "log_uniform: low must be > 0"
    return ""


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
    documents: dict[Path, Document] = {}
    checked: set[tuple[Path, str, str, str]] = set()
    runs: dict[str, RunSpec] = {}  # identical runs (repeated draws) run once
    for (scenario, seed), method, point, draw in itertools.product(
        bases, spec.methods, points, draws
    ):
        values = {**point, **draw}
        overrides = {k: _yaml(v) for k, v in {**spec.set, **values}.items()}
        clock = _clock_key(method)
        if clock is not None:
            overrides.setdefault(clock, spec.clock)
        overrides["method.name"] = method
        if scenario not in documents:
            documents[scenario] = _base_document(scenario)
        # Each value is checked with the scenario in the first run that has
        # it (a full check per run would take minutes for large sweeps).
        signature = {(scenario, method, k, v) for k, v in overrides.items()}
        check = not signature <= checked
        checked |= signature
        key = _run_id(documents[scenario], overrides, method, seed, check)
        runs.setdefault(
            key, RunSpec(key, str(scenario), method, seed, overrides, values)
        )
    return list(runs.values())


def run_id(scenario: Path, overrides: dict[str, str], method: str, seed: int) -> str:
    """Hash of the scenario document after includes and overrides, method, seed.

    Raises:
        ScenarioError: the file or an override has a problem.
    """
    return _run_id(_base_document(scenario), overrides, method, seed, check=True)


def _base_document(scenario: Path) -> Document:
    """The scenario file with its includes merged in."""
    doc = Document.from_file(scenario)
    doc.resolve_includes()
    doc.raise_if_problems()
    return doc


def _run_id(
    base: Document, overrides: dict[str, str], method: str, seed: int, check: bool
) -> str:
    doc = base.copy()
    for key, text in overrides.items():
        doc.override(key, text)
    if check:
        doc.build(ScenarioSpec, doc.root, "")  # keys and types, as cbp run checks
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


def _clock_key(method: str) -> str | None:
    """The ``--set`` key of the clock ``method`` runs on, if it has one.

    A periodic method's loop timing (the table's ``timing``: the hybrid runs
    CAT's loop, with ``method.cat``'s timing).
    """
    section = METHODS[method].timing
    return None if section is None else f"method.{section}.timing.clock"


def _yaml(value: Any) -> str:
    """A value as ``--set`` text (JSON is YAML)."""
    return json.dumps(value)
