# SPDX-License-Identifier: Apache-2.0
"""``cbp teleop``: serve a live session's page until its stop, then save it."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from cbp.errors import CbpError, ConfigError
from cbp.files import OutputClaim, claim_new_output_folder, claim_output_folder
from cbp.teleop.goal_page import TeleopPage
from cbp.teleop.goal_session import TeleopSession, latency_summary
from cbp.teleop.input_session import InputSession
from cbp.teleop.inputs_page import InputsPage
from cbp.teleop.profiles import InputProfile

if TYPE_CHECKING:
    from cbp.teleop.hid_reader import HidDevice

__all__ = ["serve_teleop"]

#: How long the page stays up after its last notice [s].
NOTICE_SHOWN = 1.0
#: The signals that end a session as the page's stop does (saving it).
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


def _let_the_page_show_it() -> None:
    """Give the browser a moment to receive the last notice before the server stops."""
    time.sleep(NOTICE_SHOWN)


@contextlib.contextmanager
def _stopping_on_signals(page: TeleopPage | InputsPage) -> Iterator[None]:
    """While inside: SIGTERM and SIGHUP press the page's stop (it then saves)."""
    if threading.current_thread() is not threading.main_thread():
        yield  # only the main thread may set handlers; Ctrl-C still works
        return

    def stop(signum: int, _: object) -> None:
        print(f"{signal.Signals(signum).name}: stopping and saving", flush=True)
        page.stopped.set()

    previous = {s: signal.signal(s, stop) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _drive_with(
    profile: InputProfile,
    page: TeleopPage | InputsPage,
    session: TeleopSession | InputSession,
    host: str,
    opened: tuple[HidDevice, str] | None,
) -> Callable[[], None]:
    """Stream the profile's device to the session; the way to stop.

    Read by the page (streamed to a device link), or by this process when the
    device was ``opened`` here (``--hid``).
    """
    from cbp.teleop.device_driver import DeviceDriver, GoalTarget, VelocityTarget
    from cbp.teleop.device_link import DeviceLink, add_device_panel
    from cbp.teleop.hid_reader import HidReader

    target = (
        VelocityTarget(session)
        if isinstance(session, InputSession)
        else GoalTarget(session)
    )
    driver = DeviceDriver(profile, target)
    source: DeviceLink | HidReader
    if opened is None:
        source = link = DeviceLink(driver, host, page_port=page.server.get_port())
        where = f"read by the page, streamed to port {link.port}"
    else:
        source, link = HidReader(driver, *opened), None
        where = f"{opened[1]}, read by this process (hidapi)"
    add_device_panel(page, profile, link)
    driver.start()
    print(f"{profile.device}: {where}", flush=True)

    def stop() -> None:
        source.close()
        driver.stop()

    return stop


def serve_teleop(
    scenarios: list[Path],
    method: str,
    host: str,
    port: int,
    out: Path | None,
    overrides: dict[str, str],
    profile: InputProfile | None = None,
    hid: bool = False,
) -> int:
    """``cbp teleop``: serve the session until the page's stop, Ctrl-C or a signal.

    SIGTERM and SIGHUP end the session like the page's stop and Ctrl-C: the
    arm brakes and every output is written.

    One scenario of a trajectory executor: a goal session
    (:class:`TeleopPage`). Velocity-executor scenarios (one or several
    configurations of one robot, switched on the page): an input session
    (:class:`InputsPage`). Then the outputs are written. Exit 2 for a scenario
    or method that cannot start (nothing runs).

    A session never replaces an earlier one: ``out`` must be new or empty
    (else exit 2); without it, the session gets the first free folder of
    ``out/<name>_teleop``, ``out/<name>_teleop_2``...

    With an input ``profile`` (``--device``, ``--profile``), the page also
    reads that device and streams it to the session
    (:mod:`cbp.teleop.device_link`), through its deadman; with ``hid``
    (``--hid``), this process reads the 6-DOF mouse instead
    (:mod:`cbp.teleop.hid_reader`).
    """
    try:
        session, page, claim, opened = _start(
            scenarios, method, host, port, out, overrides, profile, hid
        )
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    device = None
    if profile is not None:
        device = _drive_with(profile, page, session, host, opened)
    print(
        f"teleoperation of {scenarios[0]}: {page.url} (stop on the page or Ctrl-C)",
        flush=True,
    )
    try:
        with contextlib.suppress(KeyboardInterrupt), _stopping_on_signals(page):
            page.run()
        if device is not None:
            device()
        page.say("**Stopping**: the arm brakes to rest, then the session is saved.")
        said = _save(session, page, claim, scenarios[0])
        _let_the_page_show_it()
    finally:
        page.close()
    print(said)
    if isinstance(session, TeleopSession):
        latency = latency_summary(session.latency_ms())
        if latency["n"]:
            print(
                f"goal-to-command latency: median {latency['median_ms']:.1f} ms, "
                f"p95 {latency['p95_ms']:.1f} ms over {latency['n']} goals"
            )
    return 0


def _start(
    scenarios: list[Path],
    method: str,
    host: str,
    port: int,
    out: Path | None,
    overrides: dict[str, str],
    profile: InputProfile | None,
    hid: bool,
) -> tuple[
    TeleopSession | InputSession,
    TeleopPage | InputsPage,
    OutputClaim,
    tuple[HidDevice, str] | None,
]:
    """The session started, its page, its output folder claimed, the HID device.

    Raises:
        CbpError: nothing started (the claim, if made, is released).
    """
    from cbp.scenario import load_scenario

    claim: OutputClaim | None = None
    try:
        opened = None
        if hid:
            from cbp.teleop.hid_reader import check_hid_profile, open_spacemouse

            if profile is None:
                raise ConfigError("give --device spacemouse with it", "--hid")
            check_hid_profile(profile)
            opened = open_spacemouse()
        first = load_scenario(scenarios[0])
        velocity = first.spec.method.name == "velocity"
        if not velocity and len(scenarios) > 1:
            raise ConfigError(
                "several scenarios are configurations of the velocity executor "
                "to switch between; a goal session takes one"
            )
        # Claimed for the whole session: a second session (or run) with the
        # same folder is refused while this one lives, and an earlier
        # session's folder is never replaced.
        claim = (
            claim_output_folder(out, replace=False)
            if out is not None
            else claim_new_output_folder(Path("out") / f"{first.spec.name}_teleop")
        )
        session: TeleopSession | InputSession
        page: TeleopPage | InputsPage
        if velocity:
            session = InputSession(scenarios, overrides)
            page = InputsPage(session, host=host, port=port)
        else:
            session = TeleopSession(scenarios[0], method, overrides)
            page = TeleopPage(session, host=host, port=port)
        session.start()
    except CbpError:
        if claim is not None:
            claim.release(remove=True)
        raise
    return session, page, claim, opened


def _save(
    session: TeleopSession | InputSession,
    page: TeleopPage | InputsPage,
    claim: OutputClaim,
    scenario: Path,
) -> str:
    """Stop the session and write its outputs; what to print about them."""
    out = claim.out
    if isinstance(session, InputSession):
        session.write(session.stop(), out, claim)
        page.say(f"**Saved** to `{out}`.")
        return f"wrote {out}"
    session.stop()
    goal_file = session.write(out, claim)
    replay = f"cbp compare {scenario} --goal {goal_file}"
    page.say(f"**Saved** to `{out}`. Replay to every method: `{replay}`")
    return f"wrote {out}; the operator's goals: {goal_file} (replay: {replay})"
