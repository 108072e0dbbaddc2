# SPDX-License-Identifier: Apache-2.0
"""A device's state and the command it makes through a profile (pure functions).

The page (or the server's HID reader) reports the device's state
(:class:`DeviceState`: axes, buttons, keys held; :func:`parse_state` reads the
page's message). Through an input profile it makes a command
(:func:`command`: dead band, :func:`shaped`, and scale), which moves the goal
(:func:`move_goal`, along the world's or the hand's axes) or is the user
velocity. :func:`deadman_held` says whether the state holds the profile's
deadman. :class:`~cbp.teleop.device_driver.DeviceDriver` applies them to a
session.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.robot import FloatArray
from cbp.teleop.profiles import AxisMap, DeadmanSpec

__all__ = [
    "SPACEMOUSE_FULL",
    "SPACEMOUSE_VENDORS",
    "DeviceState",
    "command",
    "deadman_held",
    "move_goal",
    "parse_state",
    "shaped",
]

#: Axes, buttons and keys a state may hold.
MAX_ENTRIES = 64
#: A button counts as pressed above this value.
PRESSED = 0.5
#: A 6-DOF mouse's axes read this much at full travel (3Dconnexion's range).
SPACEMOUSE_FULL = 350
#: The 6-DOF mice that may be opened: 3Dconnexion's USB vendor ids (old, new).
SPACEMOUSE_VENDORS = (0x046D, 0x256F)


@dataclass(frozen=True)
class DeviceState:
    """A device's state at one moment, as the page reads it.

    Attributes:
        axes: axis values, each in -1..1.
        buttons: button values, each in 0..1 (analog triggers in between).
        keys: the keyboard keys held (as the browser names them).
        device: the device's name (the Gamepad API's ``id``), for the log.
    """

    axes: tuple[float, ...] = ()
    buttons: tuple[float, ...] = ()
    keys: frozenset[str] = frozenset()
    device: str = ""


def parse_state(message: str | bytes) -> DeviceState:
    """A state from the page's JSON message.

    ``{"axes": [...], "buttons": [...], "keys": [...], "device": "..."}``;
    values out of range are clipped, a missing list is empty.

    Raises:
        ConfigError: not such an object, or a value that is not a finite number.
    """
    try:
        data = json.loads(message)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ConfigError(f"not JSON: {exc}", "device state") from None
    if not isinstance(data, dict):
        raise ConfigError(
            f"expected an object, got {type(data).__name__}", "device state"
        )

    def numbers(key: str, low: float) -> tuple[float, ...]:
        values = data.get(key, [])
        if not isinstance(values, list) or len(values) > MAX_ENTRIES:
            raise ConfigError(f"expected a list of at most {MAX_ENTRIES}", key)
        out = []
        for v in values:
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise ConfigError(f"expected numbers, got {v!r}", key)
            if not math.isfinite(v):
                raise ConfigError(f"expected finite numbers, got {v!r}", key)
            out.append(min(1.0, max(low, float(v))))
        return tuple(out)

    keys = data.get("keys", [])
    if (
        not isinstance(keys, list)
        or len(keys) > MAX_ENTRIES
        or not all(isinstance(k, str) for k in keys)
    ):
        raise ConfigError(f"expected a list of at most {MAX_ENTRIES} names", "keys")
    device = data.get("device", "")
    return DeviceState(
        axes=numbers("axes", -1.0),
        buttons=numbers("buttons", 0.0),
        keys=frozenset(keys),
        device=str(device)[:100],
    )


def shaped(value: float, dead_band: float) -> float:
    """A deflection past the dead band, rescaled to reach 1 at full travel.

    0 within ``dead_band`` of rest; beyond it the output grows linearly from 0
    (no jump at the band's edge) to +-1 at +-1. Pure.
    """
    magnitude = abs(value)
    if magnitude <= dead_band:
        return 0.0
    return math.copysign(min(1.0, (magnitude - dead_band) / (1.0 - dead_band)), value)


def _raw(mapping: AxisMap, state: DeviceState) -> float:
    """The mapped axis's or button's value; 0 when the device has no such one."""
    if mapping.axis is not None:
        return state.axes[mapping.axis] if mapping.axis < len(state.axes) else 0.0
    assert mapping.button is not None
    return state.buttons[mapping.button] if mapping.button < len(state.buttons) else 0.0


def command(
    mappings: tuple[AxisMap, ...],
    state: DeviceState,
    dead_band: float,
    components: tuple[str, ...],
) -> FloatArray:
    """The command a state makes through a profile's mappings. Pure.

    Args:
        mappings: the profile's ``goal`` or ``velocity`` mappings.
        state: the device's state.
        dead_band: the profile's dead band (fraction of full travel).
        components: the command's components, in order
            (:data:`~cbp.teleop.profiles.GOAL_COMPONENTS` or
            :data:`~cbp.teleop.profiles.VELOCITY_COMPONENTS`).

    Returns:
        One value per component: the sum of ``scale * shaped(value)`` of the
        mappings to it.
    """
    out = np.zeros(len(components))
    for mapping in mappings:
        out[components.index(mapping.to)] += mapping.scale * shaped(
            _raw(mapping, state), dead_band
        )
    return out


def move_goal(
    position: FloatArray, rotation: FloatArray, twist: FloatArray, dt: float, frame: str
) -> tuple[FloatArray, FloatArray]:
    """The goal moved by ``twist`` for ``dt``. Pure.

    Args:
        position: the goal's position (3,) [m].
        rotation: the goal's rotation (3, 3).
        twist: velocity (3,) [m/s] then rate (3,) [rad/s].
        dt: how long [s].
        frame: ``world`` (the twist is along the world's axes) or ``hand``
            (along the goal's own axes). Either way the goal turns about its
            own position.

    Returns:
        The new position and rotation.
    """
    velocity, rate = np.asarray(twist[:3], float), np.asarray(twist[3:], float)
    if frame == "hand":
        velocity, rate = rotation @ velocity, rotation @ rate
    return position + velocity * dt, pin.exp3(rate * dt) @ rotation


def deadman_held(spec: DeadmanSpec, state: DeviceState) -> bool:
    """Whether the state holds the deadman (its button or its key). Pure."""
    button = spec.button
    pressed = (
        button is not None
        and button < len(state.buttons)
        and state.buttons[button] > PRESSED
    )
    key = spec.key
    if key is not None and len(key) == 1:
        key = key.lower()  # the page names single letters in lower case
    return pressed or (key is not None and key in state.keys)
