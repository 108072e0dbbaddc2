# SPDX-License-Identifier: Apache-2.0
"""Functions of time written in scenario files: ``"0.1 * sin(2 * pi * 0.5 * t)"``.

An expression is parsed with :mod:`ast` and accepted only if it uses numbers,
the variable ``t`` [s], the constants ``pi`` and ``e``, arithmetic
(``+ - * / ** %``), comparisons inside ``where(cond, a, b)``, and the functions
listed in :data:`FUNCTIONS`. Anything else (attribute access, names, lambdas,
indexing) is rejected when the scenario loads, with the offending part named.

An expression's cost is bounded: at most :data:`MAX_LENGTH` characters and
:data:`MAX_NODES` parts, and every number is a float, so ``9**9**9`` overflows
at once instead of computing a number of 370 million digits. The loader also
evaluates each expression at every time the run will (:func:`check_over`), so a
division by zero at t = 1 s is an error before the run starts.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Sequence

from cbp.errors import ConfigError, suggestion

__all__ = [
    "FUNCTIONS",
    "MAX_LENGTH",
    "MAX_NODES",
    "TimeFunction",
    "check_over",
    "compile_time_function",
    "run_times",
]

#: Longest expression accepted [characters].
MAX_LENGTH = 1000
#: Most syntax-tree parts in one expression.
MAX_NODES = 400
#: Most times :func:`check_over` evaluates an expression at.
MAX_CHECKS = 200_000


def _smoothstep(x: float) -> float:
    """0 before 0, 1 after 1, 3x^2 - 2x^3 in between."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


FUNCTIONS: dict[str, Callable[..., float]] = {
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "exp": math.exp,
    "log": math.log,
    "sqrt": math.sqrt,
    "tanh": math.tanh,
    "abs": abs,
    "min": min,
    "max": max,
    "clip": lambda x, lo, hi: min(max(x, lo), hi),
    "smoothstep": _smoothstep,
    "where": lambda cond, a, b: a if cond else b,
}
"""Functions an expression may call."""

_CONSTANTS = {"pi": math.pi, "e": math.e}
_NODES = (
    ast.Expression,
    ast.BinOp,
    ast.UnaryOp,
    ast.Compare,
    ast.Call,
    ast.Name,
    ast.Load,
    ast.Constant,
    ast.Add,
    ast.Sub,
    ast.Mult,
    ast.Div,
    ast.Pow,
    ast.Mod,
    ast.USub,
    ast.UAdd,
    ast.Lt,
    ast.LtE,
    ast.Gt,
    ast.GtE,
)

#: A compiled expression: value at time t [s].
TimeFunction = Callable[[float], float]


def compile_time_function(text: str | float, where: str = "") -> TimeFunction:
    """Compile an expression of ``t``; a number is a constant function.

    Raises:
        ConfigError: syntax error, or a part that is not allowed (at ``where``).
    """
    if isinstance(text, int | float):
        value = float(text)
        if not math.isfinite(value):
            raise ConfigError(f"must be finite, got {value}", where)
        return lambda t: value
    if len(text) > MAX_LENGTH:
        raise ConfigError(
            f"expression of {len(text)} characters; at most {MAX_LENGTH}", where
        )
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError) as exc:
        reason = exc.msg if isinstance(exc, SyntaxError) else "nested too deeply"
        raise ConfigError(
            f"not an expression: {_short(text)} ({reason})", where
        ) from None
    names = ("t", *_CONSTANTS, *FUNCTIONS)
    nodes = list(ast.walk(tree))
    if len(nodes) > MAX_NODES:
        raise ConfigError(
            f"expression has {len(nodes)} parts; at most {MAX_NODES}", where
        )
    for node in nodes:
        if not isinstance(node, _NODES):
            raise ConfigError(
                f"{type(node).__name__} is not allowed in {text!r}; use numbers, t, "
                f"pi, e, + - * / ** % and {', '.join(FUNCTIONS)}",
                where,
            )
        if isinstance(node, ast.Name) and node.id not in names:
            raise ConfigError(
                f"unknown name '{node.id}' in {text!r}{suggestion(node.id, names)}"
                " Names: t, pi, e.",
                where,
            )
        if isinstance(node, ast.Call) and not (
            isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS
        ):
            called = node.func.id if isinstance(node.func, ast.Name) else "?"
            raise ConfigError(
                f"unknown function '{called}' in {text!r}"
                f"{suggestion(called, list(FUNCTIONS))} Functions: "
                f"{', '.join(FUNCTIONS)}.",
                where,
            )
        if isinstance(node, ast.Constant):
            if not isinstance(node.value, int | float) or isinstance(node.value, bool):
                raise ConfigError(
                    f"only numbers are allowed, got {node.value!r}", where
                )
            try:
                # Floats only: powers overflow instead of growing without bound.
                node.value = float(node.value)
            except OverflowError:
                raise ConfigError(
                    f"the number in {text!r} is too large", where
                ) from None
    try:
        code = compile(tree, f"<{where or 'expression'}>", "eval")
    except (RecursionError, MemoryError):
        raise ConfigError(
            f"not an expression: {text!r} (nested too deeply)", where
        ) from None
    namespace = {"__builtins__": {}, **_CONSTANTS, **FUNCTIONS}

    def evaluate(t: float) -> float:
        return float(eval(code, namespace, {"t": t}))

    evaluate.text = text  # type: ignore[attr-defined]
    check_over(evaluate, [0.0], where)
    return evaluate


def _short(text: str) -> str:
    """``text`` quoted, cut to 60 characters for messages."""
    return repr(text) if len(text) <= 60 else repr(text[:57] + "...")


def run_times(duration: float, rate_hz: float) -> list[float]:
    """The times ``k / rate_hz`` in ``[0, duration]``: when a run samples an input.

    Longer runs are thinned evenly to :data:`MAX_CHECKS` times (the last kept).
    """
    count = math.floor(duration * rate_hz + 1e-9) + 1
    stride = max(1, -(-count // MAX_CHECKS))
    times = [k / rate_hz for k in range(0, count, stride)]
    if (count - 1) % stride:
        times.append((count - 1) / rate_hz)
    return times


def check_over(function: TimeFunction, times: Sequence[float], where: str = "") -> None:
    """Evaluate ``function`` at ``times``; the first failure is a ConfigError.

    The loader passes the times a run will evaluate the expression at
    (:func:`run_times`), so an expression that divides by zero or leaves its
    domain during the run is refused before it starts.

    Raises:
        ConfigError: the expression raises or is not finite at one of ``times``.
    """
    text = getattr(function, "text", "expression")
    for t in times:
        try:
            value = function(t)
        except OverflowError:
            raise ConfigError(f"{text!r} overflows at t = {t:g} s", where) from None
        except (ArithmeticError, ValueError, TypeError) as exc:
            raise ConfigError(f"{text!r} fails at t = {t:g} s: {exc}", where) from None
        if not math.isfinite(value):
            raise ConfigError(f"{text!r} is not finite at t = {t:g} s", where)
