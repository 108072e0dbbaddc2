# SPDX-License-Identifier: Apache-2.0
"""The ``cbp`` command: run, check and plugins."""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import sys
import typing
from collections.abc import Sequence
from pathlib import Path

from cbp.errors import CbpError, ScenarioError
from cbp.registry import Registry
from cbp.schema import type_name


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cbp`` and ``python -m cbp``; returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="cbp",
        description="Constraint-based robot control: run and check scenarios.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scenario headless and write its outputs")
    run.add_argument("scenario", type=Path)
    run.add_argument(
        "--out", type=Path, default=None, help="output folder (default out/<name>)"
    )
    check = sub.add_parser("check", help="validate scenario files without running them")
    check.add_argument("scenarios", type=Path, nargs="+")
    sub.add_parser("plugins", help="list every plugin with its parameters")
    args = parser.parse_args(argv)
    if args.command == "run":
        return _run(args.scenario, args.out)
    if args.command == "check":
        return _check(args.scenarios)
    return _plugins()


def _run(path: Path, out: Path | None) -> int:
    from cbp.executors.kinematic import run_kinematic
    from cbp.report import write_outputs
    from cbp.scenario import load_scenario

    try:
        scenario = load_scenario(path)
    except ScenarioError as exc:
        print(exc, file=sys.stderr)
        return 2
    out = out or Path("out") / scenario.spec.name
    trace = run_kinematic(scenario)
    metrics = write_outputs(scenario, trace, out)
    print(
        f"{scenario.spec.name}: {metrics['steps']} steps, final position error "
        f"{metrics['final_position_error_m']} m, {metrics['events']} events"
    )
    print(f"wrote {out}/report.md, metrics.json, trace.csv, tracking.png")
    return 0


def _check(paths: Sequence[Path]) -> int:
    from cbp.scenario import load_scenario

    status = 0
    for path in paths:
        try:
            load_scenario(path)
        except CbpError as exc:
            print(exc, file=sys.stderr)
            status = 2
        else:
            print(f"{path}: ok")
    return status


def _plugins() -> int:
    from plugins.constraints import CONSTRAINTS
    from plugins.tasks import TASKS

    registry: Registry[typing.Any]
    for registry in (TASKS, CONSTRAINTS):
        print(f"{registry.kind}s:")
        for cls in registry:
            print(f"  {cls.type_name}  [{cls.unit}]  default gain {cls.default_gain}")
            summary = (cls.__doc__ or "").strip().splitlines()[0]
            print(f"      {summary}")
            hints = typing.get_type_hints(cls.Params)
            docs = _field_docs(cls.Params)
            for f in dataclasses.fields(cls.Params):
                if f.default is not dataclasses.MISSING:
                    default = f"default {f.default!r}"
                elif f.default_factory is not dataclasses.MISSING:
                    default = f"default {f.default_factory()!r}"
                else:
                    default = "required"
                print(f"      params.{f.name}: {type_name(hints[f.name])}, {default}")
                if f.name in docs:
                    print(f"          {docs[f.name]}")
        extra = registry.entry_point_names()
        if extra:
            print(f"  from installed distributions: {', '.join(extra)}")
    return 0


def _field_docs(cls: type) -> dict[str, str]:
    """Attribute docstrings of a dataclass (the string after each field)."""
    import ast
    import inspect
    import textwrap

    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError):
        return {}
    body = (
        tree.body[0].body
        if tree.body and isinstance(tree.body[0], ast.ClassDef)
        else []
    )
    docs: dict[str, str] = {}
    for prev, node in itertools.pairwise(body):
        if (
            isinstance(prev, ast.AnnAssign)
            and isinstance(prev.target, ast.Name)
            and isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)
        ):
            docs[prev.target.id] = " ".join(node.value.value.split())
    return docs


if __name__ == "__main__":
    raise SystemExit(main())
