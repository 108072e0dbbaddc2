# SPDX-License-Identifier: Apache-2.0
"""PyBullet, imported once without its build banner.

PyBullet's C extension prints "pybullet build time: ..." when it is first
imported, before any of cbp's own output; every ``cbp`` command would start
with it. The import here sends the process's standard output and error to
/dev/null at the file-descriptor level (where C writes), flushes C's buffers,
and restores both at once. Modules import ``pb`` from here.
"""

from __future__ import annotations

import ctypes
import os
import sys
from typing import Any

__all__ = ["pb"]


def _import_quietly() -> Any:
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            import pybullet

            ctypes.CDLL(None).fflush(None)  # C's buffers, while they go nowhere
    finally:
        for fd, copy in zip((1, 2), saved, strict=True):
            os.dup2(copy, fd)
            os.close(copy)
    return pybullet


pb = _import_quietly()
