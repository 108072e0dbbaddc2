# SPDX-License-Identifier: Apache-2.0
"""The ``cbp`` command: run, check and plugins."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
import typing
from collections.abc import Sequence
from pathlib import Path

from cbp.errors import CbpError, ConfigError
from cbp.methods import COMPARABLE, METHODS
from cbp.registry import Registry
from cbp.schema import type_name

if typing.TYPE_CHECKING:
    from cbp.teleop.profiles import InputProfile


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cbp`` and ``python -m cbp``; returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="cbp",
        description="Constraint-based robot control: run and check scenarios.",
        epilog=(
            "exit status: 0 done; 1 a sweep had runs not ok (failed or raised; "
            "see its report), or a run's output folder was taken meanwhile; 2 bad "
            "input, found before anything ran; 3 a run was aborted after repeated "
            "faults (its outputs are written, the reason is in metrics.json); 4 a "
            "stage after the run failed (clearance, metrics, plots or the report: "
            "the rest is written, metrics.json names it); 130 interrupted."
        ),
    )
    parser.add_argument("--version", action="version", version=f"cbp {_version()}")
    noise = parser.add_mutually_exclusive_group()
    noise.add_argument(
        "-q", "--quiet", action="store_true", help="log errors only (no warnings)"
    )
    noise.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="also every event of a run as it happens (logging at INFO)",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scenario headless and write its outputs")
    run.add_argument("scenario", type=Path)
    run.add_argument(
        "--out", type=Path, default=None, help="output folder (default out/<name>)"
    )
    run.add_argument(
        "--method",
        default=None,
        help=f"executor: {', '.join(METHODS)} (default: the scenario's method.name)",
    )
    run.add_argument("--gui", action="store_true", help="show PyBullet's window")
    _add_set(
        run,
        "override a scenario value, e.g. --set perception.source=depth_camera",
    )
    compare = sub.add_parser(
        "compare", help="run several methods on one recorded goal stream; one report"
    )
    compare.add_argument("scenario", type=Path)
    compare.add_argument(
        "--methods",
        default=",".join(COMPARABLE),
        help=f"comma-separated, from {', '.join(COMPARABLE)} (default: all)",
    )
    compare.add_argument(
        "--out", type=Path, default=None, help="output folder (default out/<name>)"
    )
    compare.add_argument(
        "--jobs", type=int, default=1, help="methods run in this many processes"
    )
    compare.add_argument(
        "--goal",
        type=Path,
        default=None,
        help="replay this recorded goal file (a teleop session's operator_goal.csv)"
        " instead of the scenario's goal, until its end and 2 s more",
    )
    _add_set(
        compare,
        "override a scenario value (as for run)",
    )
    bench = sub.add_parser("bench", help="time the engine, CAT, MP, orbit and map rows")
    bench.add_argument("--quick", action="store_true", help="fewer repetitions")
    bench.add_argument("--out", type=Path, default=None, help="write the rows as JSON")
    bench.add_argument(
        "--results", type=Path, default=None, help="write a RESULTS.md table there"
    )
    check = sub.add_parser("check", help="validate scenario files without running them")
    check.add_argument("scenarios", type=Path, nargs="+")
    _add_set(check, "override a value in every scenario checked (as for run)")
    sub.add_parser("plugins", help="list every plugin with its parameters")
    pairs = sub.add_parser(
        "robot-pairs",
        help="suggest collision.ignore_pairs for robot.yaml by sampling (MoveIt's way)",
    )
    pairs.add_argument("robot", help="robot name (a folder under robots/)")
    pairs.add_argument(
        "--samples", type=_positive_int, default=20000, help="random configurations"
    )
    pairs.add_argument("--seed", type=int, default=0)
    scenes = sub.add_parser(
        "scenes", help="write seeded cluttered scenes (scenario files) for the Panda"
    )
    scenes.add_argument("--count", type=_positive_int, default=30)
    scenes.add_argument("--seed", type=int, default=0, help="first seed")
    scenes.add_argument("--out", type=Path, default=Path("out/scenes"))
    scenes.add_argument(
        "--moving",
        action="store_true",
        help="obstacles that come at a still hand at 2-20 cm/s instead of clutter",
    )
    scenes.add_argument(
        "--mbm", type=Path, help="MotionBenchMaker's Panda problems from this checkout"
    )
    scenes.add_argument("--family", action="append", help="with --mbm: only these")
    robot = sub.add_parser("robot", help="bring your own robot")
    robot_sub = robot.add_subparsers(dest="robot_command", required=True)
    init = robot_sub.add_parser(
        "init", help="write robot.yaml for a URDF arm, saying what it assumed"
    )
    init.add_argument("urdf", type=Path)
    init.add_argument("--out", type=Path, required=True, help="the robot's folder")
    init.add_argument("--name", default=None, help="default: the URDF's robot name")
    init.add_argument(
        "--end-effector",
        default=None,
        help="default: the hand (where the fingers attach), else the last link of "
        "the longest chain",
    )
    init.add_argument(
        "--control-gripper",
        action="store_true",
        help="keep the gripper's joints in the QP (default: locked, half open)",
    )
    init.add_argument(
        "--no-copy",
        action="store_true",
        help="name the URDF where it is (a relative path) instead of copying it "
        "and its meshes into the robot's folder",
    )
    init.add_argument(
        "--samples",
        type=int,
        default=2000,
        help="configurations sampled for self-collision pairs (0: none)",
    )
    init.add_argument("--seed", type=int, default=0)
    init.add_argument(
        "--home",
        action="append",
        default=[],
        metavar="JOINT=VALUE",
        help="home posture of a joint [rad or m] (default: mid-range)",
    )
    view = sub.add_parser(
        "view", help="replay a finished run (or a comparison) in the browser"
    )
    view.add_argument("out", type=Path, help="the run's output folder")
    view.add_argument("--port", type=int, default=8080)
    view.add_argument(
        "--export", type=Path, default=None, help="write a .viser recording instead"
    )
    teleop = sub.add_parser(
        "teleop", help="drive the robot from the browser (prints the page's URL)"
    )
    teleop.add_argument(
        "scenario",
        type=Path,
        nargs="+",
        help="a scenario; or velocity-executor configurations of one robot to "
        "switch between (orbit and pan object)",
    )
    teleop.add_argument(
        "--method", default="cat", help="cat, ik, mp or hybrid (switchable live)"
    )
    teleop.add_argument("--port", type=int, default=8080)
    teleop.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default: localhost)"
    )
    teleop.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default out/<name>_teleop)",
    )
    teleop.add_argument(
        "--device",
        choices=("gamepad", "spacemouse"),
        default=None,
        help="drive with a gamepad or a 6-DOF mouse, read by the page, through its "
        "shipped input profile (hold the deadman to move)",
    )
    teleop.add_argument(
        "--profile",
        default=None,
        help="an input profile file (mapping, dead band, deadman) or a shipped "
        "profile's name; implies its device",
    )
    teleop.add_argument(
        "--hid",
        action="store_true",
        help="read the 6-DOF mouse in this process (hidapi, the hid extra) instead "
        "of in the page (WebHID); its deadman must be one of its buttons",
    )
    _add_set(
        teleop,
        "override a scenario value (as for run)",
    )
    examples = sub.add_parser(
        "examples", help="copy the example scenarios (and configs) out to edit"
    )
    examples.add_argument("out", type=Path, nargs="?", default=Path("cbp_examples"))
    sweep = sub.add_parser(
        "sweep",
        help="run a sweep file (scenes x methods x settings) on Ray or a process pool",
        description="Run a sweep file on Ray or a process pool. A run whose worker "
        "dies is retried (the file's 'retries'), then recorded as failed; a run "
        "that raises is recorded with its error. Exit status 1 when any run is "
        "not ok, 0 when all are; a rerun skips the runs already done.",
    )
    sweep.add_argument("sweep", type=Path, help="the sweep file (YAML)")
    sweep.add_argument("--out", type=Path, default=None, help="default out/<name>")
    sweep.add_argument(
        "--workers", type=_positive_int, default=None, help="CPUs (default: all)"
    )
    sweep.add_argument(
        "--address", default=None, help="join this Ray cluster (ray start --head)"
    )
    sweep.add_argument(
        "--backend",
        choices=("auto", "ray", "pool"),
        default="auto",
        help="ray, a process pool, or ray if installed (auto)",
    )
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.ERROR
        if args.quiet
        else logging.INFO
        if args.verbose
        else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if args.command == "sweep":
        return _sweep(args.sweep, args.out, args.workers, args.address, args.backend)
    if args.command == "run":
        overrides = _overrides(args.set)
        if overrides is None:
            return 2
        return _run(args.scenario, args.out, args.method, args.gui, overrides)
    if args.command == "compare":
        overrides = _overrides(args.set)
        if overrides is None:
            return 2
        if args.goal is not None:
            from cbp.goals import recorded_goal_overrides

            try:
                overrides = {**recorded_goal_overrides(args.goal), **overrides}
            except CbpError as exc:
                print(f"--goal: {exc}", file=sys.stderr)
                return 2
        return _compare(args.scenario, args.methods, args.out, args.jobs, overrides)
    if args.command == "teleop":
        overrides = _overrides(args.set)
        if overrides is None or _missing_extra("teleop", "viewer"):
            return 2
        from cbp.teleop.serve import serve_teleop

        ok, profile = _input_profile(args.device, args.profile)
        if not ok:
            return 2
        return serve_teleop(
            args.scenario,
            args.method,
            args.host,
            args.port,
            args.out,
            overrides,
            profile,
            args.hid,
        )
    if args.command == "bench":
        return _bench(args.quick, args.out, args.results)
    if args.command == "check":
        overrides = _overrides(args.set)
        if overrides is None:
            return 2
        return _check(args.scenarios, overrides)
    if args.command == "robot":
        return _robot_init(args)
    if args.command == "view":
        if _missing_extra("view", "viewer"):
            return 2
        from cbp.viewer import serve

        try:
            return serve(args.out, args.port, args.export)
        except CbpError as exc:
            print(exc, file=sys.stderr)
            return 2
    if args.command == "examples":
        return _examples(args.out)
    if args.command == "robot-pairs":
        return _robot_pairs(args.robot, args.samples, args.seed)
    if args.command == "scenes" and args.mbm is not None:
        from cbp.mbm import scenes_command

        return scenes_command(args.mbm, args.out, args.count, args.seed, args.family)
    if args.command == "scenes":
        from cbp.scenes import write_scenes

        for path in write_scenes(args.out, args.count, args.seed, args.moving):
            print(path)
        return 0
    return _plugins()


#: The modules each optional extra of pyproject.toml brings, by extra.
EXTRAS = {"viewer": ("viser", "yourdfpy")}
#: The example ``cbp examples`` suggests running first: CAT reaches across
#: three boards without touching them (the demo's scenario).
FIRST_EXAMPLE = "cat_boards.yaml"


def _version() -> str:
    """The installed distribution's version."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("cbp")
    except PackageNotFoundError:
        return "(not installed)"


def _missing_extra(command: str, extra: str) -> bool:
    """Say which extra to install when a module of ``extra`` cannot be imported."""
    import importlib

    for module in EXTRAS[extra]:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError:
            print(
                f"cbp {command} needs the {extra} extra ({module} is not "
                f"installed): pip install 'cbp[{extra}]'",
                file=sys.stderr,
            )
            return True
    return False


def _add_set(parser: argparse.ArgumentParser, help_text: str) -> None:
    """The repeatable ``--set KEY=VALUE`` scenario override (read by _overrides)."""
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help=help_text
    )


def _robot_init(args: argparse.Namespace) -> int:
    from cbp.robot_init import describe_urdf, relative_urdf, write_robot_yaml
    from cbp.urdf_files import copy_urdf

    pairs = _overrides(args.home)
    if pairs is None:
        return 2
    try:
        home = {joint: float(value) for joint, value in pairs.items()}
    except ValueError as exc:
        print(f"--home: {exc}", file=sys.stderr)
        return 2
    out: Path = args.out
    if (out / "robot.yaml").exists():
        print(f"{out / 'robot.yaml'} exists; choose a new folder", file=sys.stderr)
        return 2
    try:
        setup = describe_urdf(
            args.urdf,
            name=args.name,
            end_effector=args.end_effector,
            home=home or None,
            samples=args.samples,
            seed=args.seed,
            urdf_entry=relative_urdf(args.urdf, out) if args.no_copy else "robot.urdf",
            lock_gripper=not args.control_gripper,
        )
        copied = None if args.no_copy else copy_urdf(args.urdf, out)
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    if copied is not None:
        setup.assumptions.insert(
            0,
            f"copied {args.urdf.name} to robot.urdf and the {len(copied.meshes)} "
            "files it names (meshes, materials) beside it (--no-copy to name it "
            "where it is)",
        )
        setup.warnings += [
            f"no file found for the URDF's mesh {m} (left as it was)"
            for m in copied.missing
        ]
    path = write_robot_yaml(setup, out)
    print(f"wrote {path}; assumed:")
    for line in setup.assumptions:
        print(f"  - {line}")
    for line in setup.warnings:
        print(f"warning: {line}")
    print(
        f"use it as robot: {{name: {out}}} in a scenario "
        "(include: cat for constraint-aware teleoperation)"
    )
    return 0


def _examples(out: Path) -> int:
    import shutil

    from cbp.data import data_dir

    if out.exists() and any(out.iterdir()):
        print(f"{out} is not empty; choose a new folder", file=sys.stderr)
        return 2
    shutil.copytree(
        data_dir("scenarios"), out, ignore=shutil.ignore_patterns("__pycache__")
    )
    names = sorted(p.name for p in out.glob("*.yaml"))
    print(f"copied {len(names)} scenarios (and configs/, sweeps/) to {out}:")
    for name in names:
        print(f"  {name}")
    if FIRST_EXAMPLE in names:
        print(
            f"run one with: cbp run {out / FIRST_EXAMPLE} (CAT over three boards, "
            "without touching them)"
        )
    return 0


def _input_profile(
    device: str | None, name: str | None
) -> tuple[bool, InputProfile | None]:
    """``cbp teleop``'s input profile (None without a device); False on an error."""
    from cbp.teleop.profiles import load_profile

    if device is None and name is None:
        return True, None
    try:
        profile = load_profile(name or str(device))
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return False, None
    if device is not None and profile.device != device:
        print(
            f"--profile {name} is a {profile.device} profile, not a {device} one",
            file=sys.stderr,
        )
        return False, None
    return True, profile


def _positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _robot_pairs(name: str, samples: int, seed: int) -> int:
    import numpy as np

    from cbp.collision import RobotGeometry, find_ignorable_pairs
    from cbp.robot import RobotModel

    try:
        robot = RobotModel.load(name)
        geometry = RobotGeometry(robot)
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    pairs = find_ignorable_pairs(geometry, np.random.default_rng(seed), samples)
    print(
        f"# {len(pairs)} of {len(geometry.non_adjacent_pairs())} non-adjacent pairs "
        "never "
        f"(or always) collide in {samples} random configurations (seed {seed}):"
    )
    print(f"# cbp robot-pairs {name} --samples {samples} --seed {seed}")
    print("collision:")
    print("  ignore_pairs:")
    for a, b in pairs:
        print(f"    - [{a}, {b}]")
    return 0


def _overrides(items: Sequence[str]) -> dict[str, str] | None:
    """``KEY=VALUE`` pairs from the command line; None (and a message) if malformed."""
    overrides = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            print(f"expected KEY=VALUE, got {item!r}", file=sys.stderr)
            return None
        overrides[key.strip()] = value
    return overrides


def _run(
    path: Path,
    out: Path | None,
    method: str | None,
    gui: bool,
    overrides: dict[str, str],
) -> int:
    from cbp.executors import load_executor
    from cbp.scenario import load_scenario

    try:
        scenario = load_scenario(path, overrides=overrides)
        name = method or scenario.spec.method.name
        executor = load_executor(name)
        METHODS[name].refuse_source(
            scenario.spec.perception.source, f"{scenario.path}: perception.source"
        )
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    out = out or Path("out") / scenario.spec.name
    from cbp.files import claim_output_folder
    from cbp.report import summary_line, write_outputs
    from cbp.run.faults import EXIT_ABORTED, EXIT_INCOMPLETE, stop_on_signals

    try:
        claim = claim_output_folder(out)  # refused if a live run writes there
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    from cbp.progress import run_progress

    try:
        # SIGINT, SIGTERM, SIGHUP: the run brakes and its outputs are written.
        with run_progress(f"{scenario.spec.name} ({name})"), stop_on_signals():
            trace = executor(scenario, gui)
    except ConfigError as exc:  # found as the run starts (a URDF PyBullet refuses)
        claim.release(remove=True)
        print(exc, file=sys.stderr)
        return 2
    except BaseException:
        claim.release(remove=True)
        raise
    try:
        metrics = write_outputs(scenario, {name: trace}, out, claim=claim)[name]
    except CbpError as exc:  # the folder changed during the run; outputs kept
        print(exc, file=sys.stderr)
        return 1
    print(summary_line(scenario, name, metrics))
    print(f"wrote {out}/report.md, metrics.json, trace.csv and plots")
    if trace.aborted:
        return EXIT_ABORTED
    if metrics.get("incomplete"):
        print(
            f"not written: {', '.join(metrics['incomplete'])} (see the events in "
            f"{out}/metrics.json)",
            file=sys.stderr,
        )
        return EXIT_INCOMPLETE
    return 0


def _sweep(
    path: Path, out: Path | None, workers: int | None, address: str | None, backend: str
) -> int:
    from cbp.sweep import load_sweep, run_sweep

    try:
        name = load_sweep(path).name
        outcome = run_sweep(
            path,
            out or Path("out") / name,
            workers=workers,
            address=address,
            progress=True,
            backend=backend,
        )
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    ran = len(outcome.records) - outcome.skipped
    print(
        f"{len(outcome.runs)} runs: {outcome.skipped} already done, {ran} run now "
        f"({outcome.backend}), {outcome.failed} not ok"
    )
    print(f"Report: {outcome.out / 'report.md'}")
    if outcome.interrupted:
        print("interrupted: run the same command again to resume", file=sys.stderr)
        return 130
    if outcome.failed:
        print(
            f"{outcome.failed} of {len(outcome.runs)} runs not ok (see the report)",
            file=sys.stderr,
        )
        return 1
    return 0


def _compare(
    path: Path, methods: str, out: Path | None, jobs: int, overrides: dict[str, str]
) -> int:
    from cbp.compare import compare

    names = [m.strip() for m in methods.split(",") if m.strip()]
    try:
        result = compare(
            path, names, out, jobs=jobs, overrides=overrides, progress=True
        )
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    for name, m in result.metrics.items():
        print(
            f"{name:>3}: reached {m.get('reached')!s:5}  total "
            f"{_num(m.get('total_time_s'))} s  peak force "
            f"{_num(m.get('peak_contact_force_n'))} N"
        )
    print(f"Report: {result.out / 'report.md'}")
    from cbp.run.faults import EXIT_ABORTED, EXIT_INCOMPLETE

    aborted = [name for name, m in result.metrics.items() if m.get("aborted")]
    if aborted:
        print(f"aborted: {', '.join(aborted)} (see the report)", file=sys.stderr)
        return EXIT_ABORTED
    incomplete = [name for name, m in result.metrics.items() if m.get("incomplete")]
    if incomplete:
        print(
            f"outputs incomplete: {', '.join(incomplete)} (see metrics.json)",
            file=sys.stderr,
        )
        return EXIT_INCOMPLETE
    return 0


def _bench(quick: bool, out: Path | None, results: Path | None) -> int:
    """Run the benchmark harness of the source checkout (``benchmarks/bench.py``).

    The harness is not part of the installed package: it times peers (pink,
    placo) and scenes that only the repository has.
    """
    import importlib.util

    harness = Path(__file__).resolve().parents[1] / "benchmarks" / "bench.py"
    spec = importlib.util.spec_from_file_location("cbp_benchmarks_bench", harness)
    if not harness.is_file() or spec is None or spec.loader is None:
        print(
            f"cbp bench runs the benchmark harness of a source checkout "
            f"({harness} is missing): clone the repository and install it with "
            "'pip install -e .[bench]'",
            file=sys.stderr,
        )
        return 2
    bench = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = bench  # dataclasses look their module up
    spec.loader.exec_module(bench)
    config = bench.BenchConfig.quick() if quick else bench.BenchConfig()
    result = bench.run_bench(
        config, progress=lambda row: print(bench.format_row(row), flush=True)
    )
    print("profile of the CAT step (largest own-time shares):")
    for name, pct in result["profile_cat_step"]:
        print(f"  {name}: {pct:.0f} %")
    print("\n".join(bench.targets_table(result["rows"])), flush=True)
    if out is not None:
        bench.dump(result, out)
    if results is not None:
        flags = " --quick" if quick else ""
        bench.write_results(result, results, f"cbp bench{flags} --results {results}")
    return 0


def _num(value: float | None, scale: float = 1.0) -> str:
    return "n/a" if value is None else f"{value * scale:.1f}"


def _check(paths: Sequence[Path], overrides: dict[str, str]) -> int:
    from cbp.scenario import load_scenario

    status = 0
    for path in paths:
        try:
            load_scenario(path, overrides=overrides)
        except CbpError as exc:
            print(exc, file=sys.stderr)
            status = 2
        else:
            print(f"{path}: ok")
    return status


def _plugins() -> int:
    from cbp.plugins.constraints import CONSTRAINTS
    from cbp.plugins.tasks import TASKS
    from cbp.schema import field_docs

    registry: Registry[typing.Any]
    for registry in (TASKS, CONSTRAINTS):
        print(f"{registry.kind}s:")
        for cls in registry:
            print(f"  {cls.type_name}  [{cls.unit}]  default gain {cls.default_gain}")
            summary = (cls.__doc__ or "").strip().splitlines()[0]
            print(f"      {summary}")
            hints = typing.get_type_hints(cls.Params)
            docs = field_docs(cls.Params)
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


if __name__ == "__main__":
    raise SystemExit(main())
