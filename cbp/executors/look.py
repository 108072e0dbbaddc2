# SPDX-License-Identifier: Apache-2.0
"""Look before planning: turn the camera on the arm to the unseen space a goal needs.

With ``perception.unknown: occupied`` a planner needs a configuration for the
goal that lies wholly in space the cameras have seen. Where the goal, or the
arm's way of reaching it, lies in unseen space (behind a wall from the fixed
cameras, or in the arm's own shadow), no such configuration exists until a
camera looks there, and fixed cameras never will. When the IK search for the
goal has tried every start and found nothing, :class:`Looker`:

1. finds what is to be seen: the unseen points of the cube of ``look.radius``
   about the goal, and the unseen cells that a configuration for the goal
   would hold if unseen space were free (the IK search against the map's
   occupied cells alone);
2. says so (an event, once per goal): where the goal is, or what its
   configurations pass through;
3. gathers views: configurations near the arm's (each joint moved by up to
   ``look.spread``), and configurations that aim the camera (mounted on the
   arm) at the centre of each set of points from about it, where the camera
   can be carried through seen free space. Where unseen space keeps the arm
   from every aimed view, the unseen cells keeping it from the one kept by
   the fewest become points to see too, and that view is opened look by look
   until it is free (behind a wall, the arm must first see the space its
   upper links need to rise);
4. takes, of the views free in the map as the planners check it and reached
   by a free motion, the one whose camera would reveal the most of each set
   (:func:`~cbp.executors.visibility.visibility`: within its field of view
   and range, nothing occupied and no part of the arm between, less likely
   the more unseen space lies between);
5. hands the motion there to the trajectory loop, and holds at the view
   until the map has taken ``look.frames`` of the camera's frames captured
   there (``look.dwell`` at the most); the event then says how many of the
   points looked for are seen now, and the planner searches for the goal
   again.

At most ``look.looks`` looks per goal. Without a camera on the arm, the event
says that no camera can be turned there.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from cbp.collision.map_environment import OccupancyEnvironment
from cbp.collision.world import CollisionWorld
from cbp.executors.aiming import clear_line, looking_at, solve_camera, unseen_held
from cbp.executors.ik_search import IkSearch, check_work
from cbp.executors.visibility import CellStates, visibility
from cbp.methods.settings import LookSettings, PlannerSettings
from cbp.perception.frame import camera_parent
from cbp.perception.kernels import OCCUPIED
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray
from cbp.run.budget import Budget
from cbp.run.parts import RunParts
from cbp.scenario.runtime import Scenario
from cbp.state import RobotState

__all__ = ["LookPlan", "Looker"]

#: Plans a checked path from a configuration to another within a budget, or None.
GrowPlan = Callable[[FloatArray, FloatArray, Budget], "FloatArray | None"]

#: Points per side of the cube about the goal whose unseen share is measured.
CUBE_POINTS = 5
#: Configurations sampled per look.
SAMPLES = 600
#: Most target points scored (a random subset of more).
MAX_TARGETS = 400
#: The look's motion is cut into steps of at most this per joint [rad].
STEP = 0.05
#: Camera poses drawn about each set of targets, looking at its centre.
AIMS = 150
#: How far from the centre they are drawn [m].
AIM_NEAR, AIM_FAR = 0.25, 0.6
#: Free configurations found for them at most, and poses tried at most (those
#: that would see the most first).
AIM_SOLVED, AIM_TRIES = 12, 60
#: The views kept from by the fewest unseen cells whose cells are looked for.
AIM_OPEN = 2


@dataclass(frozen=True)
class LookPlan:
    """A way to a configuration from which the arm's camera sees what is unseen.

    Attributes:
        path: the configurations, the first the start.
        view: the configuration the camera looks from.
        seen: how many of the target points it is expected to see.
        targets: the target points (n, 3).
    """

    path: FloatArray
    view: FloatArray
    seen: int
    targets: FloatArray


class Looker:
    """Turns a camera on the arm to the unseen space a goal needs, before planning.

    Args:
        scenario: the scenario (its cameras and ``perception:``).
        run: the run's parts.
        settings: the planner's settings (``look:`` and the IK search's).
        method: the planner's name, for events.
    """

    def __init__(
        self,
        scenario: Scenario,
        run: RunParts,
        settings: PlannerSettings,
        method: str,
    ) -> None:
        """Find the camera to turn (None: the unseen goal is only said)."""
        self.settings: LookSettings = settings.look
        self.method = method
        self._search_settings = settings.search
        perception = scenario.spec.perception
        self.enabled = (
            self.settings.enabled
            and run.cameras is not None
            and perception.unknown_blocks
            and run.world is not None
        )
        self.robot = scenario.robot
        self.ee_frame = run.ee_frame
        self.camera = _mounted_camera(perception.all_cameras, self.settings.camera)
        self._frame = (
            self.robot.frame_id(camera_parent(self.camera.parent, self.robot))
            if self.camera is not None and self.camera.parent is not None
            else None
        )
        self._offset = (
            self.camera.offset.to_se3() if self.camera is not None else pin.SE3()
        )
        self._data = self.robot.model.createData()
        self._rng = np.random.default_rng(0)
        self._goal: pin.SE3 | None = None
        self._looks = 0  # looks made for this goal
        self._said = False  # what is unseen was said
        self._looking = False  # moving to a view, or holding there
        # A look being worked out over the periods: the search for the goal
        # against the seen obstacles (its starts go on where the budget
        # stopped them), and a look found after the period's budget ran out.
        self._seen: IkSearch | None = None
        self._ready: LookPlan | None = None
        self._watched: FloatArray = np.zeros((0, 3))  # what the look is for
        self._opening: list[FloatArray] = []  # a view unseen space keeps from

    @property
    def pending(self) -> bool:
        """A look is being worked out: call :meth:`plan` again next period."""
        return self._seen is not None or self._ready is not None

    # ------------------------------------------------------------------ state

    def reset(self, goal: pin.SE3) -> None:
        """Start afresh for ``goal`` when it is a new one."""
        if self._goal is not None and goal.isApprox(self._goal, 1e-9):
            return
        self._goal = goal
        self._looks = 0
        self._said = False
        self._looking = False
        self._seen = None
        self._ready = None
        self._opening = []

    def stop(self) -> None:
        """End the look under way (the planner found the goal meanwhile)."""
        self._looking = False

    def holding(self, run: RunParts) -> bool:
        """Whether the arm should still move to, or hold at, the view.

        The hold ends once the map has taken ``look.frames`` frames of the
        camera captured after the look's trajectory ended (``look.dwell``
        after it at the latest); then the planner searches for the goal again.
        """
        if not self._looking:
            return False
        assert self.camera is not None
        t = run.arm.t
        arrived = run.arm.trajectory.end_time
        if t < arrived - 1e-9:
            return True  # still on the way to the view
        mapped = run.mapped_since(self.camera.name, arrived)
        if mapped < self.settings.frames and t < arrived + self.settings.dwell - 1e-9:
            return True
        self._looking = False
        watched = self._watched
        seen = len(watched) - int(np.count_nonzero(run.unseen(watched)))
        run.event(
            t,
            f"{self.method}: looked (held the view {max(t - arrived, 0.0):.2f} s; "
            f"{min(mapped, self.settings.frames)} of its frames mapped; "
            f"{seen} of the {len(watched)} unseen points looked for are seen now); "
            "searching for the goal again",
        )
        return False

    def unseen_share(self, run: RunParts, goal: pin.SE3) -> float:
        """The share of the cube of ``look.radius`` about the goal that is unseen."""
        return float(np.mean(run.unseen(self._cube(goal))))

    # ------------------------------------------------------------------ a look

    def plan(
        self,
        q: FloatArray,
        goal: pin.SE3,
        budget: Budget,
        run: RunParts,
        grow: GrowPlan | None = None,
    ) -> LookPlan | None:
        """A look for ``goal`` from ``q`` (free, at rest or on its way), or None.

        Call after the IK search for ``goal`` found nothing from any start.
        None when nothing unseen stands in the way, when no camera can be
        turned, when the looks for this goal are used up, or when no sampled
        configuration sees any of it.

        Args:
            q: where the look's motion starts (collision-free).
            goal: the goal pose.
            budget: this period's budget (the work is charged to it).
            run: the run's parts.
            grow: plans a way to a view that the straight motion does not
                reach (None: straight motions only).
        """
        if not self.enabled:
            return None
        self.reset(goal)
        ready, self._ready = self._ready, None
        if ready is not None and np.array_equal(ready.path[0], q):
            return self._begin(ready, q, run)
        if self._looks >= self.settings.looks:
            return None
        found = self._targets(run, goal, q, budget)
        if found is None:
            return None  # the search goes on next period
        targets, share, through = found
        if share < self.settings.unseen_share and not through:
            return None  # what holds the search is not unseen space
        t = run.arm.t
        if not self._said:
            self._said = True
            cube = f"{share:.0%} of the {2 * self.settings.radius * 100:.0f} cm cube"
            where = (
                f"the goal lies in space no camera has seen ({cube} about it)"
                if share >= self.settings.unseen_share
                else "the goal's configurations pass through space no camera has "
                f"seen ({through} cells; {cube} about the goal)"
            )
            turn = (
                f"turning camera '{self.camera.name}' to look before planning"
                if self.camera is not None and self._frame is not None
                else "no camera on the arm to turn there"
            )
            run.event(t, f"{self.method}: {where}; {turn}")
        if self._frame is None or self.camera is None:
            self._looks = self.settings.looks
            return None
        look = self._view(q, targets, budget, run, grow)
        self._looks += 1
        if look is not None and budget.spent():
            self._ready = look  # too late for this period's plan
            return None
        if look is None:
            run.event(
                t,
                f"{self.method}: no free configuration near the arm's lets camera "
                f"'{self.camera.name}' see the unseen space (look {self._looks} of "
                f"{self.settings.looks})",
            )
            return None
        return self._begin(look, q, run)

    def _begin(self, look: LookPlan, q: FloatArray, run: RunParts) -> LookPlan:
        """Say that ``look`` is made; hold after it."""
        assert self.camera is not None
        self._looking = True
        self._watched = look.targets
        run.event(
            run.arm.t,
            f"{self.method}: camera '{self.camera.name}' sees about {look.seen} of "
            f"{len(look.targets)} unseen points from a configuration "
            f"{float(np.max(np.abs(look.view - q))):.2f} rad away; moving there "
            "to look",
        )
        return look

    def _cube(self, goal: pin.SE3) -> FloatArray:
        """Points of the cube of ``look.radius`` about the goal's position (n, 3)."""
        r = self.settings.radius
        side = np.linspace(-r, r, CUBE_POINTS)
        offsets = np.array(list(itertools.product(side, side, side)))
        return np.asarray(goal.translation + offsets, dtype=float)

    def _targets(
        self, run: RunParts, goal: pin.SE3, q: FloatArray, budget: Budget
    ) -> tuple[list[FloatArray], float, int] | None:
        """What is to be seen, the cube's unseen share, the unseen cells held.

        Two sets of points (n, 3): the cube's unseen points, and the unseen
        cells a configuration for the goal would hold were unseen space free
        (at most :data:`MAX_TARGETS`, drawn at random). None while that search
        goes on (the budget ran out).
        """
        cube = self._cube(goal)
        unseen = run.unseen(cube)
        held = self._held_unseen(run, goal, q, budget)
        if held is None:
            return None
        some = held
        if len(held) > MAX_TARGETS:
            some = held[self._rng.choice(len(held), MAX_TARGETS, replace=False)]
        return [cube[unseen], some], float(np.mean(unseen)), len(held)

    def _held_unseen(
        self, run: RunParts, goal: pin.SE3, q: FloatArray, budget: Budget
    ) -> FloatArray | None:
        """The unseen cell centres that the nearest configuration for the goal holds.

        That configuration is searched against the occupied cells alone (what
        the cameras have seen to be there; the map as it was when the look
        began); none: no points. None while the search goes on.
        """
        world, cameras = run.world, run.cameras
        assert world is not None
        assert cameras is not None
        grid = cameras.grid
        if self._seen is None:
            seen = CollisionWorld(
                world.geometry,
                OccupancyEnvironment(grid.centres(OCCUPIED), grid.cell),
                world.settings,
            )
            self._seen = IkSearch(
                self.robot, self.ee_frame, seen, self._search_settings
            )
        found = self._seen.solution_for(goal, q, budget)
        if found is None and budget.spent():
            return None
        self._seen = None
        if found is None:
            return np.zeros((0, 3))
        # Within a cell of the padded shapes (their world boxes would hold
        # several times as many cells, most of them free of the arm).
        return unseen_held(world, grid, found)

    def _view(
        self,
        q: FloatArray,
        targets: list[FloatArray],
        budget: Budget,
        run: RunParts,
        grow: GrowPlan | None,
    ) -> LookPlan | None:
        """The sampled configuration near ``q`` whose camera sees the most targets.

        Each set of targets counts as much as the other: the share of each
        seen, added.
        """
        world = run.world
        assert world is not None
        assert self.camera is not None
        robot = self.robot
        lower, upper = robot.lower_limits, robot.upper_limits
        # The joints nearer the camera move more: they turn it with the least
        # of the arm moving into space not seen yet. Half the samples move
        # every joint, half only the last three (a wrist); each by a quarter,
        # a half or all of the spread.
        n = q.size
        weight = np.arange(1, n + 1) / n
        wrist = np.where(np.arange(n) >= n - 3, 1.0, 0.0)
        k = np.arange(SAMPLES)[:, None]
        reach = (
            self.settings.spread
            * np.where(k % 2 == 0, weight, wrist)
            * np.array([0.25, 0.5, 1.0])[(k // 2) % 3]
        )
        samples = np.clip(
            q + reach * self._rng.uniform(-1.0, 1.0, (SAMPLES, n)), lower, upper
        )
        assert run.cameras is not None
        grid = run.cameras.grid
        aimed, blocking = self._aimed(q, targets, grid, world, budget)
        samples = np.vstack([samples, aimed])
        if len(blocking) > MAX_TARGETS:
            pick = self._rng.choice(len(blocking), MAX_TARGETS, replace=False)
            blocking = blocking[pick]
        targets = [*targets, blocking]
        geometry = world.geometry
        body = RobotState(robot)
        states = CellStates(grid.cells, grid.lower, grid.cell)
        scored = []
        for sample in samples:
            budget.charge(check_work(world))
            if not world.is_free(sample):
                continue
            body.update(sample)
            pose = self._pose(sample)
            # The shapes themselves (not grown by the padding) hide what is
            # behind them.
            shapes = geometry.world_shapes(body)
            seen = [
                float(np.sum(visibility(pose, self.camera, t, states, shapes)))
                for t in targets
            ]
            score = sum(s / len(t) for s, t in zip(seen, targets, strict=True) if s)
            if score > 0:
                move = float(np.max(np.abs(sample - q)))
                scored.append((score, move, round(sum(seen)), sample))
        scored.sort(key=lambda s: (-s[0], s[1]))
        total = np.vstack(targets)
        for _, _, n, view in scored[:8]:
            path = self._straight(q, view, world, budget)
            if path is None and grow is not None:
                path = grow(q, view, budget)
            if path is not None:
                return LookPlan(path, view, n, total)
        return None

    def _aimed(
        self,
        q: FloatArray,
        targets: list[FloatArray],
        grid: OccupancyGrid,
        world: CollisionWorld,
        budget: Budget,
    ) -> tuple[FloatArray, FloatArray]:
        """Configurations whose camera looks straight at the targets, from about them.

        Views near the arm's configuration see little where the unseen space
        lies behind an obstacle (the arm would have to rise over it and look
        down). So camera poses are drawn about the centre of each set of
        targets, looking at it from :data:`AIM_NEAR` to :data:`AIM_FAR` away,
        where the camera can be carried from where it is through seen free
        space (a straight line); those that would see the most are solved for
        (the camera's roll left as near the arm's as it turns).

        Returns:
            The free configurations found (m, n), and the unseen cells that
            keep the arm from the :data:`AIM_OPEN` others kept by the fewest
            (k, 3): a look there first opens the way to them.
        """
        sets = [t for t in targets if len(t)]
        rng = self._rng
        found: list[FloatArray] = []
        candidates: list[tuple[float, pin.SE3]] = []
        here = self._pose(q)
        states = CellStates(grid.cells, grid.lower, grid.cell)
        assert self.camera is not None
        for centre in (np.mean(t, axis=0) for t in sets):
            u = rng.normal(size=(AIMS, 3))
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            eyes = centre + u * rng.uniform(AIM_NEAR, AIM_FAR, (AIMS, 1))
            for eye in eyes:
                if not clear_line(here.translation, eye, grid):
                    continue
                pose = looking_at(eye, centre, here.rotation)
                score = sum(
                    float(np.mean(visibility(pose, self.camera, t, states)))
                    for t in sets
                )
                if score > 0:
                    candidates.append((score, pose))
        candidates.sort(key=lambda c: -c[0])
        # The view the last look began to open, first: it may be free now.
        assert self._frame is not None
        frame = self._frame
        solves = (
            solve_camera(self.robot, frame, self._offset, p, q, budget)
            for _, p in candidates[:AIM_TRIES]
        )
        kept: list[tuple[FloatArray, FloatArray]] = []
        for solved in itertools.chain(self._opening, solves):
            if solved is None:
                continue
            budget.charge(check_work(world))
            if world.is_free(solved):
                found.append(solved)
                if len(found) == AIM_SOLVED:
                    break
            else:
                kept.append((solved, unseen_held(world, grid, solved)))
        # The views that the fewest unseen cells keep the arm from; the one
        # kept by the fewest is opened until it is free (else every look would
        # open a little of another).
        kept.sort(key=lambda k: len(k[1]))
        self._opening = [k[0] for k in kept[:1]]
        blocked = [k[1] for k in kept[:AIM_OPEN]]
        cells = np.unique(np.vstack([np.zeros((0, 3)), *blocked]), axis=0)
        return np.array(found).reshape(-1, q.size), cells

    def _straight(
        self, q: FloatArray, view: FloatArray, world: CollisionWorld, budget: Budget
    ) -> FloatArray | None:
        """The straight joint motion from ``q`` to ``view``, if free all along."""

        def free(c: FloatArray) -> bool:
            budget.charge(check_work(world))
            return world.is_free(c)

        if not world.motion_free(q, view, free):
            return None
        n = max(1, int(np.ceil(np.max(np.abs(view - q)) / STEP)))
        return q + (view - q) * (np.arange(n + 1)[:, None] / n)

    def _pose(self, q: FloatArray) -> pin.SE3:
        """The camera's optical pose at ``q``."""
        assert self._frame is not None
        pin.framesForwardKinematics(self.robot.model, self._data, q)
        return self._data.oMf[self._frame] * self._offset


def _mounted_camera(cameras: list[CameraSpec], name: str | None) -> CameraSpec | None:
    """The camera named ``name``, else the first mounted on the robot."""
    for camera in cameras:
        if camera.parent is not None and (name is None or camera.name == name):
            return camera
    return None
