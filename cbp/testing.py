# SPDX-License-Identifier: Apache-2.0
"""Tools for plugin authors: a finite-difference Jacobian check, and sampling.

Use them in your own tests::

    from cbp.testing import check_jacobian, sample_configurations

    for q in sample_configurations(robot, np.random.default_rng(0), n=5):
        check_jacobian(MyConstraint(params, robot), robot, q)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from cbp.errors import JacobianMismatchError
from cbp.plugin import AnyPlugin
from cbp.robot import FloatArray, RobotModel
from cbp.state import RobotState

__all__ = ["JacobianReport", "check_jacobian", "sample_configurations"]


@dataclasses.dataclass(frozen=True)
class JacobianReport:
    """The outcome of one comparison.

    Attributes:
        analytic: the plugin's Jacobian (dim, nv).
        numeric: the central finite difference (dim, nv).
        max_error: largest |analytic - numeric| entry.
        worst: up to five (row, column, analytic, numeric) entries, worst first.
        passed: whether every entry is within ``atol + rtol * |numeric|``.
    """

    analytic: FloatArray
    numeric: FloatArray
    max_error: float
    worst: list[tuple[int, int, float, float]]
    passed: bool

    def describe(self, label: str = "") -> str:
        """A human-readable account of the worst entries."""
        lines = [f"{label}: max |analytic - numeric| = {self.max_error:.3g}"]
        lines += [
            f"  J[{row}, {col}]: analytic {a:+.6g}, numeric {n:+.6g}, "
            f"error {abs(a - n):.3g}"
            for row, col, a, n in self.worst
        ]
        return "\n".join(lines)


def numeric_jacobian(
    plugin: AnyPlugin,
    robot: RobotModel,
    q: FloatArray,
    eps: float = 1e-6,
) -> FloatArray:
    """Central finite difference of ``plugin.compute_value`` along tangent directions.

    Column i is (f(q ⊕ ε e_i) - f(q ⊕ -ε e_i)) / 2ε, with ⊕ pinocchio's integrate.
    The plugin must already be prepared at ``q``.
    """
    state = RobotState(robot, q)
    columns = []
    for i in range(robot.nv):
        step = np.zeros(robot.nv)
        step[i] = eps
        state.update(robot.integrate(q, step))
        plus = plugin.compute_value(state)
        state.update(robot.integrate(q, -step))
        minus = plugin.compute_value(state)
        columns.append((plus - minus) / (2.0 * eps))
    return np.array(columns).T.reshape(plugin.dim, robot.nv)


def check_jacobian(
    plugin: AnyPlugin,
    robot: RobotModel,
    q: FloatArray,
    *,
    eps: float = 1e-6,
    atol: float = 1e-6,
    rtol: float = 1e-5,
    dt: float = 0.01,
    label: str = "",
) -> JacobianReport:
    """Compare a plugin's analytic Jacobian with central finite differences at ``q``.

    The plugin is first prepared at ``q`` (step duration ``dt``), as the engine
    would at the start of a step; references it latches there stay fixed while the
    configuration is perturbed. The in-place calls the engine makes
    (:meth:`~cbp.plugin.Plugin.linearize_into`, ``value_into``) must write the
    same value and Jacobian as ``compute_value`` and ``compute_jacobian``.

    Args:
        plugin: the plugin to check (any task or constraint, in-tree or yours).
        robot: the model it is bound to.
        q: configuration (nq).
        eps: tangent step of the finite difference.
        atol: absolute tolerance per entry.
        rtol: tolerance relative to the numeric entry.
        dt: step duration passed to ``prepare``.
        label: a name for the report; default the plugin's.

    Returns:
        The report, when the check passes.

    Raises:
        JacobianMismatchError: an entry is off by more than ``atol + rtol |numeric|``
            (its message lists the worst entries), or the Jacobian's shape is wrong.
    """
    label = label or f"{plugin.name} ({plugin.type_name})"
    state = RobotState(robot, q)
    plugin.prepare(state, dt)
    analytic = np.asarray(plugin.compute_jacobian(state), dtype=float)
    if analytic.shape != (plugin.dim, robot.nv):
        raise JacobianMismatchError(
            f"{label}: Jacobian has shape {analytic.shape}, expected "
            f"({plugin.dim}, {robot.nv})"
        )
    numeric = numeric_jacobian(plugin, robot, state.q, eps)
    error = np.abs(analytic - numeric)
    allowed = atol + rtol * np.abs(numeric)
    order = np.argsort(-(error - allowed), axis=None)[:5]
    worst = [
        (int(r), int(c), float(analytic[r, c]), float(numeric[r, c]))
        for r, c in zip(*np.unravel_index(order, error.shape), strict=True)
    ]
    if plugin.constant_jacobian:
        _check_constant(plugin, robot, state.q, analytic, dt, atol, label)
    report = JacobianReport(
        analytic=analytic,
        numeric=numeric,
        max_error=float(error.max(initial=0.0)),
        worst=worst,
        passed=bool(np.all(error <= allowed)),
    )
    if not report.passed:
        raise JacobianMismatchError(
            report.describe(label)
            + f"\n  at q = {np.array2string(state.q, precision=4)}"
            + f"\n  tolerance: atol {atol:g} + rtol {rtol:g} * |numeric|"
        )
    _check_in_place(plugin, state, analytic, label)
    return report


def _check_in_place(
    plugin: AnyPlugin, state: RobotState, analytic: FloatArray, label: str
) -> None:
    """The engine's in-place calls write what compute_value and compute_jacobian return.

    Into every entry: the buffers start as NaN here.
    """
    value = np.asarray(plugin.compute_value(state), dtype=float)
    dim, nv = analytic.shape
    written = np.full(dim, np.nan), np.full((dim, nv), np.nan), np.full(dim, np.nan)
    plugin.linearize_into(state, written[0], written[1])
    plugin.value_into(state, written[2])
    for name, got, expected in (
        ("linearize_into's value", written[0], value),
        ("linearize_into's Jacobian", written[1], analytic),
        ("value_into's value", written[2], value),
    ):
        if not np.allclose(got, expected, rtol=1e-12, atol=1e-12):
            raise JacobianMismatchError(
                f"{label}: {name} differs from compute_value/compute_jacobian "
                f"(NaN: an entry left unwritten) at "
                f"q = {np.array2string(state.q, precision=4)}:\n"
                f"  written  {np.array2string(got, precision=6)}\n"
                f"  expected {np.array2string(expected, precision=6)}"
            )


def _check_constant(
    plugin: AnyPlugin,
    robot: RobotModel,
    q: FloatArray,
    analytic: FloatArray,
    dt: float,
    atol: float,
    label: str,
) -> None:
    """A plugin declaring ``constant_jacobian`` has the same Jacobian elsewhere."""
    # A fixed, generic tangent direction: every joint moves, by different amounts.
    delta = 0.3 * np.cos(1.0 + 2.3 * np.arange(robot.nv))
    other = RobotState(robot, robot.integrate(q, delta))
    plugin.prepare(other, dt)
    try:
        moved = np.asarray(plugin.compute_jacobian(other), dtype=float)
    finally:
        plugin.prepare(RobotState(robot, q), dt)
    if moved.shape != analytic.shape or not np.allclose(moved, analytic, atol=atol):
        raise JacobianMismatchError(
            f"{label}: declares constant_jacobian, but its Jacobian changes between "
            f"q = {np.array2string(q, precision=4)} and "
            f"q ⊕ {np.array2string(delta, precision=2)}"
        )


def sample_configurations(
    robot: RobotModel,
    rng: np.random.Generator,
    n: int = 5,
    *,
    margin: float = 0.05,
    accept: Callable[[FloatArray], bool] | None = None,
    max_tries: int = 1000,
) -> list[FloatArray]:
    """Draw ``n`` configurations inside the limits (shrunk by ``margin``).

    Args:
        robot: the model.
        rng: the random generator (seed it for reproducible tests).
        n: number of configurations.
        margin: distance kept from every finite limit [rad or m], so that central
            differences stay inside the limits.
        accept: optional filter, e.g. to keep away from a plugin's singularity.
        max_tries: draws allowed before giving up.

    Raises:
        RuntimeError: ``accept`` rejected too many draws.
    """
    samples: list[FloatArray] = []
    for _ in range(max_tries):
        q = robot.random_configuration(rng, margin=margin)
        if accept is None or accept(q):
            samples.append(q)
            if len(samples) == n:
                return samples
    raise RuntimeError(
        f"only {len(samples)} of {n} configurations accepted after {max_tries} draws"
    )
