# SPDX-License-Identifier: Apache-2.0
"""The page of a goal session (:class:`~cbp.teleop.TeleopSession`), served by viser.

The scene: the robot's collision meshes at the measured configuration, the
declared objects, with cameras the map's occupied cells (and, on a toggle,
the unknown cells near the robot), and the goal as a 6-DOF gizmo the operator
drags. The panel: the method (switched at the next command period), pause and
stop, jog buttons for the goal (translate or rotate by a step, in the world's
or the hand's axes) and a reset, a readout (time, method, steps per period,
deadline misses, goal error, contact force, the latest events) and a live plot
of goal error and contact force over the last seconds (in a folder, folded to
start with: in a browser without a GPU it cost a quarter of each frame).

Why the arm holds is drawn and said: a red arrow at each contact that holds
the arm, pointing along the direction it may not move (toward the obstacle);
a goal the arm stops short of drawn as a magenta gripper and the closest
posture the arm reaches as an orange wireframe, both labelled through
obstacles, which turn translucent meanwhile (an x-ray); a legend; and the
reason (:func:`cbp.teleop.hold.hold_reason`) at the top of the readout for as
long as the arm holds.

Every browser connected sees the same session; the last goal sent wins. A
browser that disconnects leaves the goal where it was.
"""

from __future__ import annotations

import json
import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from cbp.drawing import (
    RobotPose,
    add_gripper,
    add_robot,
    draw_objects,
    joint_values,
    wxyz,
)
from cbp.executors.cat import HOLDING_DISTANCE
from cbp.perception.kernels import OCCUPIED, UNKNOWN
from cbp.run.goal_input import GoalBounds
from cbp.scene_file import scene_description
from cbp.state import RobotState
from cbp.teleop.goal_session import METHODS, Snapshot, TeleopSession
from cbp.teleop.hold import GoalSpace, Hold, HoldFacts, hold_reason
from cbp.teleop.page import Page
from cbp.teleop.readout import (
    ARM,
    BLOCKED,
    CELLS,
    CLOSEST_POSTURE,
    GOAL_GRIPPER,
    LEGEND,
    PATH,
    UNREACHABLE,
    legend_html,
    readout_lines,
)

__all__ = ["GoalPageState", "TeleopPage"]

#: The map's cells are redrawn this often [s].
MAP_PERIOD = 0.5
#: Seconds of history in the live plot.
PLOT_SECONDS = 10.0
#: Length of a contact's normal as drawn [m].
CONTACT_ARROW = 0.04
#: ... and has stayed there this long [s of simulated time].
STALLED_FOR = 0.5
#: Cells drawn at most (the nearest to the hand first).
MAX_CELLS = 60_000
#: The readout and the plot are redrawn at most this often [s of wall time].
PANEL_PERIOD = 0.2
#: Length of a blocked direction's arrow as drawn [m].
BLOCKED_ARROW = 0.06
#: Opacity of the declared objects while the arm holds short of the goal
#: (an x-ray: the gripper and the closest posture inside them stay visible).
XRAY_OPACITY = 0.3

#: Keyboard shortcuts: key -> the label of the button it presses.
KEYS = {
    "w": "+x",
    "s": "-x",
    "a": "+y",
    "d": "-y",
    "r": "+z",
    "f": "-z",
    "i": "+roll",
    "k": "-roll",
    "j": "+pitch",
    "l": "-pitch",
    "u": "+yaw",
    "o": "-yaw",
}

# viser 1.1.1 sends no keyboard events to Python. Its HTML element renders
# markup in the page, where an image's error handler runs: it installs (once)
# a listener that presses the button a key names, outside text fields.
_KEYS_HTML = (
    '<div style="font-size: 0.8em">keys: '
    + ", ".join(f"{k} {v}" for k, v in KEYS.items())
    + '</div><img src="" style="display:none" onerror="'
    + "if(!window.cbpKeys){window.cbpKeys=1;"
    + "const m="
    + json.dumps(KEYS).replace('"', "&quot;")
    + ";"
    + "document.addEventListener('keydown',function(e){"
    + "const t=e.target.tagName;"
    + "if(t==='INPUT'||t==='TEXTAREA'||e.ctrlKey||e.metaKey)return;"
    + "const l=m[e.key.toLowerCase()];if(!l)return;"
    + "for(const b of document.querySelectorAll('button')){"
    + "if(b.textContent.trim()===l){b.click();e.preventDefault();break;}}});}"
    + '">'
)


#: Lines drawn (and a robot's joints) that differ by less than this from those
#: on the page are not sent again: each change costs the browser a frame
#: [m, colour 0-1, rad].
DRAWN_TOLERANCE = 2e-4


def _same(drawn: np.ndarray, new: np.ndarray) -> bool:
    """Whether ``new`` would look like ``drawn`` (same shape, within tolerance)."""
    return drawn.shape == new.shape and bool(
        np.allclose(drawn, new, rtol=0.0, atol=DRAWN_TOLERANCE)
    )


def _both_ways(axes: list[tuple[str, str]]) -> list[tuple[str, str, float]]:
    """Jog buttons (label, axis, sign) for each (name, axis): + then -."""
    return [
        (f"{s}{name}", axis, sign)
        for name, axis in axes
        for s, sign in (("+", 1.0), ("-", -1.0))
    ]


_JOGS = _both_ways([("x", "x"), ("y", "y"), ("z", "z")])
_TURNS = _both_ways([("roll", "rx"), ("pitch", "ry"), ("yaw", "rz")])


@dataclass(frozen=True)
class GoalPageState:
    """What the goal page shows, as a record tests and tools can read.

    Attributes:
        robot_q: the configuration the robot is drawn at (URDF actuated
            joints, in the URDF's order), or None without a URDF or before
            the robot is first drawn.
        goal_position: where the goal's gizmo is (3,) [m].
        unreachable: the goal is drawn out of reach (a gripper, with the
            posture the arm stopped in).
        gripper_visible: whether the goal's gripper is shown.
        ghost_visible: whether the reachable posture is shown.
        map_cells: cells of the map drawn (0 without cameras).
        readout: the readout's text.
        hold: why the arm holds (:func:`cbp.teleop.hold.hold_reason`), or None
            while it follows the goal.
        hold_since: since when it holds for that reason [s of session time].
        blocked_arrows: blocked-direction arrows drawn (one per contact that
            holds the arm).
        xray: whether the declared objects are drawn translucent.
        legend: the legend's entries, as the page lists them.
    """

    robot_q: np.ndarray | None
    goal_position: np.ndarray
    unreachable: bool
    gripper_visible: bool
    ghost_visible: bool
    map_cells: int
    readout: str
    hold: Hold | None = None
    hold_since: float | None = None
    blocked_arrows: int = 0
    xray: bool = False
    legend: tuple[str, ...] = ()


class TeleopPage(Page[TeleopSession]):
    """Serve ``session`` in the browser.

    Args:
        session: the session (started or not).
        host: where to serve (localhost unless asked otherwise).
        port: the port (0: any free one).
    """

    def __init__(
        self, session: TeleopSession, host: str = "127.0.0.1", port: int = 8080
    ) -> None:
        """Build the scene and the panel."""
        import viser
        import viser.uplot

        super().__init__(session, host, port)
        description = scene_description(session.scenario, duration=0.0)
        urdf = description.get("urdf")
        self._locked = description.get("locked_joints", {})
        self.robot = (
            add_robot(self.server, urdf, "/robot", ARM) if urdf is not None else None
        )
        self._joints = self.robot.get_actuated_joint_names() if self.robot else []
        #: Sends the robot's joints that moved (its drawn values: ``.drawn``).
        self.robot_pose = (
            RobotPose(self.robot, DRAWN_TOLERANCE) if self.robot is not None else None
        )
        #: The robot's pose last sent: (simulated time [s], the hand's
        #: position (3,) [m]), None before the first.
        self.posed: tuple[float, np.ndarray] | None = None
        self._q_names = session.scenario.robot.coordinate_names("q")
        self._objects = draw_objects(self.server, description)
        camera = self.server.initial_camera
        camera.position = (1.9, -1.4, 1.3)
        camera.look_at = (0.4, 0.0, 0.3)
        position, rotation = session.goal.pose()
        self.gizmo = self.server.scene.add_transform_controls(
            "/goal", scale=0.15, position=tuple(position), wxyz=wxyz(rotation)
        )
        self._shown_goal = session.goal.count
        self.gizmo.on_update(lambda _: self._gizmo_moved())
        gui = self.server.gui
        self.method = gui.add_dropdown(
            "method", METHODS, initial_value=session.planner.method
        )
        self.method.on_update(lambda _: session.switch(self.method.value))
        self.paused = gui.add_checkbox("pause", initial_value=False)
        self.paused.on_update(lambda _: session.pause(self.paused.value))
        self.stop_button = gui.add_button("stop and save")
        self.stop_button.on_click(lambda _: self.stopped.set())
        with gui.add_folder("jog the goal"):
            self.frame = gui.add_dropdown(
                "axes", ("world", "hand"), initial_value="world"
            )
            self.step = gui.add_slider(
                "step [m]", min=0.005, max=0.1, step=0.005, initial_value=0.02
            )
            self.turn = gui.add_slider(
                "turn [deg]", min=1.0, max=45.0, step=1.0, initial_value=10.0
            )
            self.jog_buttons: dict[str, Any] = {}
            for label, axis, sign in _JOGS + _TURNS:
                button = gui.add_button(label)
                button.on_click(self._jogger(axis, sign))
                self.jog_buttons[label] = button
            gui.add_html(_KEYS_HTML)
            reset = gui.add_button("reset goal")
            reset.on_click(lambda _: self._after_goal(session.reset()))
        self.show_unknown = gui.add_checkbox("show unknown space", initial_value=False)
        self.readout = gui.add_markdown("")
        self.legend = gui.add_html(legend_html())
        self.add_render_toggle()
        self._history: deque[tuple[float, float, float]] = deque()
        # Folded to start with: in headless Chromium without a GPU the live
        # plot cost about a quarter of the browser's work per frame of the
        # page (benchmarks/RESULTS.md); a click on the folder shows it.
        with gui.add_folder("plot", expand_by_default=False):
            self.plot = gui.add_uplot(
                data=(np.zeros(1), np.zeros(1), np.zeros(1)),
                series=(
                    viser.uplot.Series(label="t [s]"),
                    viser.uplot.Series(label="goal error [mm]", stroke="blue", width=2),
                    viser.uplot.Series(label="contact [N]", stroke="red", width=2),
                ),
                title="goal error and contact force",
                aspect=2.0,
                scales={"x": viser.uplot.Scale(time=False)},
            )
        self._cells: Any = None
        # Where the arm is heading when the goal is out of its reach: a
        # wireframe robot at the end of the commanded trajectory, and the
        # goal drawn as a gripper (the CAT paper's operator view), each with
        # a label drawn through obstacles.
        self.ghost = (
            add_robot(self.server, urdf, "/reachable", CLOSEST_POSTURE)
            if urdf is not None
            else None
        )
        # viser 1.1.1's ViserUrdf takes no wireframe option: its meshes are
        # switched to wireframe here (a ghost that would cover the arm
        # otherwise; the arm's own posture stays readable through it).
        for mesh in getattr(self.ghost, "_meshes", []):
            mesh.wireframe = True
        self._gripper = add_gripper(self.server, "/goal/gripper", GOAL_GRIPPER)
        self.server.scene.add_label("/goal/gripper/label", "goal (out of reach)")
        self._ghost_label = self.server.scene.add_label(
            "/closest_label", "closest posture", visible=False
        )
        self._arrows: Any = None
        self._arrow_count = 0
        self._xray = False
        self._bounds = GoalBounds.of(session.scenario)
        self._space: tuple[object, tuple[float, ...], GoalSpace] = (None, (), "free")
        #: The session's snapshot the page last drew (None before the first).
        self.shown: Snapshot | None = None
        self._panel_at = -math.inf
        #: Why the arm holds (None while it follows the goal), and since when.
        self.hold: Hold | None = None
        self._hold_since: float | None = None
        self._state = RobotState(session.scenario.robot)
        self._hand = session.scenario.robot.frame_id(session.scenario.ee_frame)
        self._drawn_path: object = None
        self._drawn_contacts: object = False  # nothing drawn yet
        #: The contacts' lines and holding flags as last sent.
        self._contact_lines: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        #: The commanded path's segments as last sent.
        self._path_lines: np.ndarray | None = None
        #: Whether the arm has stopped short of the goal (drawn as a gripper,
        #: with the posture it stopped in).
        self.unreachable = False
        self._short_since: float | None = None
        if self.ghost is not None:
            self.ghost.show_collision = False
        self._map_drawn: tuple[object, bool, float] = (None, False, -math.inf)

    # ------------------------------------------------------------------ input

    def _gizmo_moved(self) -> None:
        wxyz = np.asarray(self.gizmo.wxyz, dtype=float)
        import pinocchio as pin

        rotation = pin.Quaternion(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).matrix()
        self._shown_goal = self.session.set_goal(
            np.asarray(self.gizmo.position, dtype=float), rotation
        )

    def _jogger(self, axis: str, sign: float) -> Any:
        """A click handler that jogs ``axis`` by a step in direction ``sign``."""
        return lambda _: self._jog(axis, sign)

    def _jog(self, axis: str, sign: float) -> None:
        step = np.deg2rad(self.turn.value) if axis.startswith("r") else self.step.value
        self._after_goal(self.session.jog(axis, sign * step, self.frame.value))

    def _after_goal(self, number: int) -> None:
        """Put the gizmo where the goal now is (a jog, a reset or a script moved it)."""
        position, rotation = self.session.goal.pose()
        self._shown_goal = number
        if np.isfinite(position).all() and np.isfinite(rotation).all():
            with self.server.atomic():
                self.gizmo.position = tuple(position)
                self.gizmo.wxyz = wxyz(rotation)
            self.server.flush()  # the moved goal shown now, not at a window's end

    # ------------------------------------------------------------------ output

    def update_first(self) -> bool:
        """The robot's measured pose when it moved: sent first, at each change.

        A pose the simulation reached ahead of the wall clock (by at most a
        command lead) is not sent before its time: the page shows the
        robot's state, never one it has yet to reach. It goes at a later
        change (at the latest the period's end, when the loop has waited
        for the wall clock to reach it).
        """
        return self._pose_robot()

    def _pose_robot(self) -> bool:
        """Send the joints that moved, once their time has come; whether any."""
        if self.robot_pose is None:
            return False
        t, q, due = self.session.measured()
        values = self._cfg(q)
        if due > 0 or not self.robot_pose.moved(values):
            return False
        self.robot_pose.pose(values)
        self._state.update(q)
        self.posed = (t, self._state.frame_position(self._hand).copy())
        return True

    def update(self) -> None:
        """Bring the page up to date with the session (at each of its changes).

        The robot (unless :meth:`update_first` sent it), the goal, the
        contacts and the path at every update; the readout and the plot every
        :data:`PANEL_PERIOD`, or at once when the hold changes (each redraw
        of them costs the browser a render of the panel, on the cores the
        control loop runs on).
        """
        session = self.session
        snap = session.snapshot()
        self._pose_robot()
        if session.goal.count != self._shown_goal:  # sent from elsewhere
            self._after_goal(session.goal.count)
        goal, _ = session.goal.pose()
        error = float(np.linalg.norm(goal - snap.hand))
        self._draw_contacts(snap)
        self._draw_path(snap, goal)
        hold = self.hold
        self._update_hold(snap, goal)
        self._history.append((snap.t, 1e3 * error, snap.contact_force))
        while self._history and self._history[0][0] < snap.t - PLOT_SECONDS:
            self._history.popleft()
        now = time.monotonic()
        if now >= self._panel_at + PANEL_PERIOD or hold != self.hold:
            self._panel_at = now
            self.readout.content = "\n".join(
                readout_lines(snap, error, self.hold, self._hold_since)
            )
            if len(self._history) > 1:
                data = np.array(self._history).T
                self.plot.data = (data[0], data[1], data[2])
        self._draw_map(snap.t, snap.hand)
        self.shown = snap

    def state(self) -> GoalPageState:
        """What the page shows now."""
        return GoalPageState(
            robot_q=(
                None
                if self.robot_pose is None or self.robot_pose.drawn is None
                else np.array(self.robot_pose.drawn, dtype=float)
            ),
            goal_position=np.array(self.gizmo.position, dtype=float),
            unreachable=self.unreachable,
            gripper_visible=bool(self._gripper.visible),
            ghost_visible=self.ghost is not None and bool(self.ghost.show_collision),
            map_cells=0 if self._cells is None else len(self._cells.points),
            readout=str(self.readout.content),
            hold=self.hold,
            hold_since=self._hold_since,
            blocked_arrows=self._arrow_count,
            xray=self._xray,
            legend=tuple(text for _, text in LEGEND),
        )

    def _update_hold(self, snap: Snapshot, goal: np.ndarray) -> None:
        """Why the arm holds; the objects turn translucent while it stops short."""
        bounded, clamped = self._bounds.clamp(goal)
        facts = HoldFacts(
            paused=snap.paused,
            short=self.unreachable,
            goal_space=self._goal_space(bounded),
            clamped=clamped,
            held_by=snap.held_by,
            note=snap.note,
            recent_misses=snap.recent_misses,
            method=snap.method,
        )
        hold = hold_reason(facts)
        if hold is None:
            self._hold_since = None
        elif self.hold is None or hold.kind != self.hold.kind:
            self._hold_since = snap.t
        self.hold = hold
        xray = self.unreachable
        if xray != self._xray:
            self._xray = xray
            for handle in self._objects.values():
                if hasattr(handle, "opacity"):  # boxes, spheres, cylinders
                    handle.opacity = XRAY_OPACITY if xray else None

    def _goal_space(self, position: np.ndarray) -> GoalSpace:
        """Whether ``position`` lies in open space, an obstacle or unseen space."""
        parts = self.session.parts
        world = parts.world
        if world is None:
            return "free"
        environment = world.environment
        key = tuple(float(v) for v in position)
        checked, checked_key, space = self._space
        if environment is checked and key == checked_key:
            return space
        point = np.asarray(position, dtype=float)[None]
        if bool(parts.unseen(point)[0]):
            space = "unseen"
        elif bool(environment.inside(point)[0]):
            space = "obstacle"
        else:
            space = "free"
        self._space = (environment, key, space)
        return space

    def _cfg(self, q: np.ndarray) -> np.ndarray:
        """The URDF's actuated joints' values for the robot's configuration."""
        values = dict(zip(self._q_names, (float(v) for v in q), strict=True))
        return joint_values(self._joints, values, self._locked)

    def _draw_contacts(self, snap: Snapshot) -> None:
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
            and _same(drawn[0], points)
            and _same(drawn[1], colours)
            and np.array_equal(drawn[2], holding)
        ):
            return  # as drawn: nothing sent (each change costs the browser a frame)
        self._contact_lines = (points, colours, holding)
        self.server.scene.add_line_segments(
            "/contacts", points, colours, thickness=3.0, thickness_units="screen"
        )
        self._arrow_count = int(holding.sum())
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

    def _draw_path(self, snap: Snapshot, goal: np.ndarray) -> None:
        """The commanded trajectory's hand path, and the reachable posture."""
        trajectory = snap.trajectory
        if trajectory is None:
            return
        if trajectory is not self._drawn_path:  # a new one was spliced in
            self._drawn_path = trajectory
            ahead = int(np.searchsorted(trajectory.times, snap.t))
            path = (
                trajectory.positions[ahead:]
                if ahead < len(trajectory.times)
                else trajectory.positions[-1:]
            )
            keep = np.unique(
                np.linspace(0, len(path) - 1, min(len(path), 60)).astype(int)
            )
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
            if self._path_lines is None or not _same(self._path_lines, segments):
                self._path_lines = segments
                self.server.scene.add_line_segments(
                    "/commanded",
                    segments,
                    PATH,
                    thickness=2.0,
                    thickness_units="screen",
                )
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
        self._gripper.visible = unreachable
        if self.ghost is not None:
            if unreachable:
                self.ghost.update_cfg(self._cfg(end))
            self.ghost.show_collision = unreachable
        if unreachable:
            self._ghost_label.position = tuple(heading)
        self._ghost_label.visible = unreachable

    def _draw_map(self, t: float, hand: np.ndarray) -> None:
        """Redraw the map's cells when the map or the toggle changed."""
        parts = self.session.parts
        world = parts.world
        if parts.cameras is None or world is None:
            return
        environment = world.environment
        unknown = bool(self.show_unknown.value)
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
