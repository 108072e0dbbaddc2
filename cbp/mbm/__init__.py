# SPDX-License-Identifier: Apache-2.0
"""MotionBenchMaker's Panda problem families as a source of cbp scenarios.

MotionBenchMaker (Chamzas et al., RA-L 2022; Kavraki Lab, BSD-3-Clause)
describes a family of motion-planning problems by a nominal scene, random
variations of its objects' poses, start and goal queries given relative to
named objects, and depth sensors. This package reads those files from a
MotionBenchMaker checkout (:mod:`.files`), samples scenes and queries as its
generator does (:mod:`.sampling`) and writes the valid problems as CAT
scenarios with the declared objects and two camera placements
and two camera placements (:mod:`.problems`, :mod:`.cameras`):
``cbp scenes --mbm DIR``.
"""

from cbp.mbm.files import Family, family_names, read_family
from cbp.mbm.problems import (
    Problem,
    make_problem,
    scenes_command,
    write_problems,
)
from cbp.mbm.sampling import query_pose, sample_scene

__all__ = [
    "Family",
    "Problem",
    "family_names",
    "make_problem",
    "query_pose",
    "read_family",
    "sample_scene",
    "scenes_command",
    "write_problems",
]
