# SPDX-License-Identifier: Apache-2.0
r"""The plugin contract: a value f(q), its exact Jacobian, and (for constraints) bounds.

Conventions, fixed once for every plugin and executor:

* **The decision variable is the joint displacement** :math:`\Delta q` **over one
  step**, a tangent vector with ``nv`` entries: the next configuration is
  :math:`q \oplus \Delta q` (``pinocchio.integrate``). Velocity-level executors
  divide by the step duration :math:`\Delta t`: :math:`u = \Delta q / \Delta t`.
* **Jacobians are derivatives along tangent directions**:
  :math:`J = \partial f(q \oplus \delta) / \partial \delta` at :math:`\delta = 0`,
  shape ``(dim, nv)`` even when ``nq != nv``. Shared helpers express frame
  quantities in pinocchio's LOCAL_WORLD_ALIGNED frame.
* **Plugins are math only.** They never see the QP, the solver, weights, priorities,
  gains or the step duration. The engine owns, per entry, a ``weight``, a
  ``priority`` (``soft`` or ``hard``) and a feedback ``gain`` :math:`k \in [0, 1]`
  (per step) and turns plugins into QP rows:

  - a task (residual f driven toward 0) becomes the cost
    :math:`\|W (J \Delta q + k f)\|^2` when soft, the equality
    :math:`J \Delta q = -k f` when hard;
  - a constraint :math:`l \le f(q) \le u` becomes
    :math:`-k (f - l) \le J \Delta q \le -k (f - u)`: the feedback form
    :math:`\dot f \le -k (f - b)` of the orbit paper (Problem 4.2). With
    :math:`k = 1` a joint-limit constraint is CAT's
    :math:`q_{min} \le q + \Delta q \le q_{max}` (eq. 4); with :math:`k = 0` a
    contact constraint is :math:`n^T J \Delta q \ge 0` (eq. 5).

* **Compute methods are pure**: they change neither ``self`` nor the state.
  The one exception is :meth:`Plugin.prepare`, which the engine calls once per
  step, before any compute method, with the state at the start of the step. A
  plugin that needs the step's start (a small-step term anchored at the current
  configuration, contacts found by a collision query) latches it there.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import Any, ClassVar, Generic, NamedTuple, TypeVar

import numpy as np

from cbp.errors import ConfigError, PluginOutputError
from cbp.robot import FloatArray, RobotModel
from cbp.state import RobotState

__all__ = [
    "Constraint",
    "FloatArray",
    "Linearization",
    "ParamsT",
    "Plugin",
    "PluginParams",
    "Task",
]


@dataclasses.dataclass(frozen=True, kw_only=True)
class PluginParams:
    """Base of every plugin's parameter schema (a frozen, keyword-only dataclass).

    Subclasses declare one field per parameter, each with a type, a default when it
    has one, and a docstring that gives its unit in square brackets. Checks that need
    no robot go in ``__post_init__`` and raise :class:`~cbp.errors.ConfigError` with
    ``location`` set to the field name.
    """


ParamsT = TypeVar("ParamsT", bound=PluginParams)


class Linearization(NamedTuple):
    """A plugin's value and Jacobian at one configuration."""

    value: FloatArray
    """f(q), shape (dim,)."""
    jacobian: FloatArray
    """df/dq along tangent directions, shape (dim, nv)."""


class Plugin(abc.ABC, Generic[ParamsT]):
    """Common contract of tasks and constraints: a value f(q) and its Jacobian.

    Attributes:
        params: the validated parameters.
        robot: the model the plugin was bound to.
        name: the instance name (from the scenario entry, or the type name).
    """

    type_name: ClassVar[str]
    """Name used in YAML ``type:``; snake_case, unique within its kind."""
    Params: ClassVar[type[PluginParams]]
    """Parameter schema."""
    unit: ClassVar[str]
    """Unit of f, e.g. ``"m"``, ``"rad"``, ``"m|rad"`` (translation then rotation)."""
    default_gain: ClassVar[float] = 1.0
    """Feedback gain per step used when the scenario entry gives none."""
    constant_jacobian: bool = False
    """The Jacobian is the same at every configuration, whatever ``prepare`` and
    the plugin's targets latch (a joint-space term on a Euclidean model). The
    engine then computes it once and folds a soft task's share of the Hessian into
    a constant. :func:`cbp.testing.check_jacobian` verifies the claim."""

    def __init__(self, params: ParamsT, robot: RobotModel, name: str = "") -> None:
        """Bind the parameters to a robot; subclasses resolve names to indices here.

        Raises:
            ConfigError: the parameters are not this plugin's ``Params``, or do not
                fit the robot (unknown frame, ...); ``location`` names the field.
        """
        if not isinstance(params, self.Params):
            raise ConfigError(
                f"{type(self).__name__} takes {self.Params.__name__}, got "
                f"{type(params).__name__}"
            )
        self.params: ParamsT = params
        self.robot = robot
        self.name = name or self.type_name

    @property
    @abc.abstractmethod
    def dim(self) -> int:
        """Number of scalar rows (fixed for the plugin's lifetime)."""

    def prepare(self, state: RobotState, dt: float) -> None:
        """Latch what the step needs from its start; called once per step.

        Args:
            state: the state at the start of the step.
            dt: the duration of the step [s].
        """

    @abc.abstractmethod
    def compute_value(self, state: RobotState) -> FloatArray:
        """Return f(q), shape (dim,)."""

    @abc.abstractmethod
    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """Return df/dq along tangent directions, shape (dim, nv)."""

    def linearize(self, state: RobotState) -> Linearization:
        """Return value and Jacobian; override to share work between the two."""
        return Linearization(self.compute_value(state), self.compute_jacobian(state))

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Write f(q) into ``value`` (dim,) and its Jacobian into ``jacobian``.

        The engine calls this with its own buffers (the plugin's rows of the
        stacked QP), every step. The default copies :meth:`linearize`, checking
        the shapes. Override it to write in place where that saves work; an
        override must write every entry, and agree with :meth:`compute_value`
        and :meth:`compute_jacobian` (:func:`cbp.testing.check_jacobian`
        verifies both).

        Raises:
            PluginOutputError: the outputs have the wrong shapes.
        """
        out, jac = self.linearize(state)
        shape = getattr(out, "shape", None), getattr(jac, "shape", None)
        if shape != (value.shape, jacobian.shape):
            raise PluginOutputError(
                f"{self.name} ({self.type_name}): value has shape {np.shape(out)} "
                f"and Jacobian {np.shape(jac)}, expected {value.shape} and "
                f"{jacobian.shape}"
            )
        value[:] = out
        jacobian[:] = jac

    def value_into(self, state: RobotState, value: FloatArray) -> None:
        """Write f(q) into ``value`` (dim,); the engine's call for a constant Jacobian.

        As :meth:`linearize_into`: the default copies :meth:`compute_value`.

        Raises:
            PluginOutputError: the value has the wrong shape.
        """
        out = self.compute_value(state)
        if getattr(out, "shape", None) != value.shape:
            raise PluginOutputError(
                f"{self.name} ({self.type_name}): value has shape {np.shape(out)}, "
                f"expected {value.shape}"
            )
        value[:] = out

    def __repr__(self) -> str:
        """Type name, instance name and parameters."""
        return f"{type(self).__name__}(name={self.name!r}, params={self.params!r})"


class Task(Plugin[ParamsT]):
    r"""A residual f(q) that the engine drives toward zero.

    Soft: the cost :math:`\\|W (J \\Delta q + k f)\\|^2`. Hard: the equality
    :math:`J \\Delta q = -k f`.
    """

    def limit_step(self, desired: FloatArray) -> FloatArray:
        """Limit the desired change of f over one step (default: unchanged).

        Args:
            desired: :math:`-k f`, the change of f the engine asks for, shape (dim,).

        Returns:
            The change to ask for instead; a new array (do not modify ``desired``).
        """
        return desired


class Constraint(Plugin[ParamsT]):
    """A value f(q) kept within bounds: lower <= f(q) <= upper."""

    @abc.abstractmethod
    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """Return (lower, upper), each (dim,); ±inf allowed; equal for equality."""


AnyTask = Task[Any]
AnyConstraint = Constraint[Any]
AnyPlugin = Plugin[Any]
