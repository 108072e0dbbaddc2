# SPDX-License-Identifier: Apache-2.0
"""The compiled pass that turns the stacked plugin outputs into the QP (numba).

:class:`~cbp.qp.QPAssembler` cuts every float array it fills from one buffer
and describes where each lies in an integer layout; :func:`fill_qp` reads
both and writes H, g, A and the bounds in place.
"""

from __future__ import annotations

import math

import numba

from cbp.qp.problem import BoolArray
from cbp.robot import FloatArray, IntArray

__all__ = [
    "BOUNDS_NAN",
    "COST_NOT_FINITE",
    "ROWS_NOT_FINITE",
    "ROW_KINDS",
    "SIZES",
    "fill_qp",
]

# The layout read by fill_qp: 6 sizes, then 18 offsets, then the rows' kinds.
SIZES = 6
ROW_KINDS = SIZES + 18

# Bits of the status returned by fill_qp.
COST_NOT_FINITE = 1
ROWS_NOT_FINITE = 2
BOUNDS_NAN = 4


@numba.njit(cache=True, nogil=True)
def fill_qp(floats: FloatArray, layout: IntArray, equality: BoolArray) -> int:
    r"""Turn the stacked plugin outputs into the QP, in place; return a status.

    The arrays are cut from two buffers made once per problem shape by
    :class:`QPAssembler`: ``floats`` holds every float array, ``layout`` the
    sizes (nv, n, soft rows, constant soft rows, rows m, slacks), the offset
    of each float array in ``floats`` (in :func:`_fill_arrays`'s order), then
    the task rows (m, 0 or 1) and the slack rows. Three arguments rather than
    twenty-two: numba's dispatch costs about 50 ns per array argument.
    See :func:`_fill_arrays` for what is computed.
    """
    nv, n, ms, mc = layout[0], layout[1], layout[2], layout[3]
    m, ns = layout[4], layout[5]
    at = layout[SIZES:ROW_KINDS]  # the float arrays' offsets
    rows = m + 2 * ns
    return _fill_arrays(
        nv,
        _cut(floats, at[0], n, n),
        _cut(floats, at[1], n, n),
        floats[at[2] : at[2] + n],
        _cut(floats, at[3], ms, nv),
        floats[at[4] : at[4] + ms],
        floats[at[5] : at[5] + ms],
        _cut(floats, at[6], nv, mc),
        floats[at[7] : at[7] + mc],
        floats[at[8] : at[8] + mc],
        _cut(floats, at[9], m, nv),
        floats[at[10] : at[10] + m],
        floats[at[11] : at[11] + m],
        floats[at[12] : at[12] + m],
        floats[at[13] : at[13] + m],
        layout[ROW_KINDS : ROW_KINDS + m],
        floats[at[14] : at[14] + m],
        layout[ROW_KINDS + m : ROW_KINDS + m + ns],
        _cut(floats, at[15], rows, n),
        floats[at[16] : at[16] + rows],
        floats[at[17] : at[17] + rows],
        equality,
    )


@numba.njit(cache=True, nogil=True, inline="always")
def _cut(floats: FloatArray, start: int, rows: int, cols: int) -> FloatArray:
    """The (rows, cols) matrix at ``start`` of the buffer (a view)."""
    return floats[start : start + rows * cols].reshape((rows, cols))


@numba.njit(cache=True, nogil=True)
def _fill_arrays(
    nv: int,
    H_base: FloatArray,
    H: FloatArray,
    g: FloatArray,
    soft_J: FloatArray,
    soft_weights: FloatArray,
    soft_desired: FloatArray,
    constant_JtW: FloatArray,
    constant_step: FloatArray,
    constant_scale: FloatArray,
    J: FloatArray,
    f: FloatArray,
    given_lower: FloatArray,
    given_upper: FloatArray,
    gains: FloatArray,
    task_rows: IntArray,
    desired: FloatArray,
    slack_rows: IntArray,
    A: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    equality: BoolArray,
) -> int:
    r"""The arithmetic of :func:`fill_qp`, on its arrays.

    Cost, over the joint block: :math:`H = H_0 + J_s^T W J_s` and
    :math:`g = -(J_s^T W d_s + (J_c^T W_c) d_c)`, with :math:`d = -k f` after the
    tasks' step limits (soft tasks s, constant-Jacobian soft tasks c, whose
    :math:`J_c^T W_c J_c` is already in :math:`H_0`); :math:`d_c` is
    ``constant_step * constant_scale``: f and -k, or (when a task there limits
    its step) the limited step and ones.

    Rows: A = J; a constraint row's bounds are :math:`k (l - f)` and
    :math:`k (u - f)`, except that an infinite bound stays infinite when k = 0;
    a hard task's are :math:`d` on both sides. Each soft constraint row's upper
    side moves to its own row (``slack_rows``, laid out by the assembler).

    The status is 0, or a sum of bits: ``COST_NOT_FINITE`` (a soft task's
    Jacobian or step), ``ROWS_NOT_FINITE`` (a row's value or Jacobian),
    ``BOUNDS_NAN`` (a constraint's bound).
    """
    status = 0
    for a in range(nv):
        for b in range(nv):
            H[a, b] = H_base[a, b]
        g[a] = 0.0
    for i in range(soft_J.shape[0]):
        w, d = soft_weights[i], soft_desired[i]
        if not math.isfinite(d):
            status |= COST_NOT_FINITE
        for a in range(nv):
            wa = w * soft_J[i, a]
            if not math.isfinite(wa):
                status |= COST_NOT_FINITE
            g[a] -= wa * d
            for b in range(nv):
                H[a, b] += wa * soft_J[i, b]
    for i in range(constant_step.size):
        d = constant_step[i] * constant_scale[i]
        if not math.isfinite(d):
            status |= COST_NOT_FINITE
        for a in range(nv):
            g[a] -= constant_JtW[a, i] * d
    m = f.size
    for r in range(m):
        if not math.isfinite(f[r]):
            status |= ROWS_NOT_FINITE
        for c in range(nv):
            v = J[r, c]
            if not math.isfinite(v):
                status |= ROWS_NOT_FINITE
            A[r, c] = v
        if task_rows[r]:
            lower[r] = upper[r] = desired[r]
            continue
        k, lo, up = gains[r], given_lower[r], given_upper[r]
        if math.isnan(lo) or math.isnan(up):
            status |= BOUNDS_NAN
        lower[r] = lo if k == 0.0 and math.isinf(lo) else k * (lo - f[r])
        upper[r] = up if k == 0.0 and math.isinf(up) else k * (up - f[r])
    for j in range(slack_rows.size):
        r = slack_rows[j]
        for c in range(nv):
            A[m + j, c] = J[r, c]
        upper[m + j] = upper[r]
        upper[r] = math.inf
    for r in range(lower.size):
        equality[r] = lower[r] == upper[r]
    return status
