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

from cbp.drawing import RobotPose, add_robot, joint_values, wxyz
from cbp.run.goal_input import GoalBounds
from cbp.scene_file import scene_description
from cbp.state import RobotState
from cbp.teleop.goal_scene import DRAWN_TOLERANCE, MAX_CELLS, GoalScene
from cbp.teleop.goal_session import METHODS, Snapshot, TeleopSession
from cbp.teleop.hold import GoalSpace, Hold, HoldFacts, hold_reason
from cbp.teleop.page import Page
from cbp.teleop.readout import ARM, LEGEND, legend_html, readout_lines

__all__ = ["MAX_CELLS", "GoalPageState", "TeleopPage"]

#: Seconds of history in the live plot.
PLOT_SECONDS = 10.0
#: The readout and the plot are redrawn at most this often [s of wall time].
PANEL_PERIOD = 0.2

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

    Attributes:
        scene: what is drawn around the robot (:class:`GoalScene`).
    """

    def __init__(
        self, session: TeleopSession, host: str = "127.0.0.1", port: int = 8080
    ) -> None:
        """Build the scene and the panel."""
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
        camera = self.server.initial_camera
        camera.position = (1.9, -1.4, 1.3)
        camera.look_at = (0.4, 0.0, 0.3)
        position, rotation = session.goal.pose()
        self.gizmo = self.server.scene.add_transform_controls(
            "/goal", scale=0.15, position=tuple(position), wxyz=wxyz(rotation)
        )
        self._shown_goal = session.goal.count
        self.gizmo.on_update(lambda _: self._gizmo_moved())
        self._add_panel()
        self.scene = GoalScene(self.server, session, description, self._cfg)
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

    def _add_panel(self) -> None:
        """The method, pause and stop, the jog folder, the readout and the plot."""
        session, gui = self.session, self.server.gui
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
        self._add_plot()

    def _add_plot(self) -> None:
        """The live plot of goal error and contact force, in a folded folder."""
        import viser.uplot

        # Folded to start with: in headless Chromium without a GPU the live
        # plot cost about a quarter of the browser's work per frame of the
        # page (benchmarks/RESULTS.md); a click on the folder shows it.
        with self.server.gui.add_folder("plot", expand_by_default=False):
            self.plot = self.server.gui.add_uplot(
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
        self.scene.draw_contacts(snap)
        self.scene.draw_path(snap, goal)
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
        self.scene.draw_map(snap.t, snap.hand, bool(self.show_unknown.value))
        self.shown = snap

    def state(self) -> GoalPageState:
        """What the page shows now."""
        ghost = self.scene.ghost
        return GoalPageState(
            robot_q=(
                None
                if self.robot_pose is None or self.robot_pose.drawn is None
                else np.array(self.robot_pose.drawn, dtype=float)
            ),
            goal_position=np.array(self.gizmo.position, dtype=float),
            unreachable=self.scene.unreachable,
            gripper_visible=bool(self.scene.gripper.visible),
            ghost_visible=ghost is not None and bool(ghost.show_collision),
            map_cells=self.scene.cells,
            readout=str(self.readout.content),
            hold=self.hold,
            hold_since=self._hold_since,
            blocked_arrows=self.scene.blocked_arrows,
            xray=self.scene.xray,
            legend=tuple(text for _, text in LEGEND),
        )

    def _update_hold(self, snap: Snapshot, goal: np.ndarray) -> None:
        """Why the arm holds, and since when."""
        bounded, clamped = self._bounds.clamp(goal)
        facts = HoldFacts(
            paused=snap.paused,
            short=self.scene.unreachable,
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
