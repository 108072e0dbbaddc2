# SPDX-License-Identifier: Apache-2.0
"""Optional capabilities of a plugin, each a protocol executors test with isinstance.

A plugin has one by defining its methods (no base class to derive from):
:class:`GoalReceiver`, :class:`TakesInput` (and :class:`DescribesInput`),
:class:`MovingBounds`, :class:`UsesCollisionWorld`, :class:`HoldsContacts`,
:class:`ReportsSignals`. :mod:`cbp.plugin` exports them beside the contract.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, NamedTuple, Protocol, runtime_checkable

import numpy.typing as npt

from cbp.robot import FloatArray
from cbp.state import RobotState

if TYPE_CHECKING:
    from cbp.collision.contacts import ContactSet
    from cbp.collision.world import CollisionWorld

__all__ = [
    "DescribesInput",
    "GoalReceiver",
    "HoldsContacts",
    "InputValue",
    "MovingBounds",
    "ReportsSignals",
    "TakesInput",
    "UsesCollisionWorld",
]


@runtime_checkable
class GoalReceiver(Protocol):
    """A task that drives a frame toward the operator's goal pose.

    The goal stream (``goal:`` in a scenario, the teleoperation page) calls
    :meth:`set_target` every command period; executors read ``goal_frame`` to
    measure the tracking error.
    """

    @property
    def goal_frame(self) -> str:
        """Name of the frame moved to the goal."""

    def set_target(self, position: npt.ArrayLike, rotation: npt.ArrayLike) -> None:
        """Set the goal: position (3,) [m], rotation matrix (3, 3), world frame.

        Raises:
            InvalidTargetError: the goal is refused (NaN, not a rotation); the
                previous one is kept.
        """


@runtime_checkable
class TakesInput(Protocol):
    """A plugin driven by a live operator input (``inputs:`` in a scenario)."""

    @property
    def input_size(self) -> int:
        """Number of input values."""

    def set_input(self, values: npt.ArrayLike) -> None:
        """Take new input values, shape (input_size,).

        Raises:
            ValueError: the values are refused; the previous ones are kept.
        """


class InputValue(NamedTuple):
    """What one value of an operator input means, for a slider or a device.

    Attributes:
        label: what the value sets, in words ("camera velocity along its y").
        unit: its unit ("m/s").
        low: the lowest value an operator would set.
        high: the highest.
    """

    label: str
    unit: str
    low: float
    high: float


@runtime_checkable
class DescribesInput(Protocol):
    """A :class:`TakesInput` plugin that says what each of its input values means.

    Pages name their sliders from it, with units and ranges.
    """

    def input_values(self) -> tuple[InputValue, ...]:
        """One description per input value, in the input's order."""


@runtime_checkable
class MovingBounds(Protocol):
    """A constraint whose bounds move from step to step (an operator's input).

    The feedback form removes a fraction k of the error each step, so bounds
    that move at a steady rate are followed with a lag of rate / k per step.
    An engine step given the robot's velocity moves the rows' bounds, after
    the gain, by :meth:`bound_change` as well (feedforward: no lag).
    """

    def bound_change(self) -> FloatArray:
        """How far the bounds are expected to move over the step (dim,).

        Zeros when they are not moving steadily (a single jump is left to
        the feedback).
        """


@runtime_checkable
class UsesCollisionWorld(Protocol):
    """A plugin that reads contacts: the scenario attaches the collision world."""

    def attach_world(self, world: CollisionWorld) -> None:
        """Use ``world`` for contact queries from now on."""


@runtime_checkable
class HoldsContacts(Protocol):
    """A constraint with a row per contact with the environment.

    Executors read the contacts latched for the current step, with the world's
    shapes, to say what holds the arm (``contact_normals``).
    """

    @property
    def contacts(self) -> ContactSet:
        """The contacts latched for the current step.

        Raises:
            CbpError: nothing is latched yet (no step, no world).
        """

    @property
    def world(self) -> CollisionWorld | None:
        """The collision world the contacts come from."""


@runtime_checkable
class ReportsSignals(Protocol):
    """A plugin with named quantities worth recording over a run.

    Executors record them at every tick; reports plot and summarise them (the
    orbit's distance, view error, roll, altitude and their bounds).
    """

    def signals(self, state: RobotState) -> Mapping[str, float]:
        """Values at ``state``, by name (the unit in the name: ``_deg``, ``_m``)."""
