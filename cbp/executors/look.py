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
3. samples configurations near the arm's (each joint moved by up to
   ``look.spread``), free in the map as the planners check it and reached
   from the arm's by a free straight joint motion, and takes the one whose
   camera (mounted on the arm) sees the most of those points: within its
   field of view and range, with no occupied cell between;
4. hands the motion there to the trajectory loop, and holds ``look.dwell``
   after it while the map takes the camera's frames in; the planner then
   searches for the goal again.

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
from cbp.executors.clock import Budget
from cbp.executors.ik_search import IkSearch
from cbp.methods.settings import LookSettings, PlannerSettings
from cbp.perception.frame import camera_parent
from cbp.perception.kernels import OCCUPIED, UNKNOWN
from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray
from cbp.run.parts import RunParts
from cbp.scenario.runtime import Scenario
from cbp.state import RobotState

__all__ = ["LookPlan", "Looker", "sees"]

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


@dataclass(frozen=True)
class LookPlan:
    """A way to a configuration from which the arm's camera sees what is unseen.

    Attributes:
        path: the configurations, the first the start.
        view: the configuration the camera looks from.
        seen: how many of the target points it sees.
        targets: how many target points there were.
    """

    path: FloatArray
    view: FloatArray
    seen: int
    targets: int


def sees(
    camera: pin.SE3,
    spec: CameraSpec,
    points: FloatArray,
    state_at: Callable[[FloatArray], np.ndarray],
    cell: float,
) -> np.ndarray:
    """Which ``points`` (n, 3) a camera at ``camera`` (optical frame) sees.

    Within its field of view (the spec's vertical angle, its image's aspect)
    and range, with no occupied cell on the line to it (``state_at`` gives a
    map's cell states of points; the point's own cell and the one before do
    not count).
    """
    local = (points - camera.translation) @ camera.rotation  # into the camera
    z = local[:, 2]
    half = np.tan(np.deg2rad(spec.fov_deg) / 2.0)
    aspect = spec.width / spec.height
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = (
            (z > spec.near)
            & (z < spec.far)
            & (np.abs(local[:, 1] / z) < half)
            & (np.abs(local[:, 0] / z) < half * aspect)
        )
    out = np.zeros(len(points), dtype=bool)
    if not inside.any():
        return out
    eye = camera.translation
    d = points[inside] - eye
    length = np.linalg.norm(d, axis=1)
    k = max(2, int(np.max(length) / (0.5 * cell)))
    ts = np.linspace(0.0, 1.0, k)
    along = eye + ts[None, :, None] * d[:, None, :]
    before = ts[None, :] * length[:, None] < length[:, None] - 1.5 * cell
    state = state_at(along.reshape(-1, 3)).reshape(len(d), k)
    out[inside] = ~np.any((state == OCCUPIED) & before, axis=1)
    return out


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

    def stop(self) -> None:
        """End the look under way (the planner found the goal meanwhile)."""
        self._looking = False

    def holding(self, run: RunParts) -> bool:
        """Whether the arm should still move to, or hold at, the view.

        The hold ends ``look.dwell`` after the trajectory being followed (the
        look's) ends; then the planner searches for the goal again.
        """
        if not self._looking:
            return False
        t = run.sim.t
        if t < run.sim.trajectory.end_time + self.settings.dwell - 1e-9:
            return True
        self._looking = False
        run.event(
            t,
            f"{self.method}: looked (held the view {self.settings.dwell:g} s); "
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
        t = run.sim.t
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
        run.event(
            run.sim.t,
            f"{self.method}: camera '{self.camera.name}' sees {look.seen} of "
            f"{look.targets} unseen points from a configuration "
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
        unknown = grid.centres(UNKNOWN)
        if not len(unknown):
            return np.zeros((0, 3))
        state = RobotState(self.robot)
        state.update(found)
        placed = world.placed(state)
        # Within each shape's world box grown by the padding and a cell.
        reach = world.padding + grid.cell
        near = np.zeros(len(unknown), dtype=bool)
        for centre, half in zip(placed.centres, placed.halves, strict=True):
            near |= np.all(np.abs(unknown - centre) < half + reach, axis=1)
        return np.asarray(unknown[near], dtype=float)

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
        state = (grid.state_at, grid.cell)
        scored = []
        for sample in samples:
            budget.charge("collision_check")
            if not world.is_free(sample):
                continue
            pose = self._pose(sample)
            seen = [
                int(np.count_nonzero(sees(pose, self.camera, t, *state)))
                for t in targets
            ]
            score = sum(s / len(t) for s, t in zip(seen, targets, strict=True) if s)
            if score > 0:
                move = float(np.max(np.abs(sample - q)))
                scored.append((score, move, sum(seen), sample))
        scored.sort(key=lambda s: (-s[0], s[1]))
        total = sum(len(t) for t in targets)
        for _, _, n, view in scored[:8]:
            path = self._straight(q, view, world, budget)
            if path is None and grow is not None:
                path = grow(q, view, budget)
            if path is not None:
                return LookPlan(path, view, n, total)
        return None

    def _straight(
        self, q: FloatArray, view: FloatArray, world: CollisionWorld, budget: Budget
    ) -> FloatArray | None:
        """The straight joint motion from ``q`` to ``view``, if free all along."""

        def free(c: FloatArray) -> bool:
            budget.charge("collision_check")
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
