# SPDX-License-Identifier: Apache-2.0
"""The page's device reader and the endpoint it streams to.

viser 1.1.1 runs no script of its own in its panel, but its HTML element
renders markup where an image's error handler runs (as the page's keyboard
shortcuts do): :func:`device_html` installs, once per page, a reader that
every :data:`SEND_PERIOD` reads the gamepad (``navigator.getGamepads()``) or
the 6-DOF mouse (WebHID: the "connect 6-DOF mouse" button asks for it once;
Chromium remembers the choice) and the keys held, and sends the state as JSON
over a websocket to a :class:`DeviceLink` served beside the page's server.
The link hands each state to a :class:`~cbp.teleop.device_driver.DeviceDriver`.

Browsers give the Gamepad API and WebHID to secure pages only: open the page
as ``http://localhost`` or ``http://127.0.0.1`` (through an SSH tunnel from
another machine), or behind HTTPS.
"""

from __future__ import annotations

import html
import json
import logging
import re
import socket
import threading
from pathlib import Path
from typing import Any

from cbp.errors import ConfigError
from cbp.teleop.device_driver import DeviceDriver
from cbp.teleop.devices import SPACEMOUSE_FULL, SPACEMOUSE_VENDORS, parse_state
from cbp.teleop.profiles import InputProfile

__all__ = [
    "READER",
    "SEND_PERIOD",
    "DeviceLink",
    "add_device_panel",
    "device_html",
    "page_origins",
]

log = logging.getLogger(__name__)

#: How often the page sends the device's state [ms].
SEND_PERIOD = 20
#: The largest message accepted [bytes].
MAX_MESSAGE = 1 << 14

#: The reader's script (installed once per page).
READER = Path(__file__).with_name("device_reader.js")


def _deadman_text(profile: InputProfile) -> str:
    """What the deadman is, in words: ``button 4``, ``key Shift``, or both."""
    deadman = profile.deadman
    return " or ".join(
        ([f"button {deadman.button}"] if deadman.button is not None else [])
        + ([f"key {deadman.key}"] if deadman.key is not None else [])
    )


def device_html(profile: InputProfile, port: int) -> str:
    """The panel's device section: a status line, and the reader that streams.

    Args:
        profile: the input profile (its device and deadman).
        port: the :class:`DeviceLink`'s port (on the page's host).
    """
    spacemouse = profile.device == "spacemouse"
    deadman = profile.deadman
    held = _deadman_text(profile)
    config = {
        "port": port,
        "device": profile.device,
        "period": SEND_PERIOD,
        "button": deadman.button,
        "key": deadman.key,
        "full": SPACEMOUSE_FULL,
        "vendors": list(SPACEMOUSE_VENDORS),
        "missing": (
            "6-DOF mouse: none yet (connect it below, in Chromium)"
            if spacemouse
            else "gamepad: none yet (plug one in and press any of its buttons)"
        ),
    }
    lines = READER.read_text(encoding="utf-8").splitlines()
    script = f"window.cbpDeviceConfig={json.dumps(config)};\n" + "\n".join(
        line for line in lines if not line.startswith("//")
    )
    connect = (
        '<button type="button" onclick="window.cbpConnectHid&&window.cbpConnectHid()">'
        "connect 6-DOF mouse</button>"
        if spacemouse
        else ""
    )
    return (
        '<div style="font-size: 0.85em">'
        f"<div>{html.escape(profile.device)}: hold {html.escape(held)} to move</div>"
        '<div id="cbp-device-status">the device reader starts...</div>'
        f"{connect}"
        f'<img src="" style="display:none" onerror="{html.escape(script)}">'
        "</div>"
    )


def page_origins(host: str, page_port: int) -> list[re.Pattern[str] | None]:
    """The origins a browser may stream from: the page's, on this machine's names.

    And None: a program that sends no origin.
    """
    names = {"localhost", "127.0.0.1", "[::1]", socket.gethostname()}
    if host not in ("", "0.0.0.0", "::"):
        names.add(f"[{host}]" if ":" in host else host)
    hosts = "|".join(sorted(re.escape(n) for n in names))
    return [re.compile(rf"https?://({hosts}):{page_port}", re.IGNORECASE), None]


class DeviceLink:
    """A websocket endpoint beside the page's server; the page streams to it.

    Each message is a device state (:func:`~cbp.teleop.devices.parse_state`);
    a malformed one is counted and dropped. Given the page's port, browsers
    connect only from the page (any other site open in the operator's
    browser could otherwise drive the robot): from an origin at that port on
    this machine's names (``localhost``, ``127.0.0.1``, ``[::1]``, its host
    name, ``host``). Programs that send no origin (a script) connect too.

    Args:
        driver: the driver that takes the states.
        host: where to serve (the page's host).
        port: the port (0: any free one).
        page_port: the page's port (None: browsers connect from any page).

    Attributes:
        port: the port served on.
        rejected: malformed messages dropped so far.
    """

    def __init__(
        self,
        driver: DeviceDriver,
        host: str = "127.0.0.1",
        port: int = 0,
        page_port: int | None = None,
    ):
        """Start serving in a thread of its own."""
        from websockets.sync.server import serve

        self.driver = driver
        self.rejected = 0
        self._server = serve(
            self._handle,
            host,
            port,
            max_size=MAX_MESSAGE,
            origins=None if page_port is None else page_origins(host, page_port),
        )
        self.port = int(self._server.socket.getsockname()[1])
        self._thread = threading.Thread(
            target=self._server.serve_forever, name="device-link", daemon=True
        )
        self._thread.start()

    def _handle(self, connection: Any) -> None:
        try:
            for message in connection:
                try:
                    state = parse_state(message)
                except ConfigError as exc:
                    if not self.rejected:
                        log.warning("a device state was dropped: %s", exc)
                    self.rejected += 1
                    continue
                self.driver.receive(state)
        except Exception as exc:  # a connection that breaks ends alone
            log.info("device connection closed: %s", exc)

    def close(self) -> None:
        """Stop serving."""
        self._server.shutdown()
        self._thread.join(5.0)


def add_device_panel(page: Any, profile: InputProfile, link: DeviceLink | None) -> None:
    """Add the device's section to a page's panel (the reader with it).

    Without a link (the server reads the device), what to hold only.
    """
    gui = page.server.gui
    with gui.add_folder("device"):
        if link is None:
            gui.add_markdown(
                f"{profile.device} (read by the server): hold "
                f"{_deadman_text(profile)} to move"
            )
        else:
            gui.add_html(device_html(profile, link.port))
