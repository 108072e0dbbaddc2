# SPDX-License-Identifier: Apache-2.0
"""The exception hierarchy of cbp: one base class, a flat set of subclasses."""

from __future__ import annotations

import difflib
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

T = TypeVar("T")
A = TypeVar("A")


def close_matches(name: str, choices: Iterable[str], n: int = 3) -> list[str]:
    """Return up to ``n`` entries of ``choices`` that look like ``name``."""
    return difflib.get_close_matches(name, list(choices), n=n, cutoff=0.5)


def suggestion(name: str, choices: Iterable[str]) -> str:
    """Return "; did you mean 'x'?" for the nearest choice, or an empty string."""
    matches = close_matches(name, choices, n=1)
    return f"; did you mean '{matches[0]}'?" if matches else ""


def close_matches_hint(name: str, choices: Iterable[str]) -> str:
    """Return "; close matches: a, b" for the choices like ``name``, or ""."""
    matches = close_matches(name, choices)
    return f"; close matches: {', '.join(matches)}" if matches else ""


class CbpError(Exception):
    """Base class of every error raised by cbp."""


class ConfigError(CbpError, ValueError):
    """A configuration value is invalid.

    Attributes:
        location: where the value came from, e.g. ``tasks[0].params.frame``; empty
            when the value came from Python code rather than a file.
    """

    def __init__(self, message: str, location: str = "") -> None:
        """Store the message and where the bad value sits."""
        self.message = message
        self.location = location
        super().__init__(f"{location}: {message}" if location else message)


def require_choice(
    value: str, choices: Iterable[str], kind: str, location: str
) -> None:
    """Raise a located ConfigError unless ``value`` is one of ``choices``.

    The message names the nearest choice and lists them all:
    ``unknown solver 'daq'; did you mean 'daqp'? Solvers: daqp, piqp, cvxpy.``
    """
    allowed = list(choices)
    if value not in allowed:
        raise ConfigError(
            f"unknown {kind} '{value}'{suggestion(value, allowed)} "
            f"{kind.capitalize()}s: {', '.join(allowed)}.",
            location,
        )


def require(obj: object, condition: str, *names: str) -> None:
    """Check fields of a settings object; a located ConfigError for the first bad one.

    ``condition`` is one of ``> 0``, ``>= 0``, ``>= 1`` and ``in (0, 1]``.
    """
    tests: dict[str, Callable[[float], bool]] = {
        "> 0": lambda v: v > 0,
        ">= 0": lambda v: v >= 0,
        ">= 1": lambda v: v >= 1,
        "in (0, 1]": lambda v: 0 < v <= 1,
    }
    test = tests[condition]
    for name in names:
        value = getattr(obj, name)
        if not test(value):
            raise ConfigError(f"must be {condition}, got {value}", name)


def require_between(obj: object, lo: float, hi: float, unit: str, *names: str) -> None:
    """Check fields of a settings object lie in ``[lo, hi]`` (finite, sane ranges).

    Durations, rates and steps use it, so that ``duration: .inf`` or
    ``dt: 1e-300`` is refused at load instead of giving a run that never ends.
    """
    for name in names:
        value = getattr(obj, name)
        if not lo <= value <= hi:
            raise ConfigError(f"must be in [{lo:g}, {hi:g}] {unit}, got {value}", name)


def located(lookup: Callable[[A], T], name: A, location: str) -> T:
    """Call ``lookup(name)``; a ConfigError it raises gets ``location`` attached.

    Plugins use it to resolve a parameter (a frame or joint name) so that the error
    names the parameter: ``located(robot.frame_id, params.frame, "frame")``.
    """
    try:
        return lookup(name)
    except ConfigError as exc:
        raise type(exc)(exc.message, location=location) from None


class ScenarioError(CbpError):
    """A scenario file has one or more problems; all of them are listed."""

    def __init__(self, path: str, problems: Sequence[str]) -> None:
        """Collect every problem found in the file at ``path``."""
        self.path = path
        self.problems = list(problems)
        super().__init__(_listed(path, self.problems))


def _listed(path: str, problems: Sequence[str]) -> str:
    """``path: N problems:`` and the problems, one an indented line."""
    noun = "problem" if len(problems) == 1 else "problems"
    lines = "\n".join(f"  {p}" for p in problems)
    return f"{path}: {len(problems)} {noun}:\n{lines}"


class DataFileError(ConfigError):
    """A data file a scenario names (a recorded goal) has problems, each located.

    Attributes:
        path: the file.
        problems: every problem, each with its place in the file (``row 3,
            column 5 (qx): ...``).
    """

    def __init__(self, path: str, problems: Sequence[str], location: str = "") -> None:
        """Collect the problems of the file at ``path``, named at ``location``."""
        self.path = path
        self.problems = list(problems)
        super().__init__(_listed(path, self.problems), location)


class UnknownPluginError(ConfigError):
    """A plugin type name is not registered."""


class FrameNotFoundError(ConfigError):
    """A frame name does not exist in the robot model."""


class JointNotFoundError(ConfigError):
    """A joint name does not exist in the robot model."""


class RobotNotFoundError(ConfigError):
    """No robot description folder with that name."""


class PluginDefinitionError(CbpError, TypeError):
    """A plugin class breaks the plugin contract (raised when Python defines it)."""


class TargetNotSetError(CbpError):
    """A plugin was evaluated before its target was set."""


class InvalidTargetError(CbpError, ValueError):
    """A target has the wrong shape or is not finite (e.g. a NaN goal)."""


class PluginOutputError(CbpError):
    """A plugin returned a value, Jacobian or bound of the wrong shape or not finite."""


class SolveError(CbpError):
    """The QP could not be solved.

    Attributes:
        problem: the assembled problem (a :class:`cbp.qp.QPProblem`).
        status: the solver's own status, as text.
        conflicting: names of the entries whose rows could not be met together,
            found by a relaxed solve with slack variables; empty when unknown.
        infeasible: whether the solver found the problem infeasible (rather
            than failing on it).
    """

    def __init__(
        self,
        message: str,
        *,
        problem: Any = None,
        status: str = "",
        conflicting: Sequence[str] = (),
        infeasible: bool = False,
    ) -> None:
        """Keep the problem and the solver's answer for post-mortem."""
        self.problem = problem
        self.status = status
        self.conflicting = list(conflicting)
        self.infeasible = infeasible
        super().__init__(message)


class UnsafeStepError(SolveError):
    """The QP's answer is not a step the robot may take (the step guard).

    Raised like a failed solve, so every executor holds the robot: the step is
    non-finite, faster than a joint's velocity limit allows for the step's
    duration, or takes a joint beyond its limit. The message says which joint
    and by how much.
    """


class InvalidStateError(CbpError, ValueError):
    """An engine was given a configuration or duration it cannot step from."""


class JacobianMismatchError(CbpError, AssertionError):
    """A plugin's analytic Jacobian disagrees with finite differences."""
