# SPDX-License-Identifier: Apache-2.0
"""The collision world: the robot's shapes, the current environment, and contacts.

One :class:`CollisionWorld` is shared by the contact constraints (which latch its
contacts at the start of each step) and by the executor (which validates steps and
swaps in new environment snapshots from the map). Contacts of a configuration are
computed once and cached, so the check that validates a step also provides the
constraints of the next one (CAT Sec. IV-C).
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from cbp.collision.broad import shape_bounds
from cbp.collision.contacts import ContactSet
from cbp.collision.convex_kernels import (
    RobotTable,
    compile_convex_kernels,
    packed_robot,
)
from cbp.collision.environment import Environment, WholeQuery
from cbp.collision.free_check import FreeCheck
from cbp.collision.geometry import PlacedShapes, RobotGeometry, ShapePlacements
from cbp.collision.motion import SweepBound
from cbp.collision.objects import PrimitiveEnvironment
from cbp.collision.placements import ShapeKinematics
from cbp.collision.self_contacts import SelfContacts
from cbp.collision.settings import CollisionSettings
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = [
    "CollisionSettings",
    "CollisionWorld",
    "ContactSet",
    "StepCheck",
]


@dataclass(frozen=True)
class StepCheck:
    """The outcome of validating a configuration (:meth:`CollisionWorld.check`).

    Attributes:
        accepted: the penetration is within the tolerance.
        penetration: the deepest penetration of the padded shapes [m], each
            obstacle where it is (one the cameras see moving is not measured
            where it may come: :attr:`ContactSet.lead`).
        contacts: the contacts found there.
    """

    accepted: bool
    penetration: float
    contacts: ContactSet


@dataclass
class _Cache:
    key: bytes = b""
    environment: Environment | None = None
    contacts: ContactSet = field(default_factory=ContactSet.empty)


class CollisionWorld:
    """Robot geometry + environment snapshot: contact queries and step validation.

    Args:
        geometry: the robot's collision shapes.
        environment: the obstacles (default: none).
        settings: activation distance, contacts per shape, self-collision, ...

    The environment can be replaced at any time, from any thread
    (:meth:`set_environment`); a query uses the snapshot current when it starts.
    While a plan is made (:meth:`holding`), a new snapshot waits until the plan
    is done: every step of one plan is measured against the same obstacles.
    """

    def __init__(
        self,
        geometry: RobotGeometry,
        environment: Environment | None = None,
        settings: CollisionSettings | None = None,
    ) -> None:
        """Keep the parts; nothing is queried yet."""
        self.geometry = geometry
        self.settings = settings or CollisionSettings()
        self.padding = (
            self.settings.padding
            if self.settings.padding is not None
            else geometry.padding
        )
        self._environment: Environment = environment or PrimitiveEnvironment([])
        self._lock = threading.Lock()
        self._cache = _Cache()
        self._carried = ContactSet.empty()
        self._state = RobotState(geometry.robot)
        self.environment_version = 0
        #: Plans in progress (:meth:`holding`), and the snapshot waiting for them.
        self._holds = 0
        self._waiting: Environment | None = None
        #: The shapes no joint moves (a fixed base), left out of the map's
        #: contacts: a floor under the base touches it, and no motion can
        #: change that. (Declared objects leave them out by ``allow_contact``:
        #: :meth:`~cbp.scenario.runtime.Scenario.environment_objects`.)
        fixed = geometry.robot.fixed_links()
        self._fixed = np.array([s.link in fixed for s in geometry.shapes], dtype=bool)
        #: The others, by index, or None when every shape moves.
        self._moving = np.flatnonzero(~self._fixed) if self._fixed.any() else None
        self._geometry_model = geometry.geometry_model()
        self._geometry_data = pin.GeometryData(self._geometry_model)
        # Bounding-sphere (and box) centres in the shapes' own frames, (n, 3).
        self._centres = np.array(
            [s.placement.actInv(s.centre) for s in geometry.shapes]
        ).reshape(-1, 3)
        first, second = geometry.pair_arrays
        if not self.settings.self_collision:
            first, second = first[:0], second[:0]
        #: The shapes as the one-pass queries read them.
        self._table = RobotTable(
            np.ascontiguousarray(self._centres),
            np.ascontiguousarray(geometry.box_halves, dtype=float),
            np.ascontiguousarray(geometry.radii, dtype=float),
            packed_robot(geometry.shapes),
            first,
            second,
            np.zeros((len(first), 5)),
        )
        frames = geometry.robot.model.frames
        self._kinematics = ShapeKinematics.build(
            geometry.robot.model,
            [s.joint_id for s in geometry.shapes],
            [frames[s.frame_id].placement * s.placement for s in geometry.shapes],
        )
        if self._kinematics is not None:  # compiled (or loaded) here, not in a loop
            self._kinematics(pin.neutral(geometry.robot.model))
        #: The robot's own pairs measured apart (all pairs; the table's are
        #: those the one-pass queries check).
        self._own = SelfContacts(geometry, self.settings, self.padding)
        #: The planners' checks (:meth:`is_free`, :meth:`motion_free`).
        self._free = FreeCheck(
            geometry,
            self.settings,
            self.padding,
            self._table,
            self._centres,
            self._fixed,
            self.shape_frames,
        )
        if self.settings.narrow_phase == "compiled":
            compile_convex_kernels()
        self._environment.prepare(geometry.shapes, self.margin(self._environment))

    @property
    def environment(self) -> Environment:
        """The current environment snapshot."""
        return self._environment

    def set_environment(self, environment: Environment) -> None:
        """Swap in a new snapshot (thread-safe; queries in flight keep the old one).

        The snapshot is prepared for this world's queries first, in the caller's
        thread (:meth:`Environment.prepare`).
        """
        environment.prepare(self.geometry.shapes, self.margin(environment))
        with self._lock:
            if self._holds:
                self._waiting = environment
            else:
                self._swap(environment)

    def _swap(self, environment: Environment) -> None:
        """Make ``environment`` the current snapshot (the lock held)."""
        self._environment = environment
        self._waiting = None
        self.environment_version += 1

    @contextlib.contextmanager
    def holding(self) -> Iterator[Environment]:
        """Keep the current snapshot while a plan is made; yield it.

        A map that publishes from its own thread would otherwise swap the
        obstacles between two steps of one plan: a step validated against one
        snapshot from a depth measured in another is rejected, and the steps'
        contact rows change under the plan. The newest snapshot published
        meanwhile is taken when the (outermost) hold ends.
        """
        with self._lock:
            self._holds += 1
        try:
            yield self._environment
        finally:
            with self._lock:
                self._holds -= 1
                if not self._holds and self._waiting is not None:
                    self._swap(self._waiting)

    def margin(self, environment: Environment) -> float:
        """How far from the unpadded shapes obstacles are reported [m].

        The activation distance, plus the padding, plus the environment's
        resolution (an occupancy map's obstacles are inflated by half a cell).
        """
        return self.settings.activation_distance + self.padding + environment.resolution

    def contacts(self, state: RobotState) -> ContactSet:
        """Contacts at ``state`` (cached per configuration and environment).

        Includes, once, the contacts carried over from a rejected step
        (:meth:`carry_over`).
        """
        environment = self._environment
        key = state.q.tobytes()
        cache = self._cache
        if key != cache.key or environment is not cache.environment:
            cache.contacts = self.query(state, environment)
            cache.key, cache.environment = key, environment
        if len(self._carried):
            carried, self._carried = self._carried, ContactSet.empty()
            return ContactSet.concatenate([cache.contacts, carried])
        return cache.contacts

    def check(self, q: FloatArray) -> StepCheck:
        """Validate configuration ``q``: its contacts and whether the step is kept.

        A configuration with a NaN or infinite entry is never kept: it is
        rejected with an infinite penetration and no contacts.
        """
        q = np.asarray(q, dtype=float)
        if not math.isfinite(q.dot(q)):
            return StepCheck(False, math.inf, ContactSet.empty())
        state = self._state
        state.update(q)
        contacts = self.contacts(state)
        # Against each obstacle where it is: a moving one is measured nearer
        # for the contact rows (ContactSet.lead), not for the check.
        depth = contacts.present_penetration
        tolerance = self.settings.penetration_tolerance + self._environment.resolution
        return StepCheck(depth <= tolerance, depth, contacts)

    def try_step(self, q: FloatArray, current_penetration: float = 0.0) -> StepCheck:
        """Validate the step to ``q``; if it is rejected, constrain the retry.

        :meth:`check`, then :meth:`reject` when the step is not kept: every
        executor that validates its steps (CAT Sec. IV-C) calls this.

        Args:
            q: the configuration the step leads to.
            current_penetration: the penetration where the step starts [m]; a
                step that ends less deep than this is kept even beyond the
                tolerance (it backs out of contact).

        Returns:
            The check; ``accepted`` says whether the step is kept.
        """
        check = self.check(q)
        if check.accepted:
            return check
        if check.penetration < current_penetration:
            return StepCheck(True, check.penetration, check.contacts)
        self.reject(check)
        return check

    @property
    def sweep(self) -> SweepBound:
        """How far the robot's shapes move along joint-space segments.

        Raises ValueError (on first use) for a robot with joints other than
        revolute and prismatic ones.
        """
        return self._free.sweep

    @property
    def sweep_step(self) -> float:
        """The most a motion's checked configurations may be apart [m].

        By :attr:`sweep`'s bound: the padding, so that the unpadded robot
        keeps half of it between them (:mod:`cbp.collision.motion`); 2 mm
        when the links are not padded (then it may touch by up to 1 mm).
        """
        return self._free.sweep_step

    def motion_free(
        self,
        a: FloatArray,
        b: FloatArray,
        is_free: Callable[[FloatArray], bool] | None = None,
    ) -> bool:
        """Whether the straight joint-space motion from ``a`` to ``b`` is free.

        ``b``, then the configurations :attr:`sweep` places between them
        :attr:`sweep_step` apart, in order, are checked up to the first that
        is not free; ``a`` is not (the motion starts there). A motion that ends
        in collision is refused at its first check.

        Args:
            a: where the motion starts.
            b: where it ends.
            is_free: the check of one configuration (default :meth:`is_free`;
                planners pass one that charges their budget).
        """
        return self._free.motion_free(a, b, is_free or self.is_free)

    @property
    def against_map(self) -> bool:
        """Whether the obstacles are an occupancy map's (checks cost more)."""
        return getattr(self._environment, "blocked", None) is not None

    def is_free(self, q: FloatArray) -> bool:
        """Whether ``q`` is collision-free (planners, IK).

        Against declared objects, the same answer as ``check(q).penetration ==
        0``; against an occupancy map, by the rule CAT's step validation uses
        (:meth:`~cbp.collision.free_check.FreeCheck.is_free`).
        """
        return self._free.is_free(q, self._environment)

    def carry_over(self, contacts: ContactSet) -> None:
        """Add ``contacts`` (from a rejected configuration) to the next query.

        Contacts are points fixed on robot links with a world normal, so the ones
        found at a rejected configuration still constrain the step retried from the
        previous one: it cannot move those points into the obstacle again.
        """
        self._carried = ContactSet.concatenate([self._carried, contacts])

    def reject(self, check: StepCheck) -> None:
        """The checked step is not taken: its penetrating contacts constrain the retry.

        The contacts with negative distance found at the rejected configuration
        are carried over (:meth:`carry_over`) to the next query.
        """
        contacts = check.contacts
        self.carry_over(contacts.select(contacts.distance < 0))

    def shape_placements(self, state: RobotState) -> ShapePlacements:
        """Every robot shape's world placement at ``state``, in one pinocchio call."""
        oMg = self._pinocchio_placements(state)
        # By index: faster than iterating over pinocchio's vector.
        return ShapePlacements([oMg[i] for i in range(len(self.geometry.shapes))])

    def shape_frames(self, state: RobotState) -> FloatArray:
        """Every robot shape's world placement at ``state``, (n, 4, 4).

        :meth:`shape_placements` as homogeneous matrices only, for the
        compiled queries: from ``state.q`` in one compiled call
        (:mod:`cbp.collision.placements`), or read from pinocchio for a model
        with joints that call does not know.
        """
        if self._kinematics is not None:
            return self._kinematics(state.q)
        oMg = self._pinocchio_placements(state)
        count = len(self.geometry.shapes)
        return np.array([oMg[i].homogeneous for i in range(count)]).reshape(-1, 4, 4)

    def _pinocchio_placements(self, state: RobotState) -> pin.StdVec_SE3:
        """The shapes' placements in pinocchio's geometry data (``oMg``) at ``state``.

        Writes the world's own geometry data (another thread: :meth:`placed_apart`).
        """
        pin.updateGeometryPlacements(
            self.geometry.robot.model,
            state.data,
            self._geometry_model,
            self._geometry_data,
        )
        return self._geometry_data.oMg

    def shape_bounds(
        self, placements: ShapePlacements
    ) -> tuple[FloatArray, FloatArray]:
        """The shapes' bounding-sphere centres and world box half extents, (n, 3).

        The boxes are world-aligned boxes around the shapes' own bounding boxes,
        about the same centres, for the broad phases (:mod:`cbp.collision.broad`).
        """
        frames = placements.homogeneous
        centres, halves = np.empty((len(frames), 3)), np.empty((len(frames), 3))
        shape_bounds(frames, self._centres, self.geometry.box_halves, centres, halves)
        return centres, halves

    def query(
        self, state: RobotState, environment: Environment | None = None
    ) -> ContactSet:
        """Contacts at ``state`` against ``environment`` (default: the current one).

        Not cached, and without carried-over contacts: what :meth:`contacts`
        computes when its cache misses.
        """
        environment = environment or self._environment
        settings = self.settings
        if settings.narrow_phase == "compiled":
            pad2 = 2.0 * self.padding
            # A map's contacts on the shapes no joint moves are not wanted
            # (:meth:`_moving_part`): the map leaves them out.
            moving = self._moving if environment.resolution > 0.0 else None
            found = environment.query_with_self(
                WholeQuery(
                    frames=self.shape_frames(state),
                    table=self._table,
                    shapes=self.geometry.shapes,
                    margin=self.margin(environment),
                    per_shape=settings.contacts_per_link,
                    padding=self.padding + environment.resolution,
                    self_margin=settings.activation_distance + pad2,
                    self_padding=pad2,
                    moving=moving,
                )
            )
            if found is not None:
                return (
                    found
                    if moving is not None
                    else self._moving_part(found, environment)
                )
        robot = self.placed(state)
        margin, per_shape = self.margin(environment), settings.contacts_per_link
        # The default is not passed: an environment written before the setting
        # (its query without the argument) keeps working.
        obstacles = (
            environment.query(robot, margin, per_shape)
            if settings.narrow_phase == "compiled"
            else environment.query(robot, margin, per_shape, settings.narrow_phase)
        )
        own = self._own.measured(robot) if settings.self_collision else []
        # Occupancy maps: the surface is uncertain by half a cell, so obstacles
        # are inflated by that much (and step validation tolerates as much more).
        return self._moving_part(
            ContactSet.stack(obstacles, self.padding + environment.resolution, own),
            environment,
        )

    def _moving_part(
        self, contacts: ContactSet, environment: Environment
    ) -> ContactSet:
        """``contacts`` without a map's contacts on shapes no joint moves."""
        if environment.resolution <= 0.0 or not len(contacts) or not self._fixed.any():
            return contacts
        drop = self._fixed[contacts.shape] & (contacts.other_shape < 0)
        return contacts.select(~drop) if drop.any() else contacts

    def placed(self, state: RobotState) -> PlacedShapes:
        """The robot's shapes at ``state``: world placements and bounds."""
        return self._bounded(self.shape_placements(state))

    def placed_apart(self, state: RobotState) -> PlacedShapes:
        """:meth:`placed` from ``state``'s frames, without the world's buffers.

        For another thread (the map's): :meth:`placed` writes the world's
        pinocchio geometry data. ``state`` must have its frames placed.
        """
        oMf = state.data.oMf
        return self._bounded(
            ShapePlacements(
                [oMf[s.frame_id] * s.placement for s in self.geometry.shapes]
            )
        )

    def _bounded(self, placements: ShapePlacements) -> PlacedShapes:
        """The shapes at ``placements``, with their bounds."""
        centres, halves = self.shape_bounds(placements)
        return PlacedShapes(
            self.geometry.shapes, placements, centres, self.geometry.radii, halves
        )

    def self_contacts(self, robot: PlacedShapes) -> ContactSet:
        """The contacts between the robot's own shapes (padded distances).

        Args:
            robot: the shapes at a configuration (:meth:`placed`).
        """
        return self._own.contacts(robot)

    def __repr__(self) -> str:
        """Geometry, environment and settings."""
        return (
            f"CollisionWorld({self.geometry!r}, environment="
            f"{type(self._environment).__name__}, settings={self.settings!r})"
        )
