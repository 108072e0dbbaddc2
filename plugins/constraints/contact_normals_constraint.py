# SPDX-License-Identifier: Apache-2.0
"""Constraint ``contact_normals``: contact points may not move into the environment."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from cbp.collision.contacts import ContactSet
from cbp.collision.rows import LatchedContacts
from cbp.collision.world import CollisionWorld
from cbp.errors import ConfigError, TargetNotSetError
from cbp.plugin import Constraint, FloatArray, PluginParams
from cbp.robot import RobotModel
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class ContactParams(PluginParams):
    """Parameters of the contact constraints."""

    max_contacts: int = 16
    """Rows of the constraint: the closest contacts kept per step."""
    safety_distance: float = 0.0
    """Distance d_safe kept from obstacles, after the links' padding [m]."""

    def __post_init__(self) -> None:
        """At least one row; finite distance."""
        if not 1 <= self.max_contacts <= 1000:
            raise ConfigError(
                f"must be in [1, 1000], got {self.max_contacts}", "max_contacts"
            )
        if not -1.0 < self.safety_distance < 1.0:
            raise ConfigError(
                f"must be within (-1, 1) m, got {self.safety_distance}",
                "safety_distance",
            )


class ContactNormalsConstraint(Constraint[ContactParams]):
    r"""Each contact point may not move further toward the obstacle (CAT eq. 5).

    For each robot point within the collision world's activation distance of the
    environment, with normal :math:`n` from the obstacle toward the robot and
    signed distance :math:`d` (padding included):

    .. math:: n^T J_c \Delta q \ge -k (d - d_{safe})

    With gain :math:`k = 0` this is eq. 5 exactly, :math:`n^T J_c \Delta q \ge 0`;
    with :math:`k > 0` a point may approach the obstacle by a fraction of its
    remaining distance per step, and is pushed out when inside
    :math:`d_{safe}`. Contacts are latched in :meth:`prepare` (the contact pair is
    then fixed on the link; see :mod:`cbp.collision.rows`). Needs a collision
    world (the scenario's ``world:``), attached by the loader. Dimension:
    ``max_contacts`` [m].
    """

    type_name: ClassVar[str] = "contact_normals"
    unit: ClassVar[str] = "m"
    default_gain: ClassVar[float] = 0.5

    def __init__(
        self, params: ContactParams, robot: RobotModel, name: str = ""
    ) -> None:
        """No world yet: :meth:`attach_world` provides it."""
        super().__init__(params, robot, name)
        self.world: CollisionWorld | None = None
        self._rows: LatchedContacts | None = None

    def attach_world(self, world: CollisionWorld) -> None:
        """Take contacts from ``world``."""
        if world.geometry.robot.model.nv != self.robot.nv:
            raise ConfigError(f"{self.name}: the collision world is for another robot")
        self.world = world
        self._rows = LatchedContacts(world.geometry, self.params.max_contacts)

    @property
    def dim(self) -> int:
        """One row per kept contact."""
        return self.params.max_contacts

    @property
    def contacts(self) -> ContactSet:
        """The contacts latched for the current step."""
        return self._latched().contacts

    def _select(self, contacts: ContactSet) -> ContactSet:
        return contacts.environment_part()

    def _latched(self) -> LatchedContacts:
        if self._rows is None:
            raise TargetNotSetError(
                f"{self.name} ({self.type_name}): no collision world attached; "
                "declare the scenario's 'world:' or call attach_world()"
            )
        return self._rows

    def prepare(self, state: RobotState, dt: float) -> None:
        """Query (or reuse) the contacts at the step's start and latch them."""
        rows = self._latched()
        assert self.world is not None
        rows.latch(self._select(self.world.contacts(state)), state)

    def compute_value(self, state: RobotState) -> FloatArray:
        """Distances continued from the latched contacts [m]."""
        return self._latched().value(state)

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """n^T J_c per row."""
        return self._latched().jacobian(state)

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Distances and n^T J_c, written in place."""
        self._latched().linearize_into(state, value, jacobian)

    def value_into(self, state: RobotState, value: FloatArray) -> None:
        """Distances, written in place."""
        self._latched().value_into(state, value)

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """[d_safe, inf) on active rows."""
        return self._latched().bounds(self.params.safety_distance)
