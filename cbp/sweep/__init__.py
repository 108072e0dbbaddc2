# SPDX-License-Identifier: Apache-2.0
"""Sweeps: many runs across scenes, methods and settings, on Ray or a pool.

``cbp sweep SWEEP.yaml --out DIR`` (:func:`run_sweep`); the file format is in
:mod:`cbp.sweep.spec`, the outputs in :mod:`cbp.sweep.results`.
"""

from cbp.sweep.runner import SweepOutcome, run_sweep
from cbp.sweep.spec import RunSpec, SweepSpec, load_sweep

__all__ = ["RunSpec", "SweepOutcome", "SweepSpec", "load_sweep", "run_sweep"]
