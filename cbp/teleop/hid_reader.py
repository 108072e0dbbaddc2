# SPDX-License-Identifier: Apache-2.0
"""A 6-DOF mouse read by the server (hidapi, the ``hid`` extra) instead of the page.

``cbp teleop SCENARIO --device spacemouse --hid`` opens the SpaceMouse in the
``cbp`` process (any browser then, or none), reads its input reports
(:func:`apply_report`, pure: the same layout the page's WebHID reader
parses) and hands the device's state to the
:class:`~cbp.teleop.device_driver.DeviceDriver` after every read, at least every
:data:`READ_TIMEOUT_MS`. A device that stops answering (unplugged) stops the
stream, and the driver brakes after the profile's timeout. Without the
keyboard, the deadman must be one of the device's buttons.
"""

from __future__ import annotations

import logging
import struct
import threading
from collections.abc import Sequence
from typing import Protocol

from cbp.errors import ConfigError
from cbp.teleop.device_driver import DeviceDriver
from cbp.teleop.devices import SPACEMOUSE_FULL, SPACEMOUSE_VENDORS, DeviceState
from cbp.teleop.profiles import InputProfile

__all__ = [
    "READ_TIMEOUT_MS",
    "HidDevice",
    "HidReader",
    "apply_report",
    "check_hid_profile",
    "open_spacemouse",
]

log = logging.getLogger(__name__)

#: A read waits at most this long for a report [ms]; the state is sent after
#: each read, so at least this often.
READ_TIMEOUT_MS = 20
#: The buttons a report 3 carries at most (its first 4 bytes).
BUTTONS = 32
#: The HID usage of a multi-axis controller (generic desktop page 1, usage 8).
MULTI_AXIS = (1, 8)


def apply_report(
    axes: tuple[float, ...], buttons: tuple[float, ...], report: Sequence[int]
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """A SpaceMouse's input report applied to its latest axes and buttons. Pure.

    Args:
        axes: the six axes before (translation x, y, z, rotation about them).
        buttons: the buttons before.
        report: the report, its id first (as hidapi reads it).

    Returns:
        The axes and buttons after: report 1 sets the translation (and on
        newer models the rotation too: 6 values), report 2 the rotation (each
        little-endian int16, over :data:`~cbp.teleop.devices.SPACEMOUSE_FULL`,
        clipped to -1..1), report 3 the buttons (a bit each); others change
        nothing.
    """
    if not report:
        return axes, buttons
    kind, data = report[0], bytes(report[1:])
    if kind == 3:
        bits = int.from_bytes(data[:4], "little")
        return axes, tuple(float((bits >> i) & 1) for i in range(BUTTONS))
    count = len(data) // 2
    values = struct.unpack_from(f"<{count}h", data)
    scaled = [max(-1.0, min(1.0, v / SPACEMOUSE_FULL)) for v in values]
    out = list(axes) + [0.0] * (6 - len(axes))
    if kind == 1:
        out[: min(count, 6)] = scaled[:6]
    elif kind == 2:
        out[3 : 3 + min(count, 3)] = scaled[:3]
    else:
        return axes, buttons
    return tuple(out), buttons


class HidDevice(Protocol):
    """What the reader needs of an open HID device (``hid.device``)."""

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        """The next input report (its id first), or [] after ``timeout_ms``."""
        ...

    def close(self) -> None:
        """Close the device."""
        ...


def open_spacemouse() -> tuple[HidDevice, str]:
    """Open the first SpaceMouse connected; the device and its name.

    Raises:
        ConfigError: hidapi is not installed, or no SpaceMouse is found (or
            it cannot be opened: on Linux its ``/dev/hidraw*`` must be
            readable by the user).
    """
    try:
        import hid
    except ImportError:
        raise ConfigError(
            "reading the 6-DOF mouse in the server needs hidapi: "
            "pip install 'cbp[hid]' (or drop --hid: the page reads it through WebHID)",
            "--hid",
        ) from None
    found = [d for d in hid.enumerate() if d["vendor_id"] in SPACEMOUSE_VENDORS]
    if not found:
        vendors = ", ".join(f"{v:04x}" for v in SPACEMOUSE_VENDORS)
        raise ConfigError(
            f"no SpaceMouse found (USB vendors {vendors}); on Linux its "
            "/dev/hidraw* must be readable by you (a udev rule)",
            "--hid",
        )
    # The multi-axis interface where there are several.
    found.sort(key=lambda d: (d.get("usage_page"), d.get("usage")) != MULTI_AXIS)
    info = found[0]
    device = hid.device()
    try:
        device.open_path(info["path"])
    except OSError as exc:
        raise ConfigError(
            f"cannot open {info.get('product_string') or 'the SpaceMouse'}: {exc} "
            "(on Linux its /dev/hidraw* must be readable by you: a udev rule)",
            "--hid",
        ) from None
    return device, str(info.get("product_string") or "SpaceMouse")


class HidReader:
    """Reads a 6-DOF mouse in a thread and streams its state to a driver.

    Args:
        driver: the driver that takes the states.
        device: the open device.
        name: its name (for the log).

    Attributes:
        reads: reads done so far.
        error: what ended the reading, if the device failed.
    """

    def __init__(self, driver: DeviceDriver, device: HidDevice, name: str) -> None:
        """Start reading."""
        self.driver = driver
        self.device = device
        self.name = name
        self.reads = 0
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hid", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        axes: tuple[float, ...] = (0.0,) * 6
        buttons: tuple[float, ...] = ()
        try:
            while not self._stop.is_set():
                report = self.device.read(64, READ_TIMEOUT_MS)
                self.reads += 1
                axes, buttons = apply_report(axes, buttons, report)
                self.driver.receive(DeviceState(axes, buttons, device=self.name))
        except Exception as exc:  # unplugged: the stream stops, the driver brakes
            self.error = exc
            log.warning("%s: reading stopped: %s", self.name, exc)

    def close(self) -> None:
        """Stop reading and close the device."""
        self._stop.set()
        self._thread.join(5.0)
        self.device.close()


def check_hid_profile(profile: InputProfile) -> None:
    """A profile the server can read: a 6-DOF mouse with a button deadman.

    Raises:
        ConfigError: another device, or a deadman of keys only.
    """
    if profile.device != "spacemouse":
        raise ConfigError(
            f"reads a 6-DOF mouse only; the profile is a {profile.device}'s", "--hid"
        )
    if profile.deadman.button is None:
        raise ConfigError(
            "the server sees no keyboard: with --hid the profile's deadman must "
            "be a device button",
            "deadman",
        )
