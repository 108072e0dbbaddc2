# SPDX-License-Identifier: Apache-2.0
"""The array types of configurations and Jacobians, and rows of a tangent vector."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["FloatArray", "IndexRows", "IntArray", "compact_rows", "rows_count"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

#: Rows of a tangent vector: a slice or an array of indices.
IndexRows = slice | IntArray


def compact_rows(rows: IntArray) -> IndexRows:
    """Return ``rows`` as a slice when they are consecutive (cheaper to index with)."""
    if rows.size and np.array_equal(rows, np.arange(rows[0], rows[0] + rows.size)):
        return slice(int(rows[0]), int(rows[0] + rows.size))
    return rows


def rows_count(rows: IndexRows, n: int) -> int:
    """Number of entries ``rows`` selects from a vector of length ``n``."""
    return len(range(n)[rows]) if isinstance(rows, slice) else int(rows.size)
