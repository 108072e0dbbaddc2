# SPDX-License-Identifier: Apache-2.0
"""A recording that does not grow in memory: fixed-width rows spooled to disk.

A simulation records a row of numbers every few physics steps for as long as it
runs; an operator's session can run for hours. :class:`Recorder` keeps one
block of rows in memory and appends each full block to an unnamed temporary
file, so memory stays flat during the run (a block is 4096 rows: 0.8 MB for
the Panda's 25 columns) and the disk holds 200 bytes per sample (144 MB per
simulated hour at the default 200 samples per second).
:meth:`Recorder.array` reads the whole recording back once, at the end.
"""

from __future__ import annotations

import tempfile
from typing import IO

import numpy as np

from cbp.robot import FloatArray

__all__ = ["Recorder"]


class Recorder:
    """Rows of ``width`` floats, spooled to a temporary file in blocks.

    Args:
        width: numbers per row.
        block_rows: rows kept in memory before a block is written out.
    """

    def __init__(self, width: int, block_rows: int = 4096) -> None:
        """An empty recording."""
        self.width = width
        self._block = np.empty((block_rows, width))
        self._filled = 0
        self._spooled = 0
        self._file: IO[bytes] | None = None

    def __len__(self) -> int:
        """Rows recorded."""
        return self._spooled + self._filled

    def row(self) -> FloatArray:
        """The next row to fill in (a view into the block); it counts at once."""
        if self._filled == len(self._block):
            self._spool()
        row: FloatArray = self._block[self._filled]
        self._filled += 1
        return row

    def _spool(self) -> None:
        if self._file is None:
            # Held open for the run and closed by close(): no context manager.
            self._file = tempfile.TemporaryFile(prefix="cbp-recording-")  # noqa: SIM115
        self._file.write(self._block[: self._filled].tobytes())
        self._spooled += self._filled
        self._filled = 0

    def array(self) -> FloatArray:
        """Every row recorded so far, (len, width), as one new array."""
        out = np.empty((len(self), self.width))
        if self._file is not None:
            self._file.flush()
            self._file.seek(0)
            out[: self._spooled] = np.frombuffer(
                self._file.read(self._spooled * self.width * 8), dtype=float
            ).reshape(self._spooled, self.width)
            self._file.seek(0, 2)
        out[self._spooled :] = self._block[: self._filled]
        return out

    def close(self) -> None:
        """Delete the spool file (the recording is gone)."""
        if self._file is not None:
            self._file.close()
            self._file = None
