# SPDX-License-Identifier: Apache-2.0
"""The page of an input session (orbit and pan object), served by viser."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from cbp.drawing import add_robot, draw_objects, joint_values
from cbp.errors import ConfigError
from cbp.plugin import DescribesInput
from cbp.robot import FloatArray
from cbp.scene_file import scene_description
from cbp.teleop.input_session import InputSession
from cbp.teleop.page import Page

__all__ = ["InputsPage", "SliderSpec", "slider_specs"]


@dataclass(frozen=True)
class SliderSpec:
    """A slider of one input value.

    Attributes:
        label: what it sets, with its unit ("camera velocity sideways (y) [m/s]").
        low: its lowest value.
        high: its highest value.
    """

    label: str
    low: float
    high: float


def slider_specs(entry: str, plugin: object, values: FloatArray) -> list[SliderSpec]:
    """The sliders of input ``entry``, one per value, from its plugin's description.

    A plugin that describes its input (:class:`~cbp.plugin.DescribesInput`)
    names each value, with its unit and range (widened to hold the starting
    value); one that does not gets ``entry[i]``, from 0 to twice a positive
    starting value, else within +-0.2.
    """
    start = np.asarray(values, dtype=float).reshape(-1)
    if isinstance(plugin, DescribesInput):
        described = plugin.input_values()
        if len(described) != len(start):
            raise ConfigError(
                f"input {entry}: its plugin describes {len(described)} values, "
                f"it takes {len(start)}"
            )
        return [
            SliderSpec(
                f"{d.label} [{d.unit}]" if d.unit else d.label,
                min(d.low, float(v)),
                max(d.high, float(v)),
            )
            for d, v in zip(described, start, strict=True)
        ]
    return [
        SliderSpec(
            f"{entry}[{i}]",
            0.0 if v > 0 else -0.2,
            2.0 * float(v) if v > 0 else 0.2,
        )
        for i, v in enumerate(start)
    ]


class InputsPage(Page[InputSession]):
    """The page of an :class:`~cbp.teleop.InputSession` (orbit and pan object).

    The robot (its base placed from the planar joint), the declared objects, a
    dropdown of the configurations, a slider per input value named by what it
    sets, with its unit and range, as its plugin describes it
    (:class:`~cbp.plugin.DescribesInput`: "camera velocity sideways (y)
    [m/s]", "distance to the object (r_d) [m]"; :func:`slider_specs`), stop
    and save, and a readout of the active configuration's signals and the
    latest events.
    """

    def __init__(
        self, session: InputSession, host: str = "127.0.0.1", port: int = 8080
    ) -> None:
        """Build the scene and the panel."""
        super().__init__(session, host, port)
        scenario = session.scenarios[0]
        description = scene_description(scenario, duration=0.0)
        draw_objects(self.server, description)
        self.base = self.server.scene.add_frame("/robot", show_axes=False)
        self.robot = add_robot(
            self.server, description["urdf"], "/robot", (242, 153, 26)
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
                    specs = slider_specs(entry, session.plugin(config, entry), values)
                    for spec, value in zip(specs, values, strict=True):
                        slider = gui.add_slider(
                            spec.label,
                            min=spec.low,
                            max=spec.high,
                            step=(spec.high - spec.low) / 200,
                            initial_value=float(value),
                        )
                        slider.on_update(self._setter(config, entry))
                        handles.append(slider)
                    self.sliders[config][entry] = handles
            folder.visible = config == session.active
        self.readout = gui.add_markdown("")
        self.add_render_toggle()

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
        q = snap.q
        values = dict(zip(self._q_names, (float(v) for v in q), strict=True))
        # The planar base: x, y, cos(yaw), sin(yaw).
        yaw = math.atan2(q[3], q[2])
        self.base.position = (float(q[0]), float(q[1]), 0.0)
        self.base.wxyz = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        self.robot.update_cfg(joint_values(self._joints, values, {}))
        lines = [f"**t = {snap.t:.2f} s**, configuration **{snap.active}**", ""]
        lines += [f"- {k}: {v:.3f}" for k, v in sorted(snap.signals.items())]
        if snap.events:
            lines += ["", "latest events:"]
            lines += [f"- {t:.2f} s: {m}" for t, m in snap.events]
        self.readout.content = "\n".join(lines)
