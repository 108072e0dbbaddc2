# SPDX-License-Identifier: Apache-2.0
"""MotionBenchMaker problems as cbp scenarios, kept only when valid.

:func:`write_problems` samples problems of each family
(:mod:`cbp.mbm.sampling`) with one seeded stream per attempt, and keeps a
problem, as MotionBenchMaker's generator does, when its start is free of
the scene (the scenario loader's check; for a start query, a collision-free
IK solution of it) and the goal pose has a collision-free IK solution
(:class:`~cbp.executors.ik_search.IkSearch` against the declared objects,
the links padded as the planners pad them). MotionBenchMaker also keeps
only problems its planner solves in 60 s; here that is left to the methods
run on them.

Each problem is written twice, as a CAT scenario with the declared objects
and a camera placement for ``perception.source: depth_camera``
(:mod:`cbp.mbm.cameras`): ``<name>.yaml`` with ours, ``configs/cat.yaml``'s
five cameras turned to face the goal, and ``<name>_mbm_cameras.yaml`` with
MotionBenchMaker's sensor file.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin
import yaml

from cbp.errors import ConfigError, ScenarioError
from cbp.mbm.cameras import mbm_cameras, our_cameras
from cbp.mbm.files import Family, Primitive, family_names, read_family
from cbp.mbm.sampling import query_pose, sample_scene
from cbp.robot import FloatArray

if TYPE_CHECKING:
    from cbp.executors.ik_search import IkSearch
    from cbp.scenario.reach import Reach

__all__ = [
    "Problem",
    "make_problem",
    "problem_document",
    "scenes_command",
    "write_problems",
]

ROBOT = "franka_panda"
#: The tip link of MotionBenchMaker's Panda (its ``panda_arm`` group's).
TIP = "panda_link8"
#: When the goal is given, and the run's length [s].
GOAL_TIME, DURATION = 0.5, 10.0
#: Attempts per wanted problem before a family is given up.
ATTEMPTS = 40
#: How far the goal is moved back along the hand's approach axis (its z) from
#: MotionBenchMaker's, which puts the open fingers around the object [m].
STANDOFF = 0.1


@dataclass(frozen=True)
class Problem:
    """One valid problem of a family.

    Attributes:
        family: the family's name.
        index: its attempt's index (the stream ``[seed, index]``).
        objects: the scene's objects, in the base frame.
        start: the arm's start [rad], by joint name.
        goal: the end effector's goal pose (4, 4), base frame.
        goal_query: the name of the goal's query (``Can3_Front``).
    """

    family: str
    index: int
    objects: tuple[Primitive, ...]
    start: dict[str, float]
    goal: FloatArray
    goal_query: str

    @property
    def name(self) -> str:
        """The scenario's name: ``mbm_<family>_<index>``."""
        return f"mbm_{self.family}_{self.index}"


def _pose(T: FloatArray) -> dict[str, list[float]]:
    rpy = np.rad2deg(pin.rpy.matrixToRpy(T[:3, :3]))
    return {
        "position": [round(float(v), 5) for v in T[:3, 3]],
        "rpy_deg": [round(float(v), 4) for v in rpy],
    }


def _object(o: Primitive) -> dict[str, Any]:
    if o.shape == "box":
        size = list(o.dimensions)
    else:  # MotionBenchMaker: [height, radius]; cbp: [radius, length]
        size = [o.dimensions[1], o.dimensions[0]]
    return {
        "name": o.name,
        "shape": o.shape,
        "size": [float(v) for v in size],
        "pose": _pose(o.pose),
    }


def problem_document(
    problem: Problem, cameras: list[dict[str, Any]], timeout: float = 0.5
) -> dict[str, Any]:
    """``problem`` as a scenario document (a dict to write as YAML).

    Args:
        problem: the problem.
        cameras: the ``perception.cameras`` entries.
        timeout: ``perception.camera_timeout`` [s]; longer than the slowest
            camera's frame period.
    """
    return {
        "name": problem.name,
        "description": (
            f"MotionBenchMaker's {problem.family} family (Panda), problem "
            f"{problem.index}: goal {problem.goal_query}, "
            f"{len(problem.objects)} objects; made by cbp.mbm."
        ),
        "include": "cat",
        "robot": {"name": ROBOT, "initial": problem.start},
        "duration": DURATION,
        "goal": {
            "type": "keyframes",
            "keyframes": [{"t": GOAL_TIME, "pose": _pose(problem.goal)}],
        },
        "world": {"objects": [_object(o) for o in problem.objects]},
        "perception": {
            "source": "ground_truth",
            "unknown": "occupied",
            "cameras": cameras,
            "cell_size": 0.01,
            "camera_timeout": timeout,
        },
    }


def _solve(
    search: IkSearch, pose: FloatArray, near: FloatArray, reach: Reach | None
) -> FloatArray | None:
    """A collision-free IK solution for ``pose`` near ``near``, or None.

    A pose beyond ``reach`` (:class:`~cbp.scenario.reach.Reach`, or None) is
    refused at once. The search is charged on a virtual budget, so the answer
    does not depend on the machine's load; the budget is far more than its
    starts use.
    """
    if reach is not None and reach.beyond(pose[:3, 3]) is not None:
        return None
    from cbp.methods.settings import VirtualCosts
    from cbp.run.budget import VirtualBudget

    goal = pin.SE3(pose[:3, :3], pose[:3, 3])
    found: FloatArray | None = search.solve(
        goal, near, VirtualBudget(60.0, VirtualCosts())
    )
    return found


def _load(path: Path, document: dict[str, Any]) -> Any:
    """Write ``document`` to ``path`` and load it (None: the loader refuses it)."""
    from cbp.scenario import load_scenario

    path.write_text(yaml.safe_dump(document, sort_keys=False))
    try:
        return load_scenario(path)
    except ScenarioError:
        path.unlink()
        return None


def make_problem(
    family: Family, seed: int, index: int, out: Path, standoff: float = STANDOFF
) -> Problem | None:
    """Attempt ``index`` of ``family`` (random stream ``[seed, index]``) into ``out``.

    ``standoff`` [m] moves the goal back along the hand's approach axis:
    MotionBenchMaker's goal is a grasp, the open fingers around the object
    (1 cm from a can on either side, 5 mm from the cage's cube), which our
    padded links cannot reach without touching it.

    Returns the problem when it is valid (its two scenario files are then
    in ``out``), else None (nothing is left in ``out``).
    """
    from cbp.executors.ik_search import IkSearch
    from cbp.methods.settings import IkSearchSettings

    rng = np.random.default_rng([seed, index])
    objects, _ = sample_scene(family, rng)
    start_query = None
    if family.start_queries:
        pairs = [
            (s, g)
            for s in family.start_queries
            for g in family.goal_queries
            if s.name != g.name
        ]
        start_query, goal_query = pairs[int(rng.integers(len(pairs)))]
    else:
        goal_query = family.goal_queries[int(rng.integers(len(family.goal_queries)))]
    draft = Problem(family.name, index, objects, {}, np.eye(4), goal_query.name)
    path = out / f"{draft.name}.yaml"
    document = problem_document(draft, [])
    document["robot"]["allow_initial_contact"] = start_query is not None
    scenario = _load(path, document)
    if scenario is None:
        return None
    robot = scenario.robot
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, scenario.q0)
    tip = data.oMf[robot.frame_id(TIP)]
    ee = data.oMf[robot.frame_id(scenario.ee_frame)]
    tip_to_ee = (tip.inverse() * ee).homogeneous
    back = np.eye(4)
    back[2, 3] = -standoff
    reach = scenario.reach()
    start = {n: v for n, v in family.start_state.items() if n in robot.joint_names}
    q = scenario.q0.copy()
    for k, name in enumerate(robot.joint_names):
        q[k] = start.get(name, q[k])
    world = scenario.world_for_run()
    search = IkSearch(robot, scenario.ee_frame, world, IkSearchSettings())
    if start_query is not None:
        pose = query_pose(start_query, objects, family.ee_offset) @ tip_to_ee @ back
        found = _solve(search, pose, q, reach)
        if found is None:
            path.unlink()
            return None
        q = found
    goal = query_pose(goal_query, objects, family.ee_offset) @ tip_to_ee @ back
    if _solve(search, goal, q, reach) is None:
        path.unlink()
        return None
    problem = Problem(
        family.name,
        index,
        objects,
        {n: round(float(v), 6) for n, v in zip(robot.joint_names, q, strict=True)},
        goal,
        goal_query.name,
    )
    sensors = mbm_cameras(family, objects)
    slowest = min(c["rate_hz"] for c in sensors)
    documents = {
        path: problem_document(problem, our_cameras(goal, world.environment.clearance)),
        out / f"{problem.name}_mbm_cameras.yaml": problem_document(
            problem, sensors, timeout=round(2.5 / slowest, 2)
        ),
    }
    for where, document in documents.items():
        if _load(where, document) is None:
            for other in documents:
                other.unlink(missing_ok=True)
            return None
    return problem


def write_problems(
    root: Path,
    out: Path,
    count: int,
    seed: int = 0,
    families: Sequence[str] | None = None,
) -> list[Path]:
    """Write ``count`` valid problems of each family; return their paths.

    Args:
        root: a MotionBenchMaker checkout (the folder holding ``configs/``).
        out: the folder the scenario files go to.
        count: valid problems per family.
        seed: the first number of every attempt's random stream.
        families: the families (default: every Panda family of ``root``
            whose scene is made of primitives: at f505427, bookshelf_small,
            bookshelf_tall, bookshelf_thin, box, cage, table_pick and
            table_under_pick).

    Returns:
        The scenarios with our cameras (``<name>.yaml``); each has its twin
        with MotionBenchMaker's (``<name>_mbm_cameras.yaml``) beside it. A
        family that gives fewer than ``count`` in ``ATTEMPTS * count``
        attempts gives what it found.
    """
    root = Path(root)
    if not (root / "configs" / "problems").is_dir():
        raise ConfigError(
            f"{root} is not a MotionBenchMaker checkout: it has no configs/problems/",
            "motion_bench_maker",
        )
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for name in families or family_names(root):
        try:
            family = read_family(root, name)
        except ConfigError:
            if families:
                raise
            continue  # a scene of meshes (kitchen, table_bars)
        found = 0
        for index in range(ATTEMPTS * count):
            if found == count:
                break
            problem = make_problem(family, seed, index, out)
            if problem is not None:
                written.append(out / f"{problem.name}.yaml")
                found += 1
    return written


def scenes_command(
    root: Path, out: Path, count: int, seed: int, families: Sequence[str] | None
) -> int:
    """``cbp scenes --mbm ROOT``: write the problems, print their paths; exit code.

    ``count`` problems of each family (``families``, default all); a problem
    of the files is printed on standard error (exit code 2).
    """
    import sys

    try:
        paths = write_problems(root, out, count, seed, families)
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 2
    for path in paths:
        print(path)
    return 0
