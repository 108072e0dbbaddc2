# SPDX-License-Identifier: Apache-2.0
"""``cbp view OUT_DIR``: replay finished runs in the browser.

A run's output folder (``cbp run``) or a comparison's (``cbp compare``: every
method, each robot in its own colour) is drawn with viser: the robot's
collision meshes from its URDF at each recorded configuration, the declared
objects, and the goal as a frame. A panel holds a timeline to scrub, play and
pause, the playback speed, and, following the cursor, each method's contact
force, goal error and clearance. ``--export FILE.viser`` writes the replay as
a recording that viser's static client plays without a Python process.

The folder must hold ``scene.json`` (written with every output since it was
introduced) and the traces (``trace.csv`` or ``trace_<method>.csv``).
"""

from __future__ import annotations

import contextlib
import csv
import json
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cbp.drawing import add_robot, draw_objects, joint_values
from cbp.errors import ConfigError
from cbp.methods import method_colour
from cbp.robot import FloatArray
from cbp.scene_file import read_scene

__all__ = ["Replay", "RunRecording", "load_recordings"]

#: The plots show this many seconds up to the cursor.
PLOT_WINDOW = 5.0
#: Points per plotted curve at most.
PLOT_POINTS = 400
#: Page updates per second while playing.
FRAME_RATE = 30.0


@dataclass
class RunRecording:
    """One method's trace, as read back from its CSV.

    Attributes:
        method: the method's name.
        t: sample times (M,) [s].
        q: joint positions by joint name, (M,) each.
        goal: goal position (M, 3) and quaternion (x, y, z, w) (M, 4).
        columns: every other column by name (contact_force, clearance, ...).
    """

    method: str
    t: FloatArray
    q: dict[str, FloatArray]
    goal: tuple[FloatArray, FloatArray]
    columns: dict[str, FloatArray]

    def index(self, t: float) -> int:
        """The last sample at or before ``t``."""
        return max(0, int(np.searchsorted(self.t, t, side="right")) - 1)


def load_recordings(out: Path) -> tuple[dict[str, Any], list[RunRecording]]:
    """The scene description and every method's recording in ``out``.

    Raises:
        ConfigError: not an output folder, or one written before scene.json.
    """
    metrics_path = out / "metrics.json"
    if not metrics_path.is_file():
        raise ConfigError(f"{out} is not a cbp output folder (no metrics.json)")
    scene = read_scene(out)
    methods = list(json.loads(metrics_path.read_text()))
    recordings = []
    for method in methods:
        path = out / ("trace.csv" if len(methods) == 1 else f"trace_{method}.csv")
        recordings.append(_read_trace(method, path))
    return scene, recordings


def _read_trace(method: str, path: Path) -> RunRecording:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, data = rows[0], np.array(rows[1:], dtype=float).reshape(-1, len(rows[0]))
    column = {name: data[:, i] for i, name in enumerate(header)}
    q = {
        name[2:]: values
        for name, values in column.items()
        if name.startswith("q_") and not name.startswith("q_cmd_")
    }
    goal = (
        np.column_stack([column[f"goal_{c}"] for c in "xyz"]),
        np.column_stack([column[f"goal_{c}"] for c in ("qx", "qy", "qz", "qw")]),
    )
    return RunRecording(method, column["t"], q, goal, column)


class Replay:
    """The replay page of an output folder, served by viser.

    Args:
        out: the output folder.
        host: where to serve.
        port: the port (0: any free one).
    """

    def __init__(self, out: Path, host: str = "127.0.0.1", port: int = 8080) -> None:
        """Load the recordings and build the scene and the panel."""
        import viser

        self.scene, self.recordings = load_recordings(out)
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.duration = max(float(r.t[-1]) for r in self.recordings)
        urdf = self.scene.get("urdf")
        if urdf is None:
            raise ConfigError("the run's robot has no URDF to draw")
        self._robots = []
        for recording in self.recordings:
            colour = method_colour(recording.method)
            robot = add_robot(self.server, urdf, f"/{recording.method}", colour)
            self._robots.append((recording, robot, robot.get_actuated_joint_names()))
        self._objects = draw_objects(self.server, self.scene)
        self.server.initial_camera.position = (1.9, -1.4, 1.3)
        self.server.initial_camera.look_at = (0.4, 0.0, 0.3)
        self._tracks = {
            name: np.array(rows, dtype=float)
            for name, rows in self.scene.get("tracks", {}).items()
            if name in self._objects and rows
        }
        self._goal = self.server.scene.add_frame(
            "/goal", axes_length=0.08, axes_radius=0.004
        )
        gui = self.server.gui
        self.time = gui.add_slider(
            "time [s]", min=0.0, max=self.duration, step=0.005, initial_value=0.0
        )
        self.playing = gui.add_checkbox("play", initial_value=False)
        self.speed = gui.add_slider(
            "speed", min=0.1, max=4.0, step=0.1, initial_value=1.0
        )
        self.readout = gui.add_markdown("")
        import viser.uplot

        self.plots = {}
        for column, title in (
            ("goal_error", "goal error [mm], the last 5 s"),
            ("contact_force", "contact force [N], the last 5 s"),
        ):
            series = [viser.uplot.Series(label="t [s]")] + [
                viser.uplot.Series(
                    label=r.method,
                    stroke="#{:02x}{:02x}{:02x}".format(*method_colour(r.method)),
                    width=2,
                )
                for r in self.recordings
            ]
            self.plots[column] = gui.add_uplot(
                data=tuple(np.zeros(1) for _ in series),
                series=tuple(series),
                title=title,
                aspect=2.0,
                scales={"x": viser.uplot.Scale(time=False)},
            )
        self.time.on_update(lambda _: self.show(self.time.value))
        self._stop = threading.Event()
        self._playing = threading.Lock()
        self.show(0.0)

    @property
    def url(self) -> str:
        """The page's address."""
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def show(self, t: float) -> None:
        """Put every robot, the goal and the readout at time ``t``."""
        lines = [f"**t = {t:.3f} s**", ""]
        for recording, robot, joints in self._robots:
            k = recording.index(t)
            values = {name: float(q[k]) for name, q in recording.q.items()}
            robot.update_cfg(
                joint_values(joints, values, self.scene.get("locked_joints", {}))
            )
            c = recording.columns
            force = c.get("contact_force")
            clearance = c.get("clearance")
            error = np.linalg.norm(
                recording.goal[0][k]
                - np.array([c["ee_x"][k], c["ee_y"][k], c["ee_z"][k]])
            )
            parts = [f"- **{recording.method}**: goal error {error * 1e3:.0f} mm"]
            if force is not None:
                parts.append(f"contact {force[k]:.1f} N")
            if clearance is not None and np.isfinite(clearance[k]):
                parts.append(f"clearance {clearance[k] * 1e3:.0f} mm")
            lines.append(", ".join(parts))
        first = self.recordings[0]
        k = first.index(t)
        position, quat = first.goal[0][k], first.goal[1][k]
        if np.all(np.isfinite(position)):
            self._goal.position = tuple(position)
            self._goal.wxyz = (quat[3], quat[0], quat[1], quat[2])
            self._goal.visible = True
        else:
            self._goal.visible = False
        self.readout.content = "\n".join(lines)
        self._move_objects(t)
        self._plot(t)

    def _move_objects(self, t: float) -> None:
        """Put the objects that appear or move where they were at ``t``."""
        for name, track in self._tracks.items():
            k = max(0, int(np.searchsorted(track[:, 0], t, side="right")) - 1)
            row = track[k]
            handle = self._objects[name]
            handle.visible = bool(row[1])
            handle.position = tuple(row[2:5])
            handle.wxyz = (row[8], row[5], row[6], row[7])

    def _plot(self, t: float) -> None:
        """Each method's goal error and contact force over the 5 s up to ``t``."""
        first = self.recordings[0]
        lo = int(np.searchsorted(first.t, t - PLOT_WINDOW))
        hi = max(lo + 1, int(np.searchsorted(first.t, t, side="right")))
        step = max(1, (hi - lo) // PLOT_POINTS)
        times = first.t[lo:hi:step]
        for column, plot in self.plots.items():
            values = []
            for recording in self.recordings:
                curve = _curve(recording, column)
                values.append(np.interp(times, recording.t, curve))
            plot.data = (times, *values)

    def run(self) -> None:
        """Serve until :meth:`close`: play when the box is ticked."""
        while not self._stop.wait(1.0 / FRAME_RATE):
            with self._playing:  # never after close() has stopped the server
                if self._stop.is_set():
                    break
                if self.playing.value:
                    t = self.time.value + self.speed.value / FRAME_RATE
                    if t > self.duration:
                        t = 0.0
                    self.time.value = t  # type: ignore[misc]  # triggers show()

    def export(self, path: Path, rate: float = 20.0) -> Path:
        """Write the replay as a .viser recording (``rate`` frames per second)."""
        serializer = self.server.get_scene_serializer()
        for t in np.arange(0.0, self.duration + 1e-9, 1.0 / rate):
            self.show(float(t))
            serializer.insert_sleep(1.0 / rate)
        path.write_bytes(serializer.serialize())
        return path

    def close(self) -> None:
        """Stop playing and the server."""
        with self._playing:
            self._stop.set()
        self.server.stop()


def _curve(recording: RunRecording, column: str) -> FloatArray:
    """A plotted column of a recording: goal error [mm] or a trace column."""
    c = recording.columns
    if column == "goal_error":
        hand = np.column_stack([c["ee_x"], c["ee_y"], c["ee_z"]])
        return np.asarray(1e3 * np.linalg.norm(recording.goal[0] - hand, axis=1))
    values = c.get(column)
    return np.zeros_like(recording.t) if values is None else np.nan_to_num(values)


def serve(out: Path, port: int, export: Path | None) -> int:
    """``cbp view``: serve the replay (or write it) until interrupted."""
    replay = Replay(out, port=port)
    try:
        if export is not None:
            replay.export(export)
            print(f"wrote {export}")
            return 0
        print(f"replay of {out}: {replay.url} (Ctrl-C to stop)", flush=True)
        with contextlib.suppress(KeyboardInterrupt):
            replay.run()
        return 0
    finally:
        replay.close()
