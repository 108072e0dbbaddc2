# SPDX-License-Identifier: Apache-2.0
"""An input session: velocity-executor configurations driven live by their inputs.

Orbit object and pan object (the orbit paper) are configurations of the
velocity executor. A session runs one or several of them (scenario files of
one robot) on one simulation, in real time, and the operator sets their
inputs and switches between them within the run (:class:`InputSession`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cbp.errors import ConfigError, require_choice
from cbp.files import OutputClaim, claim_output_folder
from cbp.methods import METHODS
from cbp.robot import FloatArray
from cbp.run import WallClockPacer
from cbp.scenario import load_scenario
from cbp.teleop.changes import Changes
from cbp.teleop.goal_session import LONGEST
from cbp.trace import Trace

__all__ = ["InputSession", "InputSnapshot"]


@dataclass(frozen=True)
class InputSnapshot:
    """What the page shows of an input session at one moment.

    Attributes:
        t: simulated time [s].
        active: the configuration in control.
        q: the configuration (base and arm).
        signals: the active configuration's latest reported signals, by name.
        events: the latest events of every configuration, newest last.
    """

    t: float
    active: str
    q: FloatArray
    signals: dict[str, float]
    events: tuple[tuple[float, str], ...]


class InputSession:
    """Velocity-executor configurations of one robot driven live by their inputs.

    Orbit object and pan object (the orbit paper) are configurations of the
    velocity executor; a session loads one or several (scenario files of one
    robot) on one simulation, and the operator switches between them within
    the run (:meth:`switch`, at the next tick; the new one starts from the
    last command). Each configuration's inputs (``camera_velocity``'s
    camera-frame velocities, ``orbit_distance``'s desired distance) start at
    their scenario's values at t = 0 and are set with :meth:`set_input`; a
    value an entry refuses is an event and the entry keeps its previous one.

    Args:
        paths: the scenario files (``method.name: velocity``, one robot).
        overrides: values to replace in every one of them (``--set``).

    Raises:
        ConfigError: a scenario of another executor or robot.
    """

    def __init__(
        self, paths: list[Path], overrides: dict[str, str] | None = None
    ) -> None:
        """Load every configuration and build their loops on one simulation."""
        from cbp.executors.velocity import VelocityLoop
        from cbp.sim.mobile import MobileSimulation
        from cbp.sim.scene import simulate

        values = {"duration": str(LONGEST), **(overrides or {})}
        self.scenarios = [load_scenario(p, overrides=values) for p in paths]
        first = self.scenarios[0]
        for path, scenario in zip(paths, self.scenarios, strict=True):
            if scenario.spec.method.name != "velocity":
                raise ConfigError(
                    f"{path}: a '{scenario.spec.method.name}' scenario; with several "
                    "files, or one of the velocity executor, every file must be a "
                    "velocity-executor configuration"
                )
            if scenario.robot.name != first.robot.name:
                raise ConfigError(
                    f"{path}: robot '{scenario.robot.name}', not "
                    f"'{first.robot.name}' as in {paths[0]}"
                )
            METHODS["velocity"].refuse_source(
                scenario.spec.perception.source, f"{scenario.path}: perception.source"
            )
        self.sim = simulate(MobileSimulation, first)
        command = np.zeros(first.robot.nv)
        self.loops = {
            s.spec.name: VelocityLoop(s, self.sim, command) for s in self.scenarios
        }
        #: Each configuration's inputs by entry name: the values in force.
        self.inputs: dict[str, dict[str, FloatArray]] = {}
        self._plugins: dict[str, dict[str, Any]] = {}
        for scenario in self.scenarios:
            names = {id(e.plugin): e.name for e in scenario.entries}
            self.inputs[scenario.spec.name] = {
                names[id(p)]: np.array([f(0.0) for f in fs])
                for p, fs in scenario.inputs()
            }
            self._plugins[scenario.spec.name] = {
                names[id(p)]: p for p, _ in scenario.inputs()
            }
        self.active = first.spec.name
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._changes = Changes()
        self._thread: threading.Thread | None = None
        self.events: list[tuple[float, str]] = []
        self.t = 0.0
        self.error: BaseException | None = None

    @property
    def robot(self) -> Any:
        """The robot model."""
        return self.scenarios[0].robot

    def plugin(self, config: str, entry: str) -> Any:
        """The plugin of ``config``'s input ``entry`` (what its values mean)."""
        require_choice(config, self._plugins, "configuration", "plugin")
        require_choice(entry, self._plugins[config], "input", "plugin")
        return self._plugins[config][entry]

    def set_input(
        self, entry: str, values: FloatArray, config: str | None = None
    ) -> None:
        """Set an input of the active (or the named) configuration."""
        config = config or self.active
        require_choice(config, self.inputs, "configuration", "set_input")
        require_choice(entry, self.inputs[config], "input", "set_input")
        with self._lock:
            self.inputs[config][entry] = np.array(values, dtype=float)

    def input_plugins(self, config: str | None = None) -> dict[str, Any]:
        """The plugins whose inputs the active (or the named) configuration takes."""
        config = config or self.active
        require_choice(config, self._plugins, "configuration", "input_plugins")
        return dict(self._plugins[config])

    def event(self, message: str) -> None:
        """Record ``message`` in the session's log (a device's deadman, say)."""
        with self._lock:
            self.events.append((self.t, message))

    def switch(self, config: str) -> None:
        """Hand control to another configuration at the next tick."""
        require_choice(config, self.loops, "configuration", "switch")
        with self._lock:
            if config != self.active:
                self.events.append((self.t, f"switched from {self.active} to {config}"))
                self.active = config

    def start(self) -> None:
        """Run the ticks in real time in a thread of their own."""
        self._thread = threading.Thread(target=self._run, name="teleop", daemon=True)
        self._thread.start()

    def listen(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` (quick; from the ticks' thread) after each tick."""
        self._changes.listen(callback)

    @property
    def running(self) -> bool:
        """Whether the ticks run."""
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        try:
            dt = self.loops[self.active].settings.dt
            pacer = WallClockPacer(wake=self._stop)
            k = 0
            while not self._stop.is_set():
                t = k * dt
                with self._lock:
                    loop = self.loops[self.active]
                    values = dict(self.inputs[self.active])
                for name, value in values.items():
                    plugin = self._plugins[self.active][name]
                    loop.set_input(plugin, t, value.tolist)
                loop.tick(t)
                self.t = t + dt
                self._changes.notify()
                k += 1
                if loop.faults.aborted is not None:
                    break
                pacer.wait_until(k * dt)
        except BaseException as exc:  # kept for stop() to raise in the caller
            self.error = exc

    def snapshot(self) -> InputSnapshot:
        """What the page shows now: time, configuration, the latest signals."""
        loop = self.loops[self.active]
        signals = {k: v[-1] for k, v in loop.signals.items() if v}
        events = sorted(
            self.events + [e for lp in self.loops.values() for e in lp.events]
        )
        return InputSnapshot(
            t=self.t,
            active=self.active,
            q=np.array(self.sim.q, dtype=float),
            signals=signals,
            events=tuple(events[-5:]),
        )

    def stop(self, timeout: float = 10.0) -> dict[str, Trace]:
        """Stop the ticks (the robot brakes to rest); each configuration's trace."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        if self.error is not None:
            raise self.error
        traces = {}
        for name, loop in self.loops.items():
            if loop.rows["t"]:
                trace = loop.trace()
                trace.events.extend(e for e in self.events if e not in trace.events)
                traces[name] = trace
        self.sim.close()
        return traces

    def write(
        self, traces: dict[str, Trace], out: Path, claim: OutputClaim | None = None
    ) -> None:
        """Write each configuration's run as ``cbp run`` would, in one folder.

        ``claim``: the folder claimed for ``out`` when the session began
        (:func:`cbp.files.claim_output_folder`); None: claimed now. A
        session never replaces another's outputs: ``out`` must be new or
        empty.

        Raises:
            ConfigError: ``out`` is not empty.
        """
        from cbp.report import write_outputs

        claim = claim or claim_output_folder(out, refuse_live=False, replace=False)
        write_outputs(self.scenarios[0], traces, out, claim=claim)
