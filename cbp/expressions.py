# SPDX-License-Identifier: Apache-2.0
"""Functions of time written in scenario files: ``"0.1 * sin(2 * pi * 0.5 * t)"``.

An expression is parsed with :mod:`ast` and accepted only if it uses numbers,
the variable ``t`` [s], the constants ``pi`` and ``e``, arithmetic
(``+ - * / ** %``), comparisons inside ``where(cond, a, b)``, and the functions
listed in :data:`FUNCTIONS`. Anything else (attribute access, names, lambdas,
indexing) is rejected when the scenario loads, with the offending part named.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable

import numpy as np

from cbp.errors import ConfigError, suggestion

__all__ = ["FUNCTIONS", "TimeFunction", "compile_time_function"]


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
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ConfigError(f"not an expression: {text!r} ({exc.msg})", where) from None
    names = ("t", *_CONSTANTS, *FUNCTIONS)
    for node in ast.walk(tree):
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
        if isinstance(node, ast.Constant) and not isinstance(node.value, int | float):
            raise ConfigError(f"only numbers are allowed, got {node.value!r}", where)
    code = compile(tree, f"<{where or 'expression'}>", "eval")
    namespace = {"__builtins__": {}, **_CONSTANTS, **FUNCTIONS}

    def evaluate(t: float) -> float:
        return float(eval(code, namespace, {"t": t}))

    try:
        value = evaluate(0.0)
    except (ArithmeticError, ValueError, TypeError) as exc:
        raise ConfigError(f"{text!r} fails at t = 0: {exc}", where) from None
    if not np.isfinite(value):
        raise ConfigError(f"{text!r} is not finite at t = 0", where)
    return evaluate
