# SPDX-License-Identifier: Apache-2.0
"""The engine: one QP per step, its step guard, and the easing of infeasible QPs.

:class:`Engine` assembles and solves the QP of a step (:mod:`.engine`) and
returns a :class:`StepResult`: the step, and whether and how it was eased
(:mod:`.recovery`) or slowed; every answer passes the step guard
(:mod:`.guard`), which refuses an unsafe one with
:class:`~cbp.errors.UnsafeStepError`.
"""

from cbp.engine.engine import Engine, StepResult
from cbp.engine.guard import GARBAGE_RATIO, StepGuard
from cbp.engine.recovery import Easing

__all__ = ["GARBAGE_RATIO", "Easing", "Engine", "StepGuard", "StepResult"]
