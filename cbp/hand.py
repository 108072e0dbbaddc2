# SPDX-License-Identifier: Apache-2.0
"""An arm's hand and gripper, found in its kinematic tree.

``cbp robot init`` moves the hand, not a finger, and locks the gripper's joints
(:func:`find_hand`). Two or more short chains that branch off the arm's last
joint are a gripper (a Panda's two fingers, a four-bar gripper's knuckles), and
so are trailing joints named like fingers (:data:`GRIPPER_WORDS`) on a single
chain; the hand is the link the gripper joints are attached to. Without a
gripper, the end is the last link of the longest chain.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pinocchio as pin

__all__ = ["GRIPPER_WORDS", "Hand", "find_hand", "mimic_joints"]


@dataclass(frozen=True)
class Hand:
    """Where an arm ends: the frame to move, and the gripper joints past it.

    Attributes:
        frame: the hand (or the last link, without a gripper).
        gripper_joints: the joints of the fingers, in tree order.
        reason: why this frame, as said to the user.
    """

    frame: str
    gripper_joints: tuple[str, ...]
    reason: str


#: Words that mark a joint of a gripper when the fingers do not branch.
GRIPPER_WORDS = ("finger", "gripper", "jaw", "knuckle")
#: A branching counts as a gripper when it has at most this many joints...
_GRIPPER_MAX_JOINTS = 8
#: ... none further than this from the branching joint.
_GRIPPER_MAX_DEPTH = 3


def find_hand(model: pin.Model) -> Hand:
    """The hand of an arm and its gripper joints (see the module docstring)."""
    children: list[list[int]] = [[] for _ in range(model.njoints)]
    depth = [0] * model.njoints
    for j in range(1, model.njoints):
        children[model.parents[j]].append(j)
        depth[j] = depth[model.parents[j]] + 1
    leaves = [j for j in range(1, model.njoints) if not children[j]]
    gripper: list[int] = []
    if len(leaves) > 1:
        common = set.intersection(*(set(model.supports[j]) for j in leaves))
        branch = max(common, key=lambda j: depth[j])
        below = [j for j in range(1, model.njoints) if branch in model.supports[j]]
        below.remove(branch)
        if (
            branch > 0
            and len(below) <= _GRIPPER_MAX_JOINTS
            and max(depth[j] - depth[branch] for j in below) <= _GRIPPER_MAX_DEPTH
        ):
            gripper = below
    else:
        chain = list(model.supports[leaves[0]])[1:]
        while len(chain) > 1 and any(
            w in model.names[chain[-1]].lower() for w in GRIPPER_WORDS
        ):
            gripper.insert(0, chain.pop())
    if not gripper:
        return Hand(
            _last_link(model),
            (),
            "the last link of the longest chain (--end-effector to choose another)",
        )
    names = tuple(str(model.names[j]) for j in gripper)
    first = min(gripper, key=lambda j: depth[j])
    hand = _parent_body(model, first)
    beyond = _frames_fixed_beyond(model, hand)
    also = f"; frames fixed to it: {', '.join(beyond)}" if beyond else ""
    return Hand(
        hand,
        names,
        f"the link the gripper joints ({', '.join(names)}) are attached to, not a "
        f"finger{also} (--end-effector to choose another)",
    )


def mimic_joints(urdf: Path) -> dict[str, tuple[str, float, float]]:
    """The URDF's mimic joints: joint -> (driver, multiplier, offset)."""
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError):
        return {}
    found = {}
    for joint in root.iter("joint"):
        mimic = joint.find("mimic")
        if mimic is None or not mimic.get("joint"):
            continue
        try:
            factor = float(mimic.get("multiplier", 1.0))
            offset = float(mimic.get("offset", 0.0))
        except ValueError:
            continue
        found[joint.get("name", "")] = (str(mimic.get("joint")), factor, offset)
    return found


def _parent_body(model: pin.Model, joint: int) -> str:
    """The body frame a joint is attached to."""
    frame = model.frames[model.getFrameId(model.names[joint], pin.FrameType.JOINT)]
    while model.frames[frame.parentFrame].type != pin.FrameType.BODY:
        frame = model.frames[frame.parentFrame]
    return str(model.frames[frame.parentFrame].name)


def _frames_fixed_beyond(model: pin.Model, body: str) -> list[str]:
    """Body frames fixed (no joint between) further out than ``body``: tool frames."""
    start = model.getFrameId(body, pin.FrameType.BODY)
    found = []
    for i, frame in enumerate(model.frames):
        if frame.type != pin.FrameType.BODY or i == start:
            continue
        k = i
        while k not in (0, start) and model.frames[k].type != pin.FrameType.JOINT:
            k = model.frames[k].parentFrame
        if k == start:
            found.append(str(frame.name))
    return found


def _last_link(model: pin.Model) -> str:
    """The body frame of the deepest joint (most joints from the root)."""
    depth = [0] * model.njoints
    for j in range(1, model.njoints):
        depth[j] = depth[model.parents[j]] + 1
    deepest = max(range(1, model.njoints), key=lambda j: (depth[j], j))
    # The last body frame attached to that joint (links fixed to it included).
    bodies = [
        f.name
        for f in model.frames
        if f.parentJoint == deepest and f.type == pin.FrameType.BODY
    ]
    return str(bodies[-1])
