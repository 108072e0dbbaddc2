# SPDX-License-Identifier: Apache-2.0
"""What every live page shares: a viser server, a stop button, an update loop."""

from __future__ import annotations

import abc
import logging
import threading
from typing import Generic, Protocol, TypeVar

from cbp.run import WallClockPacer

__all__ = ["UPDATE_RATE", "Page", "Session"]

log = logging.getLogger(__name__)

#: Page updates per second.
UPDATE_RATE = 20.0


class Session(Protocol):
    """What a page needs of any session: whether it still runs."""

    @property
    def running(self) -> bool:
        """Whether the session's loop runs."""
        ...


S = TypeVar("S", bound=Session)


class Page(abc.ABC, Generic[S]):
    """What both pages share: the server, its address, and an update loop.

    Subclasses build the scene and the panel and define :meth:`update`; the
    loop ends when the session stops running.

    Args:
        session: the session the page shows.
        host: where to serve.
        port: the port (0: any free one).
    """

    def __init__(self, session: S, host: str, port: int) -> None:
        """Start serving (the scene is built by the subclass)."""
        import viser

        self.session = session
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        #: A line at the top of the panel: what the session is doing as a whole
        #: (stopping, where it saved).
        self.notice = self.server.gui.add_markdown("")
        #: Set by the page's "stop and save" button.
        self.stopped = threading.Event()
        self._close = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The page's address."""
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def add_render_toggle(self) -> None:
        """A checkbox for shadows and image-based lighting, off to start with.

        A browser without a GPU renders WebGL in software on the cores the
        session runs on, where they cost most of a frame: headless Chromium
        showed the goal page at 0.1 frames/s with viser's defaults, 0.5
        without shadows and 2.2 without either, beside two other sessions'
        work (load average 14-19 on 2 cores). With a GPU they cost little;
        the operator turns them on.
        """
        self.lighting = self.server.gui.add_checkbox(
            "shadows and reflections", initial_value=False
        )
        self.lighting.on_update(lambda _: self._light(bool(self.lighting.value)))
        # Without the environment's light, what the lights miss would be black.
        self._ambient = self.server.scene.add_light_ambient("/ambient", intensity=1.5)
        self._light(False)

    def _light(self, rich: bool) -> None:
        scene = self.server.scene
        scene.configure_default_lights(True, cast_shadow=rich)
        scene.configure_environment_map(hdri="warehouse" if rich else None)
        self._ambient.visible = not rich

    def say(self, text: str) -> None:
        """Show ``text`` at the top of the panel (markdown)."""
        self.notice.content = text

    @abc.abstractmethod
    def update(self) -> None:
        """Bring the page up to date with the session."""

    def refresh(self) -> None:
        """:meth:`update`, sent to the browsers at once as one message batch.

        viser otherwise wakes its event loop for every message (a scene node's
        pose is one; an update sends dozens), each a switch between threads
        competing for the interpreter with the control loop, and holds what it
        queued for up to a 60 Hz window before sending it. Measured on the
        boards: an update took 34 ms (median) without the batch.
        """
        with self.server.atomic():
            self.update()
        self.server.flush()

    def run(self) -> None:
        """Update the page until :meth:`close`, the stop button or the session's end."""
        period = 1.0 / UPDATE_RATE
        # On a fixed schedule; an update that ran late is not made up.
        pacer = WallClockPacer(max_lag=period, wake=self._close)
        k = 0
        failing: str | None = None
        while not self._close.is_set() and not self.stopped.is_set():
            try:
                self.refresh()
            except Exception as exc:  # the page must not stop the session
                message = f"{type(exc).__name__}: {exc}"
                if message != failing:
                    log.warning("page update failed: %s", message)
                failing = message
            else:
                failing = None
            if not self.session.running:
                break
            k += 1
            pacer.wait_until(k * period)

    def start(self) -> None:
        """Update the page in a thread of its own."""
        self._thread = threading.Thread(target=self.run, name="page", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop updating and serving."""
        self._close.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.server.stop()
