# SPDX-License-Identifier: Apache-2.0
"""What every live page shares: a viser server, a stop button, an update loop.

A page is updated when its session changes, not on a timer: the session tells
it at each change (a command period's end, a new goal) and the page's thread
wakes and sends the change at once, at most :data:`MAX_UPDATE_RATE` times a
second; without changes it updates at :data:`IDLE_UPDATE_RATE` (the readout's
clock, a session that has stopped). What must be seen first (the robot's
pose, :meth:`Page.update_first`) goes ahead of each update as a message batch
of its own, and at each change between updates too, without waiting for the
rate's interval.
"""

from __future__ import annotations

import abc
import logging
import threading
import time
from collections.abc import Callable
from typing import Any, Generic, Protocol, TypeVar

from cbp.teleop.failures import Guarded

__all__ = ["IDLE_UPDATE_RATE", "MAX_UPDATE_RATE", "Page", "Session"]

log = logging.getLogger(__name__)

#: The most page updates per second: a change is sent at once unless the
#: last update was less than this rate's interval ago (then at its end). Each
#: update costs the session's interpreter and the browser's rendering, on the
#: cores the control loop runs on.
MAX_UPDATE_RATE = 50.0
#: Page updates per second while the session tells of no change.
IDLE_UPDATE_RATE = 5.0


class Session(Protocol):
    """What a page needs of any session: whether it still runs."""

    @property
    def running(self) -> bool:
        """Whether the session's loop runs."""
        ...

    def listen(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` (from any thread) whenever the session changes."""
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
        # The panel docked beside the scene, not floating over it: a browser
        # without a GPU draws and composites the scene in software, and a
        # narrower canvas with nothing over it costs it less per frame.
        self.server.gui.main_panel.dock_right()
        #: A line at the top of the panel: what the session is doing as a whole
        #: (stopping, where it saved).
        self.notice = self.server.gui.add_markdown("")
        #: Set by the page's "stop and save" button.
        self.stopped = threading.Event()
        self._close = threading.Event()
        #: Set when the session changed (or the page closes): update now.
        self._changed = threading.Event()
        #: Page updates made so far (each one message batch to the browsers).
        self.updates = 0
        #: Batches of :meth:`update_first` alone sent between updates so far.
        self.first_sent = 0
        #: Why each update was made: ``change`` (the session told of one) or
        #: ``idle`` (none for :data:`IDLE_UPDATE_RATE`'s interval), the latest
        #: last (up to 100).
        self.update_causes: list[str] = []
        self._thread: threading.Thread | None = None
        session.listen(self._changed.set)

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

    def update_first(self) -> bool:
        """Send what the operator must see first (the robot's pose); whether any.

        Called ahead of each :meth:`update` and at each change of the
        session between updates; its messages go to the browsers at once,
        as a batch of their own. Nothing here; pages that draw a robot say.
        """
        return False

    def send_first(self) -> bool:
        """:meth:`update_first` as a message batch of its own, sent at once."""
        with self.server.atomic():
            sent = self.update_first()
        if sent:
            self.server.flush()
        return sent

    def _send_between(self) -> None:
        if self.send_first():
            self.first_sent += 1

    def refresh(self) -> None:
        """:meth:`update`, sent to the browsers at once as one message batch.

        viser otherwise wakes its event loop for every message (a scene node's
        pose is one; an update sends dozens), each a switch between threads
        competing for the interpreter with the control loop, and holds what it
        queued for up to a 60 Hz window before sending it. Measured on the
        boards: an update took 34 ms (median) without the batch. What
        :meth:`update_first` sends goes ahead, in a batch of its own.
        """
        self.send_first()
        with self.server.atomic():
            self.update()
        self.server.flush()

    def run(
        self,
        max_rate: float = MAX_UPDATE_RATE,
        idle_rate: float = IDLE_UPDATE_RATE,
        while_running: bool = True,
    ) -> None:
        """Update the page until :meth:`close`, the stop button or the session's end.

        At each change the session tells of, at most ``max_rate`` times a
        second; ``idle_rate`` times a second without changes. A change within
        ``1 / max_rate`` of the last update sends :meth:`update_first` at
        once (the robot's pose), the rest at the interval's end. With
        ``while_running`` False, a session that does not run (not started
        yet) does not end the updates.
        """
        gap, idle = 1.0 / max_rate, 1.0 / idle_rate
        refresh = Guarded(log, "page update")  # the page must not stop the session
        first = Guarded(log, "page update (robot pose)")
        cause = "idle"
        while not self._close.is_set() and not self.stopped.is_set():
            started = time.perf_counter()
            # Cleared first: a change while the page updates wakes it again.
            self._changed.clear()
            self.update_causes = [*self.update_causes[-99:], cause]
            refresh.call(self.refresh)
            self.updates += 1
            if while_running and not self.session.running:
                break
            cause = "change" if self._changed.wait(idle) else "idle"
            # Not more often than max_rate: the rest of the gap is waited out
            # (changes meanwhile are sent together at its end), but what must
            # be seen first is sent at each change.
            while not self._close.is_set():
                rest = started + gap - time.perf_counter()
                if rest <= 0:
                    break
                if self._changed.is_set():
                    self._changed.clear()
                    first.call(self._send_between)
                    continue
                self._changed.wait(rest)

    def start(self, **run: Any) -> None:
        """Update the page in a thread of its own (``run``: :meth:`run`'s options)."""
        self._thread = threading.Thread(
            target=self.run, kwargs=run, name="page", daemon=True
        )
        self._thread.start()

    def close(self) -> None:
        """Stop updating and serving."""
        self._close.set()
        self._changed.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.server.stop()
