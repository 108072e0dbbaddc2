# SPDX-License-Identifier: Apache-2.0
"""Input profiles: how a gamepad's or a 6-DOF mouse's state becomes a command.

A profile is a YAML file (schema :class:`InputProfile`, read with the strict
loader of scenarios: unknown keys, wrong types and bad values are reported
with the file and line). It names the device, the deadman (a device button or
a keyboard key that must be held for anything to move), the dead band, how
long the device's stream may fall silent, and two mappings: ``goal`` (a goal
session, CAT, IK, MP: device axes and analog buttons to the goal's twist, in
the world's or the hand's axes) and ``velocity`` (an input session, orbit and
pan object: to the camera-frame user velocity). The shipped profiles are
``scenarios/input/<name>.yaml`` (``cbp teleop --device gamepad``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from cbp.data import data_dir, is_file
from cbp.errors import ConfigError, ScenarioError
from cbp.schema import load_file

__all__ = [
    "DEVICES",
    "GOAL_COMPONENTS",
    "VELOCITY_COMPONENTS",
    "AxisMap",
    "DeadmanSpec",
    "GoalMap",
    "InputProfile",
    "VelocityMap",
    "load_profile",
    "shipped_profiles",
]

#: The devices a profile can describe (the page reads each its own way).
DEVICES = ("gamepad", "spacemouse")
#: A goal's twist: velocity along x, y, z [m/s], rates about them [rad/s].
GOAL_COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")
#: The user velocity of orbit and pan object, along the camera's axes [m/s]
#: (x along the line of sight; each configuration takes the axes it commands).
VELOCITY_COMPONENTS = ("x", "y", "z")
#: Device axes and buttons a profile may name (the Gamepad API's standard
#: layout has 4 axes and 17 buttons).
MAX_INDEX = 63
#: The longest silence a profile may allow [s].
MAX_TIMEOUT = 1.0


def _index(value: int | None, name: str) -> None:
    if value is not None and not 0 <= value <= MAX_INDEX:
        raise ConfigError(f"must be within 0..{MAX_INDEX}, got {value}", name)


@dataclass(frozen=True, kw_only=True)
class AxisMap:
    """One device axis (or analog button) to one command component."""

    to: str
    """The component it drives."""
    axis: int | None = None
    """The device axis (the Gamepad API's ``axes`` index; the 6-DOF mouse's
    0-2 translation x, y, z, 3-5 rotation about them), in -1..1."""
    button: int | None = None
    """... or the device button (its analog value, 0..1: a trigger)."""
    scale: float = 0.1
    """The command at full deflection [m/s or rad/s]; negative flips it."""

    def __post_init__(self) -> None:
        """One of axis and button; indices in range; a finite scale."""
        if (self.axis is None) == (self.button is None):
            raise ConfigError("give one of 'axis' and 'button'", "axis")
        _index(self.axis, "axis")
        _index(self.button, "button")
        if not math.isfinite(self.scale):
            raise ConfigError(f"must be finite, got {self.scale}", "scale")


@dataclass(frozen=True, kw_only=True)
class GoalMap(AxisMap):
    """A device axis or button to a component of the goal's twist."""

    to: Literal["x", "y", "z", "rx", "ry", "rz"]
    """Velocity along x, y, z [m/s] or rate about them [rad/s]."""


@dataclass(frozen=True, kw_only=True)
class VelocityMap(AxisMap):
    """A device axis or button to a component of the user velocity."""

    to: Literal["x", "y", "z"]
    """Camera-frame velocity along x (the line of sight), y or z [m/s]."""


@dataclass(frozen=True)
class DeadmanSpec:
    """What must be held for the device to move anything (either one, if both)."""

    button: int | None = None
    """A device button (pressed: value above one half)."""
    key: str | None = None
    """A keyboard key, as the browser names it (``Shift``, ``Control``, ``d``;
    a letter in either case)."""

    def __post_init__(self) -> None:
        """At least one of button and key."""
        if self.button is None and self.key is None:
            raise ConfigError("give a 'button', a 'key' or both", "button")
        _index(self.button, "button")
        if self.key is not None and not 0 < len(self.key) <= 20:
            raise ConfigError(f"a key name of 1-20 characters, got {self.key!r}", "key")


@dataclass(frozen=True)
class InputProfile:
    """An input profile: a device, its deadman, its dead band and its mappings."""

    device: Literal["gamepad", "spacemouse"]
    """The device: a gamepad (the browser's Gamepad API) or a 6-DOF mouse
    (WebHID in Chromium)."""
    deadman: DeadmanSpec
    """What must be held for motion; releasing it brakes to a stop."""
    description: str = ""
    """What the profile is for."""
    dead_band: float = 0.1
    """Deflections below this fraction of full travel count as none; above it
    the command grows from 0, so it does not jump at the band's edge."""
    timeout: float = 0.1
    """A device stream silent for longer than this brakes to a stop [s]."""
    frame: Literal["world", "hand"] = "world"
    """The goal's twist is along the world's axes or the hand's own."""
    goal: tuple[GoalMap, ...] = ()
    """Goal sessions: axes and buttons to the goal's twist."""
    velocity: tuple[VelocityMap, ...] = ()
    """Input sessions (orbit, pan): axes and buttons to the user velocity."""

    def __post_init__(self) -> None:
        """A dead band in [0, 1), a timeout in (0, 1] s."""
        if not 0.0 <= self.dead_band < 1.0:
            raise ConfigError(f"must be in [0, 1), got {self.dead_band}", "dead_band")
        if not 0.0 < self.timeout <= MAX_TIMEOUT:
            raise ConfigError(
                f"must be in (0, {MAX_TIMEOUT}] s, got {self.timeout}", "timeout"
            )


def shipped_profiles() -> list[str]:
    """Names of the profiles that ship with cbp (``gamepad``, ``spacemouse``)."""
    return sorted(p.stem for p in (data_dir("scenarios") / "input").glob("*.yaml"))


def load_profile(name_or_path: str | Path) -> InputProfile:
    """Read a profile file, or the shipped profile of that name.

    Raises:
        ScenarioError: the file's problems, each with its line; or no such
            file or shipped profile.
    """
    path = Path(name_or_path)
    if not is_file(path):
        text = str(name_or_path)
        shipped = data_dir("scenarios") / "input" / f"{text}.yaml"
        if "/" in text or "\\" in text or not is_file(shipped):
            names = ", ".join(shipped_profiles())
            raise ScenarioError(
                text, [f"no such file, nor a shipped input profile ({names})"]
            )
        path = shipped
    return load_file(InputProfile, path)
