# SPDX-License-Identifier: Apache-2.0
"""The teleoperation page of a :class:`~cbp.teleop.TeleopSession`, served by viser.

The scene: the robot's collision meshes at the measured configuration, the
declared objects, with cameras the map's occupied cells (and, on a toggle,
the unknown cells near the robot), and the goal as a 6-DOF gizmo the operator
drags. The panel: the method (switched at the next command period), pause and
stop, jog buttons for the goal (translate or rotate by a step, in the world's
or the hand's axes) and a reset, a readout (time, method, steps per period,
deadline misses, goal error, contact force, the latest events) and a live plot
of goal error and contact force over the last seconds.

Every browser connected sees the same session; the last goal sent wins. A
browser that disconnects leaves the goal where it was.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from cbp.errors import CbpError, ConfigError
from cbp.perception.kernels import OCCUPIED, UNKNOWN
from cbp.report import scene_description
from cbp.state import RobotState
from cbp.teleop import (
    METHODS,
    InputSession,
    Snapshot,
    TeleopSession,
    latency_summary,
)
from cbp.viewer import draw_objects, wxyz

__all__ = ["InputsPage", "TeleopPage", "serve_teleop"]

log = logging.getLogger(__name__)

#: Page updates per second.
UPDATE_RATE = 20.0
#: The map's cells are redrawn this often [s].
MAP_PERIOD = 0.5
#: Seconds of history in the live plot.
PLOT_SECONDS = 10.0
#: Length of a contact's normal as drawn [m].
CONTACT_ARROW = 0.04
#: The goal counts as out of reach when the commanded trajectory ends this far
#: from it [m]: the gripper and the reachable posture are drawn.
UNREACHABLE = 0.02
#: ... and has stayed there this long [s of simulated time].
STALLED_FOR = 0.5
#: Cells drawn at most (the nearest to the hand first).
MAX_CELLS = 60_000

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

_JOGS = [
    ("+x", "x", 1.0),
    ("-x", "x", -1.0),
    ("+y", "y", 1.0),
    ("-y", "y", -1.0),
    ("+z", "z", 1.0),
    ("-z", "z", -1.0),
]
_TURNS = [
    ("+roll", "rx", 1.0),
    ("-roll", "rx", -1.0),
    ("+pitch", "ry", 1.0),
    ("-pitch", "ry", -1.0),
    ("+yaw", "rz", 1.0),
    ("-yaw", "rz", -1.0),
]


class _Page:
    """What both pages share: the server, its address, and an update loop.

    Subclasses build the scene and the panel and define :meth:`update` and
    :attr:`session` (whose ``running`` ends the loop).
    """

    session: Any

    def __init__(self, host: str, port: int) -> None:
        """Start serving (the scene is built by the subclass)."""
        import viser

        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        #: Set by the page's "stop and save" button.
        self.stopped = threading.Event()
        self._close = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The page's address."""
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def update(self) -> None:
        """Bring the page up to date with the session."""
        raise NotImplementedError

    def run(self) -> None:
        """Update the page until :meth:`close`, the stop button or the session's end."""
        period = 1.0 / UPDATE_RATE
        due = time.perf_counter()
        failing: str | None = None
        while not self._close.is_set() and not self.stopped.is_set():
            try:
                self.update()
            except Exception as exc:  # the page must not stop the session
                message = f"{type(exc).__name__}: {exc}"
                if message != failing:
                    log.warning("page update failed: %s", message)
                failing = message
            else:
                failing = None
            if not self.session.running:
                break
            # On a fixed schedule; an update that ran late is not made up.
            due = max(due + period, time.perf_counter() - period)
            self._close.wait(max(0.0, due - time.perf_counter()))

    def start(self) -> None:
        """Update the page in a thread of its own."""
        self._thread = threading.Thread(target=self.run, name="page", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop updating and serving."""
        self._close.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.server.stop()


class TeleopPage(_Page):
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
        from viser.extras import ViserUrdf

        self.session = session
        super().__init__(host, port)
        description = scene_description(session.scenario, duration=0.0)
        urdf = description.get("urdf")
        self._locked = description.get("locked_joints", {})
        self.robot = (
            ViserUrdf(
                self.server,
                Path(urdf),
                root_node_name="/robot",
                load_meshes=False,
                load_collision_meshes=True,
                collision_mesh_color_override=(0.12, 0.47, 0.71),
            )
            if urdf is not None
            else None
        )
        self._joints = self.robot.get_actuated_joint_names() if self.robot else []
        self._q_names = session.scenario.robot.coordinate_names("q")
        draw_objects(self.server, description)
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
        self._history: deque[tuple[float, float, float]] = deque()
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
        # transparent robot at the end of the commanded trajectory, and the
        # goal drawn as a gripper (the CAT paper's operator view).
        self.ghost = (
            ViserUrdf(
                self.server,
                Path(urdf),
                root_node_name="/reachable",
                load_meshes=False,
                load_collision_meshes=True,
                collision_mesh_color_override=(0.6, 0.6, 0.6, 0.35),
            )
            if urdf is not None
            else None
        )
        self._gripper = _add_gripper(self.server, "/goal/gripper")
        self._state = RobotState(session.scenario.robot)
        self._hand = session.scenario.robot.frame_id(session.scenario.ee_frame)
        self._drawn_path: object = None
        self._drawn_contacts: object = False  # nothing drawn yet
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
            self.gizmo.position = tuple(position)
            self.gizmo.wxyz = wxyz(rotation)

    # ------------------------------------------------------------------ output

    def update(self) -> None:
        """Bring the page up to date with the session (called at UPDATE_RATE)."""
        session = self.session
        snap = session.snapshot()
        if self.robot is not None:
            self.robot.update_cfg(self._cfg(snap.q))
        if session.goal.count != self._shown_goal:  # sent from elsewhere
            self._after_goal(session.goal.count)
        goal, _ = session.goal.pose()
        error = float(np.linalg.norm(goal - snap.hand))
        self._draw_contacts(snap)
        self._draw_path(snap, goal)
        self._history.append((snap.t, 1e3 * error, snap.contact_force))
        while self._history and self._history[0][0] < snap.t - PLOT_SECONDS:
            self._history.popleft()
        lines = [
            f"**t = {snap.t:.2f} s**, method **{snap.method}**"
            + (" (paused)" if snap.paused else ""),
            "",
            f"- goal error: {error * 1e3:.0f} mm",
            f"- contact force: {snap.contact_force:.1f} N",
            f"- clearance (CAT's nearest contact): {_clearance(snap)}",
            f"- steps in the last period: {snap.steps}",
            f"- deadline misses: {snap.misses}",
        ]
        if snap.events:
            lines += ["", "latest events:"]
            lines += [f"- {t:.2f} s: {message}" for t, message in snap.events]
        self.readout.content = "\n".join(lines)
        if len(self._history) > 1:
            data = np.array(self._history).T
            self.plot.data = (data[0], data[1], data[2])
        self._draw_map(snap.t, snap.hand)

    def _cfg(self, q: np.ndarray) -> np.ndarray:
        """The URDF's actuated joints' values for the robot's configuration."""
        by_name = dict(zip(self._q_names, q, strict=True))
        return np.array(
            [by_name.get(j, self._locked.get(j, 0.0)) for j in self._joints]
        )

    def _draw_contacts(self, snap: Snapshot) -> None:
        """CAT's contacts: a normal at each robot witness point, by distance.

        Red at contact or closer, through yellow, to green at the safety
        distance's 5 cm and beyond.
        """
        contacts = snap.contacts
        if contacts is self._drawn_contacts:
            return
        self._drawn_contacts = contacts
        if contacts is None or not len(contacts.distance):
            points = np.zeros((0, 2, 3))
            colours = np.zeros((0, 2, 3))
        else:
            start = contacts.point
            points = np.stack([start, start + CONTACT_ARROW * contacts.normal], axis=1)
            closeness = np.clip(1.0 - contacts.distance / 0.05, 0.0, 1.0)
            rgb = np.stack(
                [closeness, 1.0 - 0.5 * closeness, np.zeros_like(closeness)], axis=1
            )
            colours = np.repeat(rgb[:, None, :], 2, axis=1)
        self.server.scene.add_line_segments(
            "/contacts", points, colours, thickness=3.0, thickness_units="screen"
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
            self.server.scene.add_line_segments(
                "/commanded",
                segments,
                (20, 20, 20),
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

    def _draw_map(self, t: float, hand: np.ndarray) -> None:
        """Redraw the map's cells when the map or the toggle changed."""
        run = self.session.run
        world = run.world
        if run.mapper is None or world is None:
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
        grid = run.mapper.grid
        centres = grid.centres(OCCUPIED)
        colours = np.tile(np.array([[200, 90, 40]], dtype=np.uint8), (len(centres), 1))
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


def serve_teleop(
    scenarios: list[Path],
    method: str,
    host: str,
    port: int,
    out: Path | None,
    overrides: dict[str, str],
) -> int:
    """``cbp teleop``: serve the session until the page's stop or Ctrl-C.

    One scenario of a trajectory executor: a goal session
    (:class:`TeleopPage`). Velocity-executor scenarios (one or several
    configurations of one robot, switched on the page): an input session
    (:class:`InputsPage`). Then the outputs are written. Exit 2 for a scenario
    or method that cannot start (nothing runs).
    """
    from cbp.files import check_output_folder
    from cbp.scenario import load_scenario

    page: TeleopPage | InputsPage
    try:
        first = load_scenario(scenarios[0])
        velocity = first.spec.method.name == "velocity"
        if not velocity and len(scenarios) > 1:
            raise ConfigError(
                "several scenarios are configurations of the velocity executor "
                "to switch between; a goal session takes one"
            )
        out = out or Path("out") / f"{first.spec.name}_teleop"
        check_output_folder(out)
        if velocity:
            inputs = InputSession(scenarios, overrides)
            page = InputsPage(inputs, host=host, port=port)
            inputs.start()
        else:
            session = TeleopSession(scenarios[0], method, overrides)
            page = TeleopPage(session, host=host, port=port)
            session.start()
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    print(f"teleoperation of {scenarios[0]}: {page.url} (stop on the page or Ctrl-C)")
    try:
        with contextlib.suppress(KeyboardInterrupt):
            page.run()
    finally:
        page.close()
    if velocity:
        inputs.write(inputs.stop(), out)
        print(f"wrote {out}")
        return 0
    session.stop()
    goal_file = session.write(out)
    latency = latency_summary(session.latency_ms())
    print(
        f"wrote {out}; the operator's goals: {goal_file} "
        f"(replay: cbp compare {scenarios[0]} --goal {goal_file})"
    )
    if latency["n"]:
        print(
            f"goal-to-command latency: median {latency['median_ms']:.1f} ms, "
            f"p95 {latency['p95_ms']:.1f} ms over {latency['n']} goals"
        )
    return 0


class InputsPage(_Page):
    """The page of an :class:`~cbp.teleop.InputSession` (orbit and pan object).

    The robot (its base placed from the planar joint), the declared objects, a
    dropdown of the configurations, a slider per input value (camera-frame
    velocities, desired distance: from 0 to twice a positive starting value,
    else within +-0.2), stop and save, and a readout of the active
    configuration's signals and the latest events.
    """

    def __init__(
        self, session: InputSession, host: str = "127.0.0.1", port: int = 8080
    ) -> None:
        """Build the scene and the panel."""
        from viser.extras import ViserUrdf

        self.session = session
        super().__init__(host, port)
        scenario = session.scenarios[0]
        description = scene_description(scenario, duration=0.0)
        draw_objects(self.server, description)
        self.base = self.server.scene.add_frame("/robot", show_axes=False)
        self.robot = ViserUrdf(
            self.server,
            Path(description["urdf"]),
            root_node_name="/robot",
            load_meshes=False,
            load_collision_meshes=True,
            collision_mesh_color_override=(0.95, 0.6, 0.1),
        )
        self._joints = self.robot.get_actuated_joint_names()
        self._q_names = scenario.robot.coordinate_names("q")
        camera = self.server.initial_camera
        camera.position = (-1.0, -2.5, 2.0)
        camera.look_at = (0.6, 0.0, 0.3)
        gui = self.server.gui
        self.config = gui.add_dropdown(
            "configuration", tuple(session.loops), initial_value=session.active
        )
        self.config.on_update(lambda _: self._switch())
        self.stop_button = gui.add_button("stop and save")
        self.stop_button.on_click(lambda _: self.stopped.set())
        self.sliders: dict[str, dict[str, list[Any]]] = {}
        self.folders: dict[str, Any] = {}
        for config, inputs in session.inputs.items():
            folder = gui.add_folder(f"{config} inputs")
            self.folders[config] = folder
            self.sliders[config] = {}
            with folder:
                for entry, values in inputs.items():
                    handles = []
                    for i, value in enumerate(values):
                        top = 2.0 * value if value > 0 else 0.2
                        bottom = 0.0 if value > 0 else -0.2
                        slider = gui.add_slider(
                            f"{entry}[{i}]",
                            min=bottom,
                            max=top,
                            step=(top - bottom) / 200,
                            initial_value=float(value),
                        )
                        slider.on_update(self._setter(config, entry))
                        handles.append(slider)
                    self.sliders[config][entry] = handles
            folder.visible = config == session.active
        self.readout = gui.add_markdown("")

    def _setter(self, config: str, entry: str) -> Any:
        """A slider handler that sends every value of ``entry`` of ``config``."""

        def send(_: Any) -> None:
            values = [s.value for s in self.sliders[config][entry]]
            self.session.set_input(entry, np.array(values), config)

        return send

    def _switch(self) -> None:
        self.session.switch(self.config.value)
        for config, folder in self.folders.items():
            folder.visible = config == self.config.value

    def update(self) -> None:
        """Bring the page up to date with the session."""
        snap = self.session.snapshot()
        q = snap["q"]
        by_name = dict(zip(self._q_names, q, strict=True))
        # The planar base: x, y, cos(yaw), sin(yaw).
        yaw = math.atan2(q[3], q[2])
        self.base.position = (float(q[0]), float(q[1]), 0.0)
        self.base.wxyz = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        self.robot.update_cfg(np.array([by_name.get(j, 0.0) for j in self._joints]))
        lines = [f"**t = {snap['t']:.2f} s**, configuration **{snap['active']}**", ""]
        lines += [f"- {k}: {v:.3f}" for k, v in sorted(snap["signals"].items())]
        if snap["events"]:
            lines += ["", "latest events:"]
            lines += [f"- {t:.2f} s: {m}" for t, m in snap["events"]]
        self.readout.content = "\n".join(lines)


def _clearance(snap: Snapshot) -> str:
    """The distance of the nearest contact CAT holds, as text; "-" without one."""
    contacts = snap.contacts
    if contacts is None or not len(contacts.distance):
        return "-"
    nearest = round(1e3 * float(np.min(contacts.distance)), 1) + 0.0  # no -0.0
    return f"{nearest:.1f} mm"


def _add_gripper(server: Any, name: str) -> Any:
    """A two-finger gripper of boxes under frame ``name`` (opening along y, z out)."""
    frame = server.scene.add_frame(name, show_axes=False, visible=False)
    colour = (200, 60, 60)
    server.scene.add_box(
        f"{name}/palm", colour, (0.02, 0.16, 0.03), position=(0.0, 0.0, -0.04)
    )
    for side in (-1, 1):
        server.scene.add_box(
            f"{name}/finger{side}",
            colour,
            (0.015, 0.015, 0.05),
            position=(0.0, 0.06 * side, 0.0),
        )
    return frame
