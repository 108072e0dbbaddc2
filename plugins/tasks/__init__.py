# SPDX-License-Identifier: Apache-2.0
"""In-tree task plugins: the explicit, sorted registry ``TASKS``."""

from cbp.plugin import AnyTask, Task
from cbp.registry import Registry

from .camera_velocity_task import CameraVelocityTask
from .goal_pose_task import GoalPoseTask
from .joint_step_task import JointStepTask
from .posture_task import PostureTask

__all__ = [
    "TASKS",
    "CameraVelocityTask",
    "GoalPoseTask",
    "JointStepTask",
    "PostureTask",
]

#: Keep sorted by type name (checked at import).
TASKS: Registry[AnyTask] = Registry(
    "task", Task, [CameraVelocityTask, GoalPoseTask, JointStepTask, PostureTask]
)
