# SPDX-License-Identifier: Apache-2.0
"""``cbp teleop``: an operator drives the robot live, from the browser or a script.

A goal session (:class:`TeleopSession`) runs a scenario's simulation in real
time with a trajectory executor (CAT, IK, MP or hybrid, switchable at the next
command period) whose goal is the operator's :class:`LiveGoal`; it is
assembled like every run (:func:`cbp.run.build_run`, with the live goal and
the wall clock). An input session (:class:`InputSession`) drives the velocity
executor's configurations (orbit and pan object) by their inputs. Their pages
(:mod:`cbp.teleop.goal_page`, :mod:`cbp.teleop.inputs_page`) are served with
viser (the ``viewer`` extra) and imported only when served.

Everything a goal stream goes through still applies: a malformed goal is
rejected with an event and the previous one kept; a goal in an obstacle is
approached without contact. When the session stops, the arm brakes on a
trajectory it can follow, and the outputs of ``cbp run`` are written, with the
operator's goal stream as ``operator_goal.csv``: ``cbp compare SCENARIO --goal
operator_goal.csv`` replays the session to every method.

A gamepad or a 6-DOF mouse read by the page (:mod:`cbp.teleop.device_link`)
drives either kind of session through an input profile
(:mod:`cbp.teleop.profiles`) and a deadman (:class:`DeviceDriver`).
"""

from cbp.goals import LiveGoal
from cbp.teleop.device_driver import DeviceDriver, GoalTarget, VelocityTarget
from cbp.teleop.goal_session import (
    GOAL_FILE,
    METHODS,
    Snapshot,
    TeleopSession,
    latency_summary,
)
from cbp.teleop.input_session import InputSession, InputSnapshot
from cbp.teleop.profiles import InputProfile, load_profile
from cbp.teleop.switching import SwitchingPlanner

__all__ = [
    "GOAL_FILE",
    "METHODS",
    "DeviceDriver",
    "GoalTarget",
    "InputProfile",
    "InputSession",
    "InputSnapshot",
    "LiveGoal",
    "Snapshot",
    "SwitchingPlanner",
    "TeleopSession",
    "VelocityTarget",
    "latency_summary",
    "load_profile",
]
