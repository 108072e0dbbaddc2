# SPDX-License-Identifier: Apache-2.0
"""``cbp robot init`` and ``cbp robot-pairs``: bring your own robot."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cbp.cli.command import Command, positive_int, read_overrides
from cbp.errors import CbpError

__all__ = ["ROBOT", "ROBOT_PAIRS"]


def _init_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("urdf", type=Path)
    parser.add_argument("--out", type=Path, required=True, help="the robot's folder")
    parser.add_argument("--name", default=None, help="default: the URDF's robot name")
    parser.add_argument(
        "--end-effector",
        default=None,
        help="default: the hand (where the fingers attach), else the last link of "
        "the longest chain",
    )
    parser.add_argument(
        "--control-gripper",
        action="store_true",
        help="keep the gripper's joints in the QP (default: locked, half open)",
    )
    parser.add_argument(
        "--no-copy",
        action="store_true",
        help="name the URDF where it is (a relative path) instead of copying it "
        "and its meshes into the robot's folder",
    )
    parser.add_argument(
        "--samples",
        type=int,
        default=2000,
        help="configurations sampled for self-collision pairs (0: none)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--home",
        action="append",
        default=[],
        metavar="JOINT=VALUE",
        help="home posture of a joint [rad or m] (default: mid-range)",
    )


def _init(args: argparse.Namespace) -> int:
    from cbp.robot_init import describe_urdf, relative_urdf, write_robot_yaml
    from cbp.urdf_files import copy_urdf

    pairs = read_overrides(args.home)
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


def _pairs_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("robot", help="robot name (a folder under robots/)")
    parser.add_argument(
        "--samples", type=positive_int, default=20000, help="random configurations"
    )
    parser.add_argument("--seed", type=int, default=0)


def _pairs(args: argparse.Namespace) -> int:
    import numpy as np

    from cbp.collision import RobotGeometry, find_ignorable_pairs
    from cbp.robot import RobotModel

    name, samples, seed = args.robot, args.samples, args.seed
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


ROBOT = Command(
    "robot",
    "bring your own robot",
    None,
    subcommands=(
        Command(
            "init",
            "write robot.yaml for a URDF arm, saying what it assumed",
            _init,
            _init_arguments,
        ),
    ),
)
ROBOT_PAIRS = Command(
    "robot-pairs",
    "suggest collision.ignore_pairs for robot.yaml by sampling (MoveIt's way)",
    _pairs,
    _pairs_arguments,
)
