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

**Writing a plugin.** Subclass :class:`Task` or :class:`Constraint`, naming the
parameter schema as the generic argument, and define ``dim``,
``compute_value`` and ``compute_jacobian`` (constraints: ``compute_bounds``)::

    @dataclass(frozen=True, kw_only=True)
    class HandAboveParams(PluginParams):
        height: float = 0.3  # lowest hand height [m]

    class HandAboveConstraint(Constraint[HandAboveParams]):
        unit = "m"
        dim = 1
        ...

The class is checked when Python defines it (:meth:`Plugin.__init_subclass__`),
with the same rules whether it is then used from Python or from a scenario:

* ``Params`` is read from the generic argument (``Constraint[HandAboveParams]``):
  a frozen, keyword-only dataclass derived from :class:`PluginParams`;
* ``type_name``, the name scenarios write in ``type:``, defaults to the class
  name in snake_case without its ``Task`` / ``Constraint`` suffix
  (``HandAboveConstraint`` -> ``hand_above``); if given, it must be snake_case;
* ``unit`` is optional: the unit of f, one per block of rows joined by ``|``
  (``"m"``, ``"rad"``, ``"m|rad"``), ``""`` when dimensionless or mixed;
* ``default_gain`` is in [0, 1];
* the constructor takes ``(params, robot, name="")``;
* :meth:`Plugin.prepare` is the only method that may change the plugin.

Optional capabilities are the protocols of :mod:`cbp.capabilities`, exported
here too (:class:`GoalReceiver`, :class:`TakesInput`, :class:`DescribesInput`,
:class:`UsesCollisionWorld`, :class:`HoldsContacts`, :class:`ReportsSignals`): a
plugin has one by defining its methods, and executors test for it with
``isinstance``. Writing rows in place (:meth:`Plugin.linearize_into`,
:meth:`Plugin.value_into`) is an optional speed-up, not part of the contract;
:class:`cbp.joint_space.JointDifference` does it for joint-space terms.
"""

from __future__ import annotations

import abc
import dataclasses
import inspect
import re
import typing
from typing import (
    Any,
    ClassVar,
    Generic,
    Literal,
    NamedTuple,
    TypeVar,
)

import numpy as np

from cbp.capabilities import (
    DescribesInput,
    GoalReceiver,
    HoldsContacts,
    InputValue,
    MovingBounds,
    ReportsSignals,
    TakesInput,
    UsesCollisionWorld,
)
from cbp.errors import (
    ConfigError,
    PluginDefinitionError,
    PluginOutputError,
    TargetNotSetError,
)
from cbp.robot import FloatArray, RobotModel
from cbp.state import RobotState

__all__ = [
    "Constraint",
    "DescribesInput",
    "FloatArray",
    "GoalReceiver",
    "HoldsContacts",
    "InputValue",
    "Linearization",
    "MovingBounds",
    "ParamsT",
    "Plugin",
    "PluginParams",
    "ReportsSignals",
    "RobotLimit",
    "TakesInput",
    "Task",
    "UsesCollisionWorld",
]


@dataclasses.dataclass(frozen=True, kw_only=True)
class PluginParams:
    """Base of every plugin's parameter schema (a frozen, keyword-only dataclass).

    Subclasses declare one field per parameter, each with a type, a default when it
    has one, and a docstring that gives its unit in square brackets. Checks that need
    no robot go in ``__post_init__`` and raise :class:`~cbp.errors.ConfigError` with
    ``location`` set to the field name. A plugin without parameters uses
    ``PluginParams`` itself.
    """


#: The robot limits an entry may keep (:attr:`Plugin.robot_limit`).
RobotLimit = Literal["position", "velocity", "acceleration"]
ParamsT = TypeVar("ParamsT", bound=PluginParams)
T = TypeVar("T")


class Linearization(NamedTuple):
    """A plugin's value and Jacobian at one configuration."""

    value: FloatArray
    """f(q), shape (dim,)."""
    jacobian: FloatArray
    """df/dq along tangent directions, shape (dim, nv)."""


# ---------------------------------------------------------------- definition checks

_SNAKE = re.compile(r"^[a-z][a-z0-9_]*$")
_SUFFIXES = ("_task", "_constraint")


def default_type_name(class_name: str) -> str:
    """``HandAboveConstraint`` -> ``hand_above``: snake_case, kind suffix removed."""
    name = class_name.lstrip("_")
    snake = re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", name)
    snake = snake.lower()
    for suffix in _SUFFIXES:
        if snake.endswith(suffix) and len(snake) > len(suffix):
            return snake[: -len(suffix)]
    return snake


def _generic_params(cls: type) -> list[object]:
    """The generic arguments ``cls`` gives its plugin bases (``Task[X]`` -> X)."""
    found: list[object] = []
    for base in cls.__dict__.get("__orig_bases__", ()):
        origin = typing.get_origin(base)
        if isinstance(origin, type) and issubclass(origin, Plugin):
            found.extend(typing.get_args(base)[:1])
    return found


def _check_definition(cls: type[Plugin[Any]]) -> None:
    """Fill in the defaults of a plugin class and check the rest (one message)."""
    name = cls.__qualname__
    generic = _generic_params(cls)
    if any(isinstance(arg, TypeVar) for arg in generic):
        return  # a generic base such as Task[ParamsT]: its subclasses are checked
    cls.Params = _params_schema(cls, generic)
    if "type_name" not in cls.__dict__:
        cls.type_name = default_type_name(cls.__name__)
    if not isinstance(cls.type_name, str) or not _SNAKE.match(cls.type_name):
        raise PluginDefinitionError(
            f"plugin {name}: type_name {cls.type_name!r} is not snake_case: use "
            "lower-case letters, digits and underscores, starting with a letter "
            f"(it is what scenarios write in 'type:'), e.g. "
            f"'{default_type_name(cls.__name__)}', or leave it out for that default"
        )
    if not isinstance(cls.unit, str):
        raise PluginDefinitionError(
            f"plugin {name}: unit must be a string such as 'm', 'rad' or 'm|rad' "
            f"(one per block of rows), or left out; got {cls.unit!r}"
        )
    if cls.robot_limit not in (None, *typing.get_args(RobotLimit)):
        raise PluginDefinitionError(
            f"plugin {name}: robot_limit must be one of "
            f"{', '.join(typing.get_args(RobotLimit))} or None (not a limit of "
            f"the robot), got {cls.robot_limit!r}"
        )
    gain = cls.default_gain
    if not (isinstance(gain, int | float) and 0.0 <= gain <= 1.0):
        raise PluginDefinitionError(
            f"plugin {name}: default_gain must be a number in [0, 1], got {gain!r}"
        )
    missing = [
        what
        for attr, what in _REQUIRED
        if getattr(getattr(cls, attr, None), "__isabstractmethod__", False)
    ]
    if missing:
        raise PluginDefinitionError(
            f"plugin {name} does not define {'; '.join(missing)}"
        )
    try:
        inspect.signature(cls.__init__).bind(None, None, None, name="")
    except TypeError:
        raise PluginDefinitionError(
            f"plugin {name}: the constructor must accept (params, robot, name=''), "
            f"got {cls.__name__}{inspect.signature(cls.__init__)}"
        ) from None


def _params_schema(cls: type[Plugin[Any]], generic: list[object]) -> type[PluginParams]:
    """The parameter schema a plugin class names (its generic argument).

    Raises:
        PluginDefinitionError: none, two, or one that is not a frozen
            PluginParams dataclass; the message says how to declare it.
    """
    name = cls.__qualname__
    declared = cls.__dict__.get("Params")
    params = generic[0] if generic else declared or getattr(cls, "Params", None)
    how = (
        f"declare its parameters as the generic argument: class {cls.__name__}"
        f"(Task[{cls.__name__}Params]) or (Constraint[...]), where "
        f"{cls.__name__}Params is a @dataclass(frozen=True, kw_only=True) "
        "subclass of cbp.PluginParams (PluginParams itself when there are none)"
    )
    if params is None:
        raise PluginDefinitionError(f"plugin {name} has no parameter schema: {how}")
    named = {p for p in (*generic, declared) if p is not None}
    if len(named) > 1:
        names = sorted(getattr(p, "__name__", repr(p)) for p in named)
        raise PluginDefinitionError(
            f"plugin {name} names two parameter schemas ({', '.join(names)}): "
            f"{how}; a Params attribute is not needed"
        )
    if not (
        isinstance(params, type)
        and issubclass(params, PluginParams)
        and "__dataclass_params__" in vars(params)  # a dataclass of its own
        and params.__dataclass_params__.frozen  # type: ignore[attr-defined]
    ):
        raise PluginDefinitionError(
            f"plugin {name}: {getattr(params, '__name__', params)!s} is not a "
            f"frozen PluginParams dataclass: {how}"
        )
    return params


_REQUIRED = (
    ("dim", "dim (the number of rows: a property, or an int class attribute)"),
    ("compute_value", "compute_value(self, state) -> f(q), shape (dim,)"),
    (
        "compute_jacobian",
        "compute_jacobian(self, state) -> df/dq along tangent directions, "
        "shape (dim, nv)",
    ),
    (
        "compute_bounds",
        "compute_bounds(self, state) -> (lower, upper), each shape (dim,)",
    ),
)


class Plugin(abc.ABC, Generic[ParamsT]):
    """Common contract of tasks and constraints: a value f(q) and its Jacobian.

    Attributes:
        params: the validated parameters.
        robot: the model the plugin was bound to.
        name: the instance name (from the scenario entry, or the type name).
    """

    type_name: ClassVar[str]
    """Name used in YAML ``type:``; snake_case. Default: the class name in
    snake_case without its ``Task`` or ``Constraint`` suffix."""
    Params: ClassVar[type[PluginParams]]
    """Parameter schema, read from the generic argument (``Task[MyParams]``)."""
    unit: ClassVar[str] = ""
    """Unit of f, one per block of rows joined by ``|``: ``"m"``, ``"rad"``,
    ``"m|rad"`` (translation then rotation); ``""`` when dimensionless."""
    default_gain: ClassVar[float] = 1.0
    """Feedback gain per step used when the scenario entry gives none, in [0, 1]."""
    constant_jacobian: bool = False
    """The Jacobian is the same at every configuration, whatever ``prepare`` and
    the plugin's targets latch (a joint-space term on a Euclidean model). The
    engine then computes it once and folds a soft task's share of the Hessian into
    a constant. :func:`cbp.testing.check_jacobian` verifies the claim."""
    easable: ClassVar[bool] = True
    """Whether the engine may ease this entry's hard rows when the QP is
    infeasible (:meth:`cbp.engine.Engine.step`). False for a physical limit of
    the robot, which no easing makes true (``joint_acceleration``)."""
    robot_limit: ClassVar[RobotLimit | None] = None
    """Which of the robot's own limits this entry keeps, if it is one:
    ``position`` (joint ranges), ``velocity`` or ``acceleration``. Executors ask
    for this, not for a type name: velocity and acceleration limits bound a
    step's size and are not obstacles to the goal (CAT's stall detection), and
    the step guard checks the acceleration limits whether or not an entry
    keeps them."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Check the contract when the class is defined (see the module docstring).

        Raises:
            PluginDefinitionError: one message saying what to add or change.
        """
        super().__init_subclass__(**kwargs)
        _check_definition(cls)

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

        The only method that may change the plugin.

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

    def latched(self, value: T | None) -> T:
        """``value`` latched by :meth:`prepare`; an error if it was not called.

        Raises:
            TargetNotSetError: ``prepare`` has not run yet.
        """
        if value is None:
            raise TargetNotSetError(
                f"{self.name} ({self.type_name}): prepare() was not called"
            )
        return value

    def linearize(self, state: RobotState) -> Linearization:
        """Value and Jacobian in new arrays, through the engine's own call."""
        value, jacobian = np.empty(self.dim), np.empty((self.dim, self.robot.nv))
        self.linearize_into(state, value, jacobian)
        return Linearization(value, jacobian)

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Write f(q) into ``value`` (dim,) and its Jacobian into ``jacobian``.

        Optional speed-up. The engine calls this with its own buffers (the
        plugin's rows of the stacked QP), every step. The default copies
        :meth:`compute_value` and :meth:`compute_jacobian`, checking the shapes.
        An override must write every entry and agree with them
        (:func:`cbp.testing.check_jacobian` verifies both).

        Raises:
            PluginOutputError: the outputs have the wrong shapes.
        """
        out, jac = self.compute_value(state), self.compute_jacobian(state)
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

        Optional speed-up, as :meth:`linearize_into`: the default copies
        :meth:`compute_value`.

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

    def limit_step_into(self, desired: FloatArray) -> None:
        """Limit the desired change in place; the engine's call every step.

        Optional speed-up, as :meth:`linearize_into`: the default writes
        :meth:`limit_step`'s answer over ``desired``. An override must agree
        with :meth:`limit_step`.
        """
        limited = self.limit_step(desired)
        if limited is not desired:
            desired[:] = limited


class Constraint(Plugin[ParamsT]):
    """A value f(q) kept within bounds: lower <= f(q) <= upper."""

    @abc.abstractmethod
    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """Return (lower, upper), each (dim,); ±inf allowed; equal for equality."""


AnyTask = Task[Any]
AnyConstraint = Constraint[Any]
AnyPlugin = Plugin[Any]
