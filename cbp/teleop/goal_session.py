# SPDX-License-Identifier: Apache-2.0
"""A goal session: a scenario driven live toward the operator's goal.

The run is assembled like every other (:func:`cbp.run.build_run`) with the
operator's :class:`~cbp.goals.LiveGoal` as its goal source, driven
by the trajectory loop paced to the wall clock, with a
:class:`~cbp.teleop.switching.SwitchingPlanner` that hands control between
methods at a period's start. :meth:`TeleopSession.snapshot` is what a page
shows, as a frozen record.
"""

from __future__ import annotations

import math
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from cbp.collision.contacts import ContactSet
from cbp.errors import ConfigError, require_choice
from cbp.files import OutputClaim, claim_output_folder
from cbp.goals import LiveGoal, write_recorded
from cbp.methods import PERIODIC
from cbp.robot import FloatArray
from cbp.run import RunParts, WallClockPacer, build_run
from cbp.run.events import RunListener
from cbp.run.loop import run_loop
from cbp.run.pacing import LoopClock
from cbp.scenario import load_scenario
from cbp.sim.trajectory import JointTrajectory
from cbp.state import RobotState
from cbp.teleop.changes import Changes
from cbp.teleop.switching import SwitchingPlanner
from cbp.trace import Trace

__all__ = [
    "GOAL_FILE",
    "LONGEST",
    "METHODS",
    "MIN_PERIOD",
    "Commanded",
    "Snapshot",
    "TeleopSession",
    "latency_summary",
]

#: The methods a session can switch between: the trajectory executors.
METHODS = PERIODIC
#: A session lasts until it is stopped, at most this long (the scenario
#: schema's longest duration) [s].
LONGEST = 86400.0
#: The shortest command period of a session [s], unless the scenario's
#: ``--set method.cat.timing.min_period`` says otherwise. The period shrinks
#: toward it while planning leaves time to spare (an arm at its goal), so a new
#: goal waits less for the next period: measured on the boards, goal-to-command
#: latency median 20 ms and p95 27 ms, against 50 and 63 ms with the nominal
#: 33 ms period throughout (``benchmarks/RESULTS.md``). Every method of a
#: session runs on these timings (CAT's).
MIN_PERIOD = 0.015
#: The operator's goal stream file in a session's outputs.
GOAL_FILE = "operator_goal.csv"


class Commanded(NamedTuple):
    """Where one goal's time went, from its arrival to its first command.

    Times are ``time.perf_counter()`` [s].

    Attributes:
        number: the goal's number (:meth:`LiveGoal.set`).
        arrival: when it was set (the page's handler, a script).
        sampled: when the control loop first took it (at a period's start,
            while CAT planned, or on waking from the period's wait).
        planned: when the plan that was commanded for it was made.
        commanded: when the first trajectory planned for it started to be
            commanded (the splice point, or the splice itself if later; of
            two plans for it, the earlier).
    """

    number: int
    arrival: float
    sampled: float
    planned: float
    commanded: float


@dataclass(frozen=True)
class Snapshot:
    """What the page shows of a session at one moment.

    Attributes:
        t: simulated time [s].
        q: joint positions.
        hand: the end effector's position (3,) [m].
        method: the method in control.
        paused: whether the arm is held.
        steps: planning steps of the last command period.
        misses: deadline misses so far.
        contact_force: contact force of the last physics step [N].
        events: the latest events, newest last.
        contacts: the contacts CAT's contact rows hold at its latest step
            (None for a method without them).
        trajectory: the trajectory the robot follows (a new object at each
            splice; its last point is where the arm is heading).
        held_by: what held the arm at the last step of the method in control
            (CAT, hybrid): ``contact`` (an obstacle), ``self-collision``,
            ``joint limit``, or the name of another hard entry; empty when
            nothing did or the method does not say (IK, MP).
        note: the last command period's note (what its planner said: a hold's
            reason, ``paused``, ``converged`` ...).
        recent_misses: deadline misses among the periods of the last second.
    """

    t: float
    q: FloatArray
    hand: FloatArray
    method: str
    paused: bool
    steps: int
    misses: int
    contact_force: float
    events: tuple[tuple[float, str], ...] = ()
    contacts: ContactSet | None = None
    trajectory: JointTrajectory | None = None
    held_by: frozenset[str] = frozenset()
    note: str = ""
    recent_misses: int = 0


class TeleopSession(RunListener):
    """A scenario driven live: the simulation, the executor and the goal.

    Args:
        path: the scenario file.
        method: the method to start with (:data:`METHODS`).
        overrides: scenario values to replace (``--set``).

    Raises:
        ConfigError: an unknown method; ScenarioError: a bad scenario.
    """

    def __init__(
        self,
        path: str | Path,
        method: str = "cat",
        overrides: dict[str, str] | None = None,
    ) -> None:
        """Load the scenario and build the run; :meth:`start` starts it."""
        require_choice(method, METHODS, "method", "--method")
        values = {
            "duration": str(LONGEST),
            "method.cat.timing.min_period": str(MIN_PERIOD),
            **(overrides or {}),
        }
        self.path = Path(path)
        self.scenario = load_scenario(self.path, overrides=values)
        if self.scenario.goal_task() is None:
            raise ConfigError(
                f"{self.path}: the scenario has no goal_pose task to teleoperate"
            )
        robot = self.scenario.robot
        state = RobotState(robot, self.scenario.q0)
        hand = state.frame_placement(robot.frame_id(self.scenario.ee_frame))
        #: The hand's pose at the start: where the goal starts and resets to.
        self.home = (hand.translation.copy(), hand.rotation.copy())
        stream = self.scenario.goal_stream()
        self.goal = LiveGoal(*self.home, stream.rate_hz if stream else 30.0)
        #: The run's parts: its goal is the operator's, its clock the wall's.
        # The live loop's wait steps the robot (lockstep even with
        # simulation.own_process).
        self.parts: RunParts = build_run(
            self.scenario,
            method=method,
            goal=self.goal,
            needs_world=True,
            lockstep=True,
        )
        self.scenario = self.parts.scenario  # the run's own binding of it
        try:
            self.planner = SwitchingPlanner(self.scenario, self.parts, method)
        except BaseException:
            self.parts.close()
            raise
        self.timing = self.scenario.spec.method.timing("cat")
        self.parts.log.listeners.append(self)  # told of commands and motion
        self._stopping = threading.Event()
        #: Told at each change a page shows: a command period's end (the
        #: arm's state at it is now), a new goal, a new trajectory.
        self.changes = Changes()
        # A new goal ends the loop's wait for its deadline: it is planned for
        # and commanded at once, not at that deadline.
        self._pacer = WallClockPacer(wake=self.goal.arrived)
        self._latencies: list[float] = []
        self._commands: list[Commanded] = []
        self._state = RobotState(robot)
        self._frame = robot.frame_id(self.scenario.ee_frame)
        self._periods_counted = self._misses = 0
        self._thread: threading.Thread | None = None
        self.trace: Trace | None = None
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ control

    def start(self) -> None:
        """Start the control loop in its own thread."""
        self._thread = threading.Thread(target=self._loop, name="teleop", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        try:
            self.trace = run_loop(
                self.parts,
                self.planner,
                self.timing,
                LoopClock.paced(self._pacer, self._stop_requested),
            )
        except BaseException as exc:  # kept for stop() to raise in the caller
            self.error = exc

    def _stop_requested(self) -> bool:
        """Stopping, and the robot at rest (its trajectory has ended)."""
        sim = self.parts.arm
        return self._stopping.is_set() and sim.trajectory.end_time <= sim.t

    def reached(self, t: float) -> None:
        """The arm's motion is simulated up to now (a period's end): tell."""
        self.changes.notify()

    def commanded(self, t: float) -> None:
        """Measure the latency of the goal this trajectory was planned for."""
        taken = self.goal.take_sampled()
        self.changes.notify()
        if not self._pacer.started:
            return
        starts = max(time.perf_counter(), self._pacer.wall_time(t))
        planned = self.planner.planned_at
        if taken is None:
            # Planned for again, for the same goal (taken by the period's
            # planner between its steps): commanded from the earlier start.
            last = self._commands[-1] if self._commands else None
            if (
                last is not None
                and last.number == self.goal.sampled_number
                and starts < last.commanded
            ):
                self._commands[-1] = Commanded(
                    last.number, last.arrival, last.sampled, planned, starts
                )
                self._latencies[-1] = starts - last.arrival
            return
        number, arrival, sampled = taken
        self._latencies.append(starts - arrival)
        self._commands.append(Commanded(number, arrival, sampled, planned, starts))

    def set_goal(self, position: FloatArray, rotation: FloatArray) -> int:
        """Send a goal (the page's gizmo, a script); return its number."""
        number = self.goal.set(position, rotation)
        self.changes.notify()
        return number

    def listen(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` (quick; from any thread) at each change.

        A command period's end (the arm's state at it is now), a new
        trajectory commanded, a goal set through :meth:`set_goal`.
        """
        self.changes.listen(callback)

    def jog(self, axis: str, step: float, frame: str = "world") -> int:
        """Move the goal by ``step`` along or about an axis.

        From the latest goal sent, or, when that one was malformed (and
        rejected by the run), from the goal in force.

        Args:
            axis: ``x``, ``y``, ``z`` (translate by ``step`` [m]) or ``rx``,
                ``ry``, ``rz`` (rotate by ``step`` [rad]).
            step: the amount, signed.
            frame: ``world`` or ``hand`` (the goal's own axes).
        """
        require_choice(axis, ("x", "y", "z", "rx", "ry", "rz"), "axis", "jog")
        require_choice(frame, ("world", "hand"), "frame", "jog")
        position, rotation = self.goal.pose()
        if not (np.isfinite(position).all() and np.isfinite(rotation).all()):
            # The latest goal was malformed (and rejected): jog from the one
            # in force.
            accepted = self.parts.goal.changes
            if accepted:
                position = accepted[-1][1].translation.copy()
                rotation = accepted[-1][1].rotation.copy()
            else:
                position, rotation = self.home[0].copy(), self.home[1].copy()
        unit = np.eye(3)["xyz".index(axis[-1])]
        if frame == "hand":
            unit = rotation @ unit
        if axis.startswith("r"):
            rotation = pin.exp3(unit * step) @ rotation
        else:
            position = position + unit * step
        return self.set_goal(position, rotation)

    def reset(self) -> int:
        """Put the goal back at the hand's starting pose."""
        return self.set_goal(*self.home)

    def pause(self, paused: bool = True) -> None:
        """Hold the arm (it brakes on its trajectory), or let it go on."""
        self.planner.paused = paused

    def switch(self, method: str) -> None:
        """Hand control to ``method`` at the next command period."""
        require_choice(method, METHODS, "method", "switch")
        self.planner.wanted = method

    def stop(self, timeout: float = 30.0) -> Trace:
        """Brake, end the run when the arm is at rest, and return its trace."""
        self.planner.paused = True
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                raise RuntimeError("the control loop did not stop in time")
        if self.error is not None:
            raise self.error
        if self.trace is None:
            raise RuntimeError("the session was not started")
        return self.trace

    def write(self, out: Path, claim: OutputClaim | None = None) -> Path:
        """Write the outputs of ``cbp run`` and the operator's goal stream.

        ``claim``: the folder claimed for ``out`` when the session began
        (:func:`cbp.files.claim_output_folder`); None: claimed now. A
        session never replaces another's outputs: ``out`` must be new or
        empty.

        Raises:
            ConfigError: ``out`` is not empty.
        """
        from cbp.report import write_outputs

        if self.trace is None:
            raise RuntimeError("stop the session before writing it")
        claim = claim or claim_output_folder(out, refuse_live=False, replace=False)
        changes = self.parts.goal.changes
        if not changes:
            changes = [(0.0, pin.SE3(self.home[1], self.home[0]))]
        with tempfile.TemporaryDirectory() as folder:
            goal_file = Path(folder) / GOAL_FILE
            write_recorded(
                goal_file,
                [t for t, _ in changes],
                np.array([p.translation for _, p in changes]),
                np.array([p.rotation for _, p in changes]),
            )
            write_outputs(
                self.scenario,
                {self.trace.method: self.trace},
                out,
                extra_files={GOAL_FILE: goal_file},
                claim=claim,
            )
        return out / GOAL_FILE

    # ------------------------------------------------------------------ reading

    @property
    def running(self) -> bool:
        """Whether the control loop runs."""
        return self._thread is not None and self._thread.is_alive()

    def snapshot(self) -> Snapshot:
        """What the page shows now (read from the control thread's state)."""
        run = self.parts
        q = np.array(run.arm.q, dtype=float)
        self._state.update(q)
        periods = run.log.periods
        # Deadline misses counted once per period (a session may run for hours).
        for period in periods[self._periods_counted :]:
            self._misses += period.missed
        self._periods_counted = len(periods)
        recent = 0
        for period in reversed(periods[-200:]):
            if period.t < run.arm.t - 1.0:
                break
            recent += period.missed
        return Snapshot(
            t=run.arm.t,
            q=q,
            hand=self._state.frame_position(self._frame).copy(),
            method=self.planner.method,
            paused=self.planner.paused,
            steps=periods[-1].steps if periods else 0,
            misses=self._misses,
            contact_force=float(run.arm.contact_force),
            events=tuple(run.log.events[-5:]),
            contacts=self.planner.contacts(),
            trajectory=run.arm.trajectory,
            held_by=self.planner.held_by,
            note=periods[-1].note if periods else "",
            recent_misses=recent,
        )

    def measured(self) -> tuple[float, FloatArray, float]:
        """The robot's measured joint positions now, with their time.

        Returns:
            Simulated time ``t`` [s], the joint positions at it, and how long
            until the wall clock reaches ``t`` [s]: above 0 when the loop has
            simulated ahead of the wall clock (by at most a command lead, so
            that a new goal can be commanded then), 0 before it starts.
        """
        sim = self.parts.arm
        # q before t: a physics step in between makes t later than q's time,
        # never earlier (due is then the later one).
        q = np.array(sim.q, dtype=float)
        t = float(sim.t)
        due = self._pacer.left(t) if self._pacer.started else 0.0
        return t, q, max(due, 0.0)

    def latency_ms(self) -> list[float]:
        """Goal-to-command latencies measured so far [ms]."""
        return [1e3 * x for x in self._latencies]

    def commands(self) -> list[Commanded]:
        """Each goal commanded so far, with where its time went."""
        return list(self._commands)


def latency_summary(latencies_ms: list[float]) -> dict[str, Any]:
    """Median, 95th percentile and count of latencies [ms]."""
    if not latencies_ms:
        return {"n": 0, "median_ms": math.nan, "p95_ms": math.nan}
    values = np.array(latencies_ms)
    return {
        "n": int(values.size),
        "median_ms": float(np.median(values)),
        "p95_ms": float(np.percentile(values, 95)),
    }
