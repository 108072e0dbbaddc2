# SPDX-License-Identifier: Apache-2.0
"""What a goal page draws around the robot: contacts, the path, the map, the goal.

CAT's contacts as normals coloured by distance, with a red arrow of the
blocked direction at each contact that holds the arm; the commanded
trajectory's hand path; a goal the arm stops short of as a magenta gripper
with the closest posture as an orange wireframe, both labelled through the
declared objects, which turn translucent meanwhile (an x-ray); and with
cameras the map's occupied cells (and, on a toggle, the unknown ones).

Each drawing is sent only when it would look different: every change costs
the browser a frame, on the cores the control loop runs on.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from cbp.drawing import add_gripper, add_robot, draw_objects
from cbp.executors.cat import HOLDING_DISTANCE
from cbp.perception.kernels import OCCUPIED, UNKNOWN
from cbp.robot import FloatArray
from cbp.state import RobotState
from cbp.teleop.goal_session import Snapshot, TeleopSession
from cbp.teleop.readout import (
    BLOCKED,
    CELLS,
    CLOSEST_POSTURE,
    GOAL_GRIPPER,
    PATH,
    UNREACHABLE,
)

__all__ = ["DRAWN_TOLERANCE", "MAX_CELLS", "GoalScene", "same_drawing"]

#: The map's cells are redrawn this often [s].
MAP_PERIOD = 0.5
#: Length of a contact's normal as drawn [m].
CONTACT_ARROW = 0.04
#: A goal is drawn out of reach once the arm's trajectory has ended short of
#: it, where the hand already is, and has stayed there this long [s of
#: simulated time].
STALLED_FOR = 0.5
#: Cells drawn at most (the nearest to the hand first).
MAX_CELLS = 60_000
#: Length of a blocked direction's arrow as drawn [m].
BLOCKED_ARROW = 0.06
#: Opacity of the declared objects while the arm holds short of the goal
#: (an x-ray: the gripper and the closest posture inside them stay visible).
XRAY_OPACITY = 0.3
#: Lines drawn (and a robot's joints) that differ by less than this from those
#: on the page are not sent again: each change costs the browser a frame
#: [m, colour 0-1, rad].
DRAWN_TOLERANCE = 2e-4


def same_drawing(drawn: np.ndarray, new: np.ndarray) -> bool:
    """Whether ``new`` would look like ``drawn`` (same shape, within tolerance)."""
    return drawn.shape == new.shape and bool(
        np.allclose(drawn, new, rtol=0.0, atol=DRAWN_TOLERANCE)
    )


class GoalScene:
    """The drawings of a goal session's page besides the robot and the gizmo.

    Args:
        server: the page's viser server (its ``/goal`` gizmo already added).
        session: the session drawn.
        description: the scene description (:func:`cbp.scene_file.scene_description`).
        urdf_values: the URDF's actuated joints' values for a configuration.

    Attributes:
        ghost: the closest posture's wireframe robot (None without a URDF).
        unreachable: whether the arm has stopped short of the goal.
        path_lines: the commanded path's segments as last sent, or None.
        blocked_arrows: arrows of blocked directions drawn.
        xray: whether the declared objects are drawn translucent.
        cells: the map's cells drawn.
    """

    def __init__(
        self,
        server: Any,
        session: TeleopSession,
        description: dict[str, Any],
        urdf_values: Callable[[FloatArray], FloatArray],
    ) -> None:
        """Add the objects, the gripper, the ghost and their labels (hidden)."""
        self.server = server
        self.session = session
        self._urdf_values = urdf_values
        self._objects = draw_objects(server, description)
        urdf = description.get("urdf")
        # Where the arm is heading when the goal is out of its reach: a
        # wireframe robot at the end of the commanded trajectory, and the
        # goal drawn as a gripper (the CAT paper's operator view), each with
        # a label drawn through obstacles.
        self.ghost = (
            add_robot(server, urdf, "/reachable", CLOSEST_POSTURE)
            if urdf is not None
            else None
        )
        # viser 1.1.1's ViserUrdf takes no wireframe option: its meshes are
        # switched to wireframe here (a ghost that would cover the arm
        # otherwise; the arm's own posture stays readable through it).
        for mesh in getattr(self.ghost, "_meshes", []):
            mesh.wireframe = True
        if self.ghost is not None:
            self.ghost.show_collision = False
        self.gripper = add_gripper(server, "/goal/gripper", GOAL_GRIPPER)
        server.scene.add_label("/goal/gripper/label", "goal (out of reach)")
        self._ghost_label = server.scene.add_label(
            "/closest_label", "closest posture", visible=False
        )
        robot = session.scenario.robot
        self._state = RobotState(robot)
        self._hand = robot.frame_id(session.scenario.ee_frame)
        self.unreachable = False
        self._short_since: float | None = None
        self.xray = False
        self.path_lines: np.ndarray | None = None
        self._drawn_path: object = None
        self._drawn_contacts: object = False  # nothing drawn yet
        #: The contacts' lines and holding flags as last sent.
        self._contact_lines: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._arrows: Any = None
        self.blocked_arrows = 0
        self._cells: Any = None
        self._map_drawn: tuple[object, bool, float] = (None, False, -math.inf)

    @property
    def cells(self) -> int:
        """The map's cells drawn (0 without cameras)."""
        return 0 if self._cells is None else len(self._cells.points)

    def draw_contacts(self, snap: Snapshot) -> None:
        """CAT's contacts: a normal at each robot witness point, by distance.

        Red at contact or closer, through yellow, to green at the safety
        distance's 5 cm and beyond. At each contact that holds the arm (within
        CAT's holding distance of its bound) a red arrow of the blocked
        direction: along the contact normal reversed, toward the obstacle,
        the way the contact row forbids the arm's point to move; drawn on the
        arm's side, its tip at the witness point.
        """
        contacts = snap.contacts
        if contacts is self._drawn_contacts:
            return
        self._drawn_contacts = contacts
        if contacts is None or not len(contacts.distance):
            points = np.zeros((0, 2, 3))
            colours = np.zeros((0, 2, 3))
            holding = np.zeros(0, dtype=bool)
        else:
            start = contacts.point
            points = np.stack([start, start + CONTACT_ARROW * contacts.normal], axis=1)
            closeness = np.clip(1.0 - contacts.distance / 0.05, 0.0, 1.0)
            rgb = np.stack(
                [closeness, 1.0 - 0.5 * closeness, np.zeros_like(closeness)], axis=1
            )
            colours = np.repeat(rgb[:, None, :], 2, axis=1)
            holding = contacts.distance <= HOLDING_DISTANCE
        drawn = self._contact_lines
        if (
            drawn is not None
            and same_drawing(drawn[0], points)
            and same_drawing(drawn[1], colours)
            and np.array_equal(drawn[2], holding)
        ):
            return  # as drawn: nothing sent (each change costs the browser a frame)
        self._contact_lines = (points, colours, holding)
        self.server.scene.add_line_segments(
            "/contacts", points, colours, thickness=3.0, thickness_units="screen"
        )
        self.blocked_arrows = int(holding.sum())
        if not holding.any():
            if self._arrows is not None:
                self._arrows.visible = False
            return
        assert contacts is not None
        tips = contacts.point[holding]
        tails = tips + BLOCKED_ARROW * contacts.normal[holding]
        self._arrows = self.server.scene.add_arrows(
            "/blocked",
            np.stack([tails, tips], axis=1),
            BLOCKED,
            shaft_radius=0.004,
            head_radius=0.01,
            head_length=0.02,
        )

    def draw_path(self, snap: Snapshot, goal: np.ndarray) -> None:
        """The commanded trajectory's hand path, and the goal if out of reach.

        Out of reach (:attr:`unreachable`): the gripper at the goal, the
        closest posture, and the objects in x-ray.
        """
        trajectory = snap.trajectory
        if trajectory is None:
            return
        if trajectory is not self._drawn_path:  # a new one was spliced in
            self._drawn_path = trajectory
            self._send_path(trajectory, snap.t)
        end = trajectory.positions[-1]
        self._state.update(end)
        heading = self._state.frame_position(self._hand)
        short = float(np.linalg.norm(goal - heading))
        # Out of reach: the arm's trajectory ends short of the goal, where the
        # hand already is (it is not on its way to anywhere nearer).
        stalled = float(np.linalg.norm(heading - snap.hand)) < UNREACHABLE / 4
        if not (short > UNREACHABLE and stalled):
            self._short_since = None
        elif self._short_since is None:
            self._short_since = snap.t
        # For a while: a new goal is short of the arm until it is planned for.
        unreachable = (
            self._short_since is not None and snap.t - self._short_since >= STALLED_FOR
        )
        self.unreachable = unreachable
        self.gripper.visible = unreachable
        if self.ghost is not None:
            if unreachable:
                self.ghost.update_cfg(self._urdf_values(end))
            self.ghost.show_collision = unreachable
        if unreachable:
            self._ghost_label.position = tuple(heading)
        self._ghost_label.visible = unreachable
        self._show_xray(unreachable)

    def _send_path(self, trajectory: Any, t: float) -> None:
        """Send the hand's path along ``trajectory`` from ``t`` on, if it moved."""
        ahead = int(np.searchsorted(trajectory.times, t))
        path = (
            trajectory.positions[ahead:]
            if ahead < len(trajectory.times)
            else trajectory.positions[-1:]
        )
        keep = np.unique(np.linspace(0, len(path) - 1, min(len(path), 60)).astype(int))
        hands = np.empty((len(keep), 3))
        for i, k in enumerate(keep):
            self._state.update(path[k])
            hands[i] = self._state.frame_position(self._hand)
        segments = (
            np.stack([hands[:-1], hands[1:]], axis=1)
            if len(hands) > 1
            else np.zeros((0, 2, 3))
        )
        # A trajectory spliced in at rest draws the same path: not sent
        # (each change costs the browser a frame).
        if self.path_lines is None or not same_drawing(self.path_lines, segments):
            self.path_lines = segments
            self.server.scene.add_line_segments(
                "/commanded",
                segments,
                PATH,
                thickness=2.0,
                thickness_units="screen",
            )

    def _show_xray(self, xray: bool) -> None:
        """The declared objects translucent (``xray``) or as declared."""
        if xray == self.xray:
            return
        self.xray = xray
        for handle in self._objects.values():
            if hasattr(handle, "opacity"):  # boxes, spheres, cylinders
                handle.opacity = XRAY_OPACITY if xray else None

    def draw_map(self, t: float, hand: np.ndarray, unknown: bool) -> None:
        """Redraw the map's cells (``unknown``: those too) when it or that changed."""
        parts = self.session.parts
        world = parts.world
        if parts.cameras is None or world is None:
            return
        environment = world.environment
        drawn, drawn_unknown, drawn_t = self._map_drawn
        if environment is drawn and unknown == drawn_unknown:
            return
        if unknown == drawn_unknown and t - drawn_t < MAP_PERIOD:
            return  # a new map, drawn at most every MAP_PERIOD
        self._map_drawn = (environment, unknown, t)
        # The grid's own states (the environment holds the obstacle shell, in
        # which occupied and unknown cells are not told apart). The map thread
        # may be writing a frame meanwhile: the page shows a cell a frame late.
        grid = parts.cameras.grid
        centres = grid.centres(OCCUPIED)
        colours = np.tile(np.array([CELLS], dtype=np.uint8), (len(centres), 1))
        if unknown:
            points = grid.centres(UNKNOWN)
            centres = np.vstack([centres, points])
            colours = np.vstack(
                [colours, np.full((len(points), 3), 150, dtype=np.uint8)]
            )
        if len(centres) > MAX_CELLS:
            nearest = np.argsort(np.linalg.norm(centres - hand, axis=1))[:MAX_CELLS]
            centres, colours = centres[nearest], colours[nearest]
        cell = grid.cell
        self._cells = self.server.scene.add_point_cloud(
            "/map", centres.astype(np.float32), colours, point_size=cell
        )
