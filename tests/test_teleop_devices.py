"""Devices in ``cbp teleop``: input profiles, the pure mapping, the deadman.

The mapping from a device's state to a command is pure and tested on values;
the deadman and the stream's timeout are tested on a virtual clock (the
driver reads time only from the clock it is given), on real sessions that
are built but not run. The browser test injects a gamepad into headless
Chromium and drives a live session's goal through the page.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin
import pytest

from cbp.errors import ConfigError, ScenarioError
from cbp.teleop import TeleopSession
from cbp.teleop.device_driver import Deadman, DeviceDriver, GoalTarget, VelocityTarget
from cbp.teleop.devices import (
    DeviceState,
    command,
    deadman_held,
    move_goal,
    parse_state,
    shaped,
)
from cbp.teleop.profiles import (
    GOAL_COMPONENTS,
    VELOCITY_COMPONENTS,
    DeadmanSpec,
    GoalMap,
    load_profile,
    shipped_profiles,
)
from tests.conftest import free_port, headless_chromium, teleop_process, wait_until

ROOT = Path(__file__).resolve().parents[1]
BOARDS = ROOT / "scenarios" / "cat_boards.yaml"


class VirtualClock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        """Start at 100 s."""
        self.now = 100.0

    def __call__(self) -> float:
        """The time now [s]."""
        return self.now

    def advance(self, seconds: float) -> None:
        """Move the time on."""
        self.now += seconds


def _pad(axes: tuple[float, ...] = (0.0,) * 4, deadman: bool = True) -> DeviceState:
    """A standard-layout gamepad state; LB (button 4) is the shipped deadman."""
    buttons = [0.0] * 17
    buttons[4] = 1.0 if deadman else 0.0
    return DeviceState(axes=axes, buttons=tuple(buttons), device="test pad")


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "profile.yaml"
    path.write_text(text)
    return path


# ---------------------------------------------------------------- profiles


def test_the_shipped_profiles_load_and_map_both_kinds_of_session() -> None:
    """Each shipped profile names its device and maps goal and velocity."""
    assert shipped_profiles() == ["gamepad", "spacemouse"]
    for name in shipped_profiles():
        profile = load_profile(name)
        assert profile.device == name
        assert profile.goal
        assert profile.velocity
        assert profile.timeout == pytest.approx(0.1)
        assert {m.to for m in profile.goal} == set(GOAL_COMPONENTS)
        assert {m.to for m in profile.velocity} == set(VELOCITY_COMPONENTS)
    assert load_profile("gamepad").deadman == DeadmanSpec(button=4)


def test_a_bad_profile_is_refused_with_every_problem_located(tmp_path: Path) -> None:
    """Unknown devices, components and keys, and two sources, each with its line."""
    path = _write(
        tmp_path,
        "device: gamepd\n"
        "deadman: {button: 4}\n"
        "goal:\n"
        "  - {axis: 1, to: q}\n"
        "  - {axis: 1, button: 2, to: x}\n"
        "  - {axis: 0, to: x, sclae: 1}\n",
    )
    with pytest.raises(ScenarioError) as info:
        load_profile(path)
    problems = info.value.problems
    assert any(
        "line 1: device: got 'gamepd'" in p and "did you mean 'gamepad'" in p
        for p in problems
    )
    assert any("line 4: goal[0].to: got 'q'" in p for p in problems)
    assert any(
        "line 5: goal[1].axis: give one of 'axis' and 'button'" in p for p in problems
    )
    assert any("line 6: goal[2].sclae: unknown key" in p for p in problems)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("dead_band: 1.0", "line 3: dead_band: must be in \\[0, 1\\), got 1.0"),
        ("timeout: 0", "line 3: timeout: must be in \\(0, 1.0\\] s"),
        ("goal: [{axis: 64, to: x}]", "line 3: goal\\[0\\].axis: must be within 0..63"),
        (
            "goal: [{axis: 1, to: x, scale: .nan}]",
            "line 3: goal\\[0\\].scale: expected a finite number",
        ),
    ],
)
def test_profile_values_out_of_range_are_refused(
    tmp_path: Path, text: str, message: str
) -> None:
    """Dead band, timeout, indices and scales out of range name their line."""
    path = _write(tmp_path, f"device: gamepad\ndeadman: {{key: Shift}}\n{text}\n")
    with pytest.raises(ScenarioError, match=message):
        load_profile(path)


def test_a_deadman_needs_a_button_or_a_key_and_an_unknown_profile_is_named() -> None:
    """An empty deadman is refused; a missing profile lists the shipped ones."""
    with pytest.raises(ConfigError, match="give a 'button', a 'key' or both"):
        DeadmanSpec()
    with pytest.raises(
        ScenarioError, match=r"shipped input profile \(gamepad, spacemouse\)"
    ):
        load_profile("joystick")


# ---------------------------------------------------------------- mapping


def test_the_dead_band_zeroes_small_deflections_without_a_jump_at_its_edge() -> None:
    """0 inside the band, continuous at its edge, full at full travel, odd."""
    assert shaped(0.1, 0.1) == 0.0
    assert shaped(-0.05, 0.1) == 0.0
    assert shaped(0.1 + 1e-9, 0.1) == pytest.approx(0.0, abs=1e-8)
    assert shaped(0.55, 0.1) == pytest.approx(0.5)
    assert shaped(1.0, 0.1) == 1.0
    assert shaped(-1.0, 0.1) == -1.0
    assert shaped(0.3, 0.0) == 0.3


def test_a_state_maps_to_the_twist_its_profile_says() -> None:
    """Scaled, dead-banded, summed per component; absent axes count as rest."""
    mappings = (
        GoalMap(axis=1, to="x", scale=-0.1),
        GoalMap(button=7, to="z", scale=0.2),
        GoalMap(button=6, to="z", scale=-0.2),
        GoalMap(axis=5, to="rz", scale=1.0),  # the pad has no axis 5
    )
    buttons = [0.0] * 8
    buttons[7], buttons[6] = 1.0, 0.5
    state = DeviceState(axes=(0.0, -1.0, 0.0, 0.0), buttons=tuple(buttons))
    twist = command(mappings, state, 0.0, GOAL_COMPONENTS)
    np.testing.assert_allclose(twist, [0.1, 0.0, 0.2 - 0.1, 0.0, 0.0, 0.0])
    resting = DeviceState(axes=(0.05, -0.08, 0, 0), buttons=(0.0,) * 8)
    assert not command(mappings, resting, 0.1, GOAL_COMPONENTS).any()


def test_the_goal_moves_along_the_world_or_the_hand_axes() -> None:
    """World: the twist as given; hand: turned by the goal's rotation."""
    rotation = pin.exp3(np.array([0.0, 0.0, np.pi / 2]))  # hand x = world y
    position = np.array([0.5, 0.0, 0.4])
    twist = np.array([0.1, 0, 0, 0, 0, 0.5])
    p, R = move_goal(position, rotation, twist, 0.2, "world")
    np.testing.assert_allclose(p, [0.52, 0.0, 0.4])
    np.testing.assert_allclose(R, pin.exp3(np.array([0, 0, 0.1])) @ rotation)
    p, R = move_goal(position, rotation, twist, 0.2, "hand")
    np.testing.assert_allclose(p, [0.5, 0.02, 0.4], atol=1e-12)
    np.testing.assert_allclose(R, pin.exp3(np.array([0, 0, 0.1])) @ rotation)
    twist = np.array([0, 0, 0, 0.3, 0, 0])  # about the hand's x: the world's y
    _, R = move_goal(position, rotation, twist, 1.0, "hand")
    expected = pin.exp3(np.array([0, 0.3, 0])) @ rotation
    np.testing.assert_allclose(R, expected, atol=1e-12)


def test_the_page_s_messages_are_read_or_refused() -> None:
    """Values are clipped to their range; non-numbers and non-objects are refused."""
    state = parse_state(
        json.dumps(
            {"axes": [2.0, -0.5], "buttons": [1, -1], "keys": ["Shift"], "device": "p"}
        )
    )
    assert state == DeviceState((1.0, -0.5), (1.0, 0.0), frozenset({"Shift"}), "p")
    assert parse_state("{}") == DeviceState()
    for bad, where in [
        ("[1]", "device state"),
        ("nope", "device state"),
        ('{"axes": ["a"]}', "axes"),
        ('{"axes": [NaN]}', "axes"),
        ('{"buttons": [true]}', "buttons"),
        ('{"keys": [1]}', "keys"),
        (json.dumps({"axes": [0] * 65}), "axes"),
    ]:
        with pytest.raises(ConfigError, match=where):
            parse_state(bad)


# ---------------------------------------------------------------- deadman


def test_the_deadman_engages_only_on_a_fresh_held_state() -> None:
    """Held and fresh: engaged; released or silent past the timeout: an event."""
    deadman = Deadman(DeadmanSpec(button=4, key="Shift"), timeout=0.1)
    assert deadman.update(None, 0.0, 0.0) is None  # nothing yet, nothing to say
    assert not deadman.engaged
    assert deadman.update(_pad(), 0.0, 0.05) == "deadman held: test pad drives"
    assert deadman.engaged
    assert deadman.update(_pad(), 0.0, 0.1) is None  # exactly the timeout: fresh
    change = deadman.update(_pad(), 0.0, 0.1001)
    assert change is not None
    assert change.startswith("device silent for 100 ms")
    assert not deadman.engaged
    keys = DeviceState(buttons=(0.0,) * 17, keys=frozenset({"Shift"}))
    assert deadman.update(keys, 1.0, 1.0) is not None  # the key holds it too
    assert deadman.update(_pad(deadman=False), 1.0, 1.0) == (
        "deadman released: braking to a stop"
    )
    letter = DeviceState(keys=frozenset({"d"}))  # the page's names: lower case
    assert deadman_held(DeadmanSpec(key="D"), letter)
    assert deadman_held(DeadmanSpec(key="d"), letter)
    assert not deadman_held(DeadmanSpec(key="Shift"), letter)


class Gamepad(NamedTuple):
    """A CAT session on the boards driven by the gamepad profile, on a virtual clock."""

    session: TeleopSession
    clock: VirtualClock
    driver: DeviceDriver


@pytest.fixture
def gamepad() -> Iterator[Gamepad]:
    """A :class:`Gamepad`, its session closed after."""
    session = TeleopSession(BOARDS, "cat")
    try:
        clock = VirtualClock()
        yield Gamepad(
            session,
            clock,
            DeviceDriver(load_profile("gamepad"), GoalTarget(session), clock),
        )
    finally:
        session.parts.close()


def test_a_held_deadman_moves_the_goal_and_releasing_it_stops_it(
    gamepad: Gamepad,
) -> None:
    """The goal moves at the stick's speed while held; released: stops, logged."""
    session, clock, driver = gamepad
    start, _ = session.goal.pose()
    forward = (0.0, -1.0, 0.0, 0.0)  # left stick fully up: +x at 0.1 m/s
    driver.receive(_pad(forward, deadman=False))
    for _ in range(10):
        clock.advance(0.02)
        assert not driver.step()
    np.testing.assert_array_equal(session.goal.pose()[0], start)  # not held
    driver.receive(_pad(forward))
    driver.step()  # engages
    for _ in range(50):  # 1 s, a state every step
        clock.advance(0.02)
        driver.receive(_pad(forward))
        assert driver.step()
    moved = session.goal.pose()[0] - start
    np.testing.assert_allclose(moved, [0.1, 0.0, 0.0], atol=1e-9)
    driver.receive(_pad(forward, deadman=False))
    clock.advance(0.02)
    assert not driver.step()
    for _ in range(10):
        clock.advance(0.02)
        driver.receive(_pad(forward, deadman=False))
        assert not driver.step()
    np.testing.assert_allclose(session.goal.pose()[0] - start, moved)
    events = [m for _, m in session.parts.log.events]
    assert events[-2:] == [
        "deadman held: test pad drives",
        "deadman released: braking to a stop",
    ]


def test_a_device_that_falls_silent_brakes_the_goal(gamepad: Gamepad) -> None:
    """No state for more than 100 ms of the session's clock stops the goal."""
    session, clock, driver = gamepad
    driver.receive(_pad((0.0, 0.0, 0.0, 0.0)))
    driver.step()
    driver.receive(_pad((1.0, 0.0, 0.0, 0.0)))  # left stick right: -y
    for _ in range(5):  # 100 ms without a new state: still fresh
        clock.advance(0.02)
        assert driver.step()
    held_at = session.goal.pose()[0]
    clock.advance(0.02)
    assert not driver.step()  # 120 ms: silent
    clock.advance(1.0)
    driver.step()
    np.testing.assert_array_equal(session.goal.pose()[0], held_at)
    assert held_at[1] == pytest.approx(session.home[0][1] - 0.1 * 0.1)
    last = session.parts.log.events[-1][1]
    assert last.startswith("device silent for 120 ms (> 100 ms)")
    driver.receive(_pad((1.0, 0.0, 0.0, 0.0)))  # the stream comes back
    clock.advance(0.02)
    driver.step()
    assert driver.engaged


def test_a_step_after_a_stall_moves_the_goal_by_at_most_a_tenth_of_a_second(
    gamepad: Gamepad,
) -> None:
    """A driver that ran late does not jump the goal."""
    session, clock, driver = gamepad
    driver.receive(_pad((0.0, -1.0, 0.0, 0.0)))
    driver.step()
    clock.advance(0.09)
    driver.receive(_pad((0.0, -1.0, 0.0, 0.0)))
    clock.advance(0.01)
    assert driver.step()
    x = session.goal.pose()[0][0] - session.home[0][0]
    assert x == pytest.approx(0.1 * 0.1)


def test_the_device_sets_the_user_velocity_and_zeroes_it_on_release() -> None:
    """Orbit takes the camera's y and z, pan all three; released: all zero."""
    from cbp.teleop import InputSession

    scenarios = ROOT / "scenarios"
    session = InputSession(
        [scenarios / "youbot_orbit_case1.yaml", scenarios / "youbot_pan.yaml"]
    )
    try:
        clock = VirtualClock()
        driver = DeviceDriver(load_profile("gamepad"), VelocityTarget(session), clock)
        # Left stick up and right, right stick up: forward, sideways, up.
        stick = (1.0, -1.0, 0.0, -1.0)
        driver.receive(_pad(stick))
        assert driver.step()
        np.testing.assert_allclose(
            session.inputs["youbot_orbit_case1"]["user_velocity"], [-0.1, 0.1]
        )
        session.switch("youbot_pan")
        clock.advance(0.02)
        driver.receive(_pad(stick))
        assert driver.step()
        np.testing.assert_allclose(
            session.inputs["youbot_pan"]["user_velocity"], [0.1, -0.1, 0.1]
        )
        clock.advance(0.02)
        driver.receive(_pad(stick, deadman=False))
        assert not driver.step()
        np.testing.assert_array_equal(session.inputs["youbot_pan"]["user_velocity"], 0)
        assert [m for _, m in session.events if m.startswith("deadman")] == [
            "deadman held: test pad drives",
            "deadman released: braking to a stop",
        ]
        assert "deadman released: braking to a stop" in [
            m for _, m in session.snapshot().events
        ]
    finally:
        session.stop()


# ---------------------------------------------------------------- the command line


def test_teleop_refuses_a_bad_profile_or_a_profile_of_another_device(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`cbp teleop --profile` with a bad file, or not the --device's: exit 2."""
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from cbp.cli import main

    bad = _write(tmp_path, "device: gamepad\ndeadman: {}\n")
    assert main(["teleop", str(BOARDS), "--profile", str(bad)]) == 2
    assert "line 2: deadman.button: give a 'button', a 'key'" in (
        capsys.readouterr().err
    )
    teleop = ["teleop", str(BOARDS), "--device", "gamepad", "--profile", "spacemouse"]
    assert main(teleop) == 2
    assert "a spacemouse profile, not a gamepad one" in capsys.readouterr().err


# ---------------------------------------------------------------- the link


def test_the_device_link_takes_states_from_the_page_s_origin_only() -> None:
    """Another site's page is refused; the page's origin and a script get through."""
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    from cbp.teleop.device_link import DeviceLink

    # The states go no further than the driver: its target is never driven.
    driver = DeviceDriver(load_profile("gamepad"), GoalTarget(None))
    link = DeviceLink(driver, page_port=8080)
    url = f"ws://127.0.0.1:{link.port}/"
    message = json.dumps({"axes": [0.5], "device": "pad"})
    try:
        for origin in ("http://evil.example:8080", "http://127.0.0.1:9999"):
            with pytest.raises(InvalidStatus, match="403"):
                connect(url, origin=origin).close()
        for origin in ("http://127.0.0.1:8080", "http://localhost:8080", None):
            with connect(url, origin=origin) as socket:
                socket.send(message)
                socket.send("not json")
        assert wait_until(lambda: driver.received == 3 and link.rejected == 3, 30)
    finally:
        link.close()
    latest = driver.latest
    assert latest is not None
    assert latest.axes == (0.5,)


# ---------------------------------------------------------------- the browser


# A gamepad in the standard layout, the page's only one: the test sets its
# axes and buttons (window.cbpTestPad) and the page's reader polls it as it
# polls a real one.
_INJECT_PAD = """
window.cbpTestPad = {id: 'injected pad', index: 0, connected: true,
  mapping: 'standard', timestamp: 0, axes: [0, 0, 0, 0],
  buttons: Array.from({length: 17}, () => ({pressed: false, touched: false, value: 0}))};
navigator.getGamepads = () => [window.cbpTestPad, null, null, null];
"""


def _axes(driver: DeviceDriver) -> tuple[float, ...]:
    """The axes of the latest state the driver received."""
    latest = driver.latest
    return () if latest is None else latest.axes


def _button(driver: DeviceDriver, index: int) -> float | None:
    """A button of the latest state the driver received (None: none yet)."""
    latest = driver.latest
    return None if latest is None else latest.buttons[index]


def _keys(driver: DeviceDriver) -> frozenset[str]:
    """The keys held in the latest state the driver received."""
    latest = driver.latest
    return frozenset({"?"}) if latest is None else latest.keys


def _settle(driver: DeviceDriver) -> None:
    """Wait until every step that may have read an older state has ended.

    A step counts itself after reading the state: once two more have begun,
    the one that read before has ended, and the last has read the latest.
    Three, and that one has ended too.
    """
    steps = driver.steps
    assert wait_until(lambda: driver.steps >= steps + 3, 30)


#: The events a device's braking logs.
_BRAKES = ("deadman released", "device silent")


def _last_device_event(events: list[tuple[float, str]]) -> str:
    """The latest event of the device (held, released, silent), its first words."""
    for _, message in reversed(events):
        if message.startswith(("deadman", "device")):
            return message.split(":")[0].split(" for ")[0]
    return ""


def _set_pad(browser, axes: list[float], deadman: bool) -> None:  # type: ignore[no-untyped-def]
    browser.execute_script(
        "const p = window.cbpTestPad; p.axes = arguments[0];"
        "p.buttons[4] = {pressed: arguments[1], touched: arguments[1],"
        " value: arguments[1] ? 1 : 0};",
        axes,
        deadman,
    )


@pytest.mark.slow
def test_a_gamepad_in_the_browser_drives_the_goal_while_its_deadman_is_held() -> None:
    """Chromium with an injected gamepad: held, the goal moves; released, it stops."""
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from selenium.webdriver.common.by import By

    from cbp.teleop.device_link import DeviceLink, add_device_panel
    from cbp.teleop.goal_page import TeleopPage

    profile = load_profile("gamepad")
    session = TeleopSession(BOARDS, "cat")
    page = TeleopPage(session, port=free_port())
    driver = DeviceDriver(profile, GoalTarget(session))
    link = DeviceLink(driver, page_port=page.server.get_port())
    add_device_panel(page, profile, link)
    session.start()
    page.start()
    driver.start()
    browser = headless_chromium()
    try:
        browser.get(page.url)
        assert wait_until(
            lambda: browser.find_elements(By.ID, "cbp-device-status"), 60
        ), "the device panel never came"
        browser.execute_script(_INJECT_PAD)
        _set_pad(browser, [0.0, 0.0, 0.0, 0.0], deadman=False)

        def status() -> str:
            found = browser.find_elements(By.ID, "cbp-device-status")
            return str(found[0].text) if found else ""

        assert wait_until(lambda: "injected pad" in status(), 30), status()
        assert wait_until(lambda: driver.received > 5, 30), (
            "no state reached the session"
        )
        start = session.goal.pose()[0]

        # The stick pushed without the deadman: nothing moves.
        _set_pad(browser, [0.0, -1.0, 0.0, 0.0], deadman=False)
        assert wait_until(lambda: _axes(driver)[1:2] == (-1.0,), 30)
        seen = driver.received
        assert wait_until(lambda: driver.received > seen + 10, 30)
        np.testing.assert_array_equal(session.goal.pose()[0], start)
        assert not driver.engaged

        # Held: the goal moves forward (+x), the hand after it.
        hand = session.snapshot().hand.copy()
        _set_pad(browser, [0.0, -1.0, 0.0, 0.0], deadman=True)
        assert wait_until(lambda: "deadman HELD" in status(), 30), status()
        assert wait_until(lambda: session.goal.pose()[0][0] - start[0] > 0.03, 30)
        moved = session.goal.pose()[0] - start
        np.testing.assert_allclose(moved[1:], 0.0, atol=1e-9)  # along x only
        assert wait_until(lambda: session.snapshot().hand[0] - hand[0] > 0.02, 30)

        # Released: the goal stops where it is, with an event (one saying the
        # stream fell silent, if the browser stalled for 100 ms just then).
        # Every state the page sends from now on has the deadman released.
        _set_pad(browser, [0.0, -1.0, 0.0, 0.0], deadman=False)
        events = session.parts.log.events
        assert wait_until(lambda: _button(driver, 4) == 0.0, 30)
        _settle(driver)
        assert not driver.engaged
        assert _last_device_event(events) in _BRAKES, _last_device_event(events)
        stopped = session.goal.pose()[0]
        seen, steps = driver.received, driver.steps
        assert wait_until(
            lambda: driver.received > seen + 10 and driver.steps > steps, 30
        )
        np.testing.assert_array_equal(session.goal.pose()[0], stopped)
        assert "deadman held: injected pad drives" in [m for _, m in events]
    finally:
        browser.quit()
        link.close()
        driver.stop()
        page.close()
        session.stop()
    assert link.rejected == 0


# A 6-DOF mouse behind WebHID: requestDevice() hands the page this device, and
# window.cbpReport(id, values) makes it send an input report of int16 values.
_INJECT_SPACEMOUSE = """
const device = new EventTarget();
device.opened = false;
device.productName = 'injected SpaceMouse';
device.open = () => { device.opened = true; return Promise.resolve(); };
const hid = new EventTarget();
hid.requestDevice = () => Promise.resolve([device]);
hid.getDevices = () => Promise.resolve([]);
Object.defineProperty(navigator, 'hid', {configurable: true, value: hid});
window.cbpUnplug = () => {
  const event = new Event('disconnect');
  event.device = device;
  hid.dispatchEvent(event);
};
window.cbpReport = (id, values) => {
  const data = new DataView(new ArrayBuffer(2 * values.length));
  values.forEach((v, i) => data.setInt16(2 * i, v, true));
  const event = new Event('inputreport');
  event.reportId = id;
  event.data = data;
  device.dispatchEvent(event);
};
"""


@pytest.mark.slow
def test_a_6dof_mouse_over_webhid_sets_the_orbit_velocity_while_shift_is_held() -> None:
    """Chromium, a WebHID SpaceMouse, Shift as the deadman: orbit's user velocity."""
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    from cbp.teleop import InputSession
    from cbp.teleop.device_link import DeviceLink, add_device_panel
    from cbp.teleop.inputs_page import InputsPage

    profile = load_profile("spacemouse")
    session = InputSession([ROOT / "scenarios" / "youbot_orbit_case1.yaml"])
    page = InputsPage(session, port=free_port())
    driver = DeviceDriver(profile, VelocityTarget(session))
    link = DeviceLink(driver, page_port=page.server.get_port())
    add_device_panel(page, profile, link)
    session.start()
    page.start()
    driver.start()
    browser = headless_chromium()
    velocity = session.inputs["youbot_orbit_case1"]

    def status() -> str:
        found = browser.find_elements(By.ID, "cbp-device-status")
        return str(found[0].text) if found else ""

    try:
        browser.get(page.url)
        assert wait_until(lambda: "6-DOF mouse: none yet" in status(), 60), status()
        browser.execute_script(_INJECT_SPACEMOUSE)
        browser.find_element(
            By.XPATH, "//button[normalize-space()='connect 6-DOF mouse']"
        ).click()
        assert wait_until(lambda: "injected SpaceMouse" in status(), 30), status()
        # The cap pushed right (x) and lifted (z, negative), both at full travel.
        browser.execute_script("window.cbpReport(1, [350, 0, -350]);")
        seen = driver.received
        assert wait_until(lambda: driver.received > seen + 5, 30)
        assert not driver.engaged  # Shift is not held
        ActionChains(browser).key_down(Keys.SHIFT).perform()
        assert wait_until(lambda: "deadman HELD" in status(), 30), status()
        # Orbit commands the camera's y and z: push right -y, lift +z.
        assert wait_until(
            lambda: np.allclose(velocity["user_velocity"], [-0.1, 0.1]), 30
        ), velocity["user_velocity"]
        # A rotation report (2) sets the rotation, leaving the translation; a
        # newer model's report 1 carries all six.
        browser.execute_script("window.cbpReport(2, [0, 0, 175]);")
        assert wait_until(lambda: _axes(driver) == (1.0, 0.0, -1.0, 0.0, 0.0, 0.5), 30)
        assert wait_until(  # (after a brake, if the browser stalled for 100 ms)
            lambda: np.allclose(velocity["user_velocity"], [-0.1, 0.1]), 30
        ), velocity["user_velocity"]
        browser.execute_script("window.cbpReport(1, [350, 0, -350, 0, 700, 0]);")
        assert wait_until(lambda: _axes(driver) == (1.0, 0.0, -1.0, 0.0, 1.0, 0.0), 30)
        ActionChains(browser).key_up(Keys.SHIFT).perform()
        # Every state the page sends from now on has Shift up.
        assert wait_until(lambda: "Shift" not in _keys(driver), 30)
        _settle(driver)
        assert not driver.engaged
        assert not velocity["user_velocity"].any(), velocity["user_velocity"]
        assert _last_device_event(session.events) in _BRAKES, session.events[-3:]

        # Held again; then the mouse is unplugged with Shift still held: the
        # page forgets it and sends nothing, and the session brakes.
        ActionChains(browser).key_down(Keys.SHIFT).perform()
        assert wait_until(lambda: velocity["user_velocity"].any(), 30)
        browser.execute_script("window.cbpUnplug();")
        assert wait_until(lambda: "6-DOF mouse: none yet" in status(), 30), status()
        assert wait_until(lambda: not driver.engaged, 30)
        _settle(driver)
        assert _last_device_event(session.events) == "device silent"
        assert not velocity["user_velocity"].any()
        ActionChains(browser).key_up(Keys.SHIFT).perform()
    finally:
        browser.quit()
        link.close()
        driver.stop()
        page.close()
        session.stop()
    assert "deadman held: injected SpaceMouse drives" in [m for _, m in session.events]


@pytest.mark.slow
def test_cbp_teleop_with_a_gamepad_records_what_the_device_did(tmp_path: Path) -> None:
    """`cbp teleop --device gamepad`: its stream moves the goal; the log has the deadman."""
    import csv
    import signal

    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from websockets.sync.client import connect

    out = tmp_path / "session"
    command = [str(BOARDS), "--device", "gamepad", "--out", str(out)]
    with teleop_process(*command) as (process, said):
        assert "gamepad: read by the page, streamed to port" in said, said
        port = int(said.split("streamed to port ")[1].split()[0])
        forward = {"axes": [0, -1, 0, 0], "device": "cli pad", "keys": []}
        with connect(f"ws://127.0.0.1:{port}/") as socket:
            for held in [True] * 50 + [False] * 10:
                buttons = [0] * 17
                buttons[4] = int(held)
                socket.send(json.dumps({**forward, "buttons": buttons}))
                time.sleep(0.02)  # the page's pace; the outcome does not hang on it
        process.send_signal(signal.SIGTERM)
        rest, _ = process.communicate(timeout=300)
    assert process.returncode == 0, rest
    metrics = json.loads((out / "metrics.json").read_text())
    messages = [e["message"] for e in metrics["cat"]["events"]]
    held = messages.index("deadman held: cli pad drives")
    assert any(m.startswith(_BRAKES) for m in messages[held + 1 :]), messages
    with open(out / "operator_goal.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) > 1
    x = [float(r["x"]) for r in rows]
    assert x[-1] > x[0] + 0.01  # forward, at 0.1 m/s for most of a second


# ---------------------------------------------------------------- the server's HID


def _report(kind: int, *values: int) -> list[int]:
    """An input report as hidapi reads it: its id, then little-endian int16s."""
    import struct

    return [kind, *struct.pack(f"<{len(values)}h", *values)]


def test_spacemouse_reports_set_the_axes_and_buttons_they_carry() -> None:
    """Report 1: translation (or all six), 2: rotation, 3: button bits; clipped."""
    from cbp.teleop.hid_reader import apply_report

    axes, buttons = (0.0,) * 6, ()
    axes, buttons = apply_report(axes, buttons, _report(1, 175, -350, 700))
    assert axes == (0.5, -1.0, 1.0, 0.0, 0.0, 0.0)
    axes, buttons = apply_report(axes, buttons, _report(2, 0, 35, -175))
    assert axes == (0.5, -1.0, 1.0, 0.0, 0.1, -0.5)
    axes, buttons = apply_report(axes, buttons, _report(1, 0, 0, 0, 350, 0, 0))
    assert axes == (0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
    axes, buttons = apply_report(axes, buttons, [3, 0b10, 0])
    assert buttons[:3] == (0.0, 1.0, 0.0)
    assert len(buttons) == 32
    assert apply_report(axes, buttons, [23, 1, 2]) == (axes, buttons)  # other ids
    assert apply_report(axes, buttons, []) == (axes, buttons)


class RecordedSpaceMouse:
    """Replays input reports as hidapi's device gives them, then is unplugged."""

    def __init__(self, reports: list[list[int]]) -> None:
        """The reports to give, in order."""
        self.reports = list(reports)
        self.closed = False

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        """The next report; OSError once they are all read (unplugged)."""
        if not self.reports:
            raise OSError("read error")
        return self.reports.pop(0)[:max_length]

    def close(self) -> None:
        """Close the device."""
        self.closed = True


def test_a_spacemouse_read_by_the_server_drives_until_it_is_unplugged() -> None:
    """Its button holds the deadman; unplugged, its stream stops and the goal brakes."""
    from cbp.teleop.hid_reader import HidReader

    session = TeleopSession(BOARDS, "cat")
    try:
        clock = VirtualClock()
        driver = DeviceDriver(load_profile("spacemouse"), GoalTarget(session), clock)
        device = RecordedSpaceMouse(
            [[3, 0b1], _report(1, 0, -350, 0), [], _report(2, 0, 0, 0)]
        )
        reader = HidReader(driver, device, "recorded SpaceMouse")
        deadline = time.monotonic() + 30
        while reader.error is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert isinstance(reader.error, OSError)
        assert reader.reads == 4
        assert driver.received == 4
        latest = driver.latest
        assert latest is not None
        assert latest.axes == (0.0, -1.0, 0.0, 0.0, 0.0, 0.0)  # pushed away: y -
        start = session.goal.pose()[0]
        assert not driver.step()  # engages; no time has passed
        clock.advance(0.05)
        assert driver.step()
        np.testing.assert_allclose(
            session.goal.pose()[0] - start, [0.1 * 0.05, 0, 0], atol=1e-12
        )
        clock.advance(0.1)  # nothing since: unplugged
        assert not driver.step()
        assert session.parts.log.events[-1][1].startswith("device silent for 150 ms")
        reader.close()
        assert device.closed
    finally:
        session.parts.close()


def test_teleop_hid_needs_a_6dof_mouse_with_a_button_deadman(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--hid` with a gamepad, a keys-only deadman or no device found: exit 2."""
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from cbp.cli import main

    teleop = ["teleop", str(BOARDS), "--out", str(tmp_path / "out")]
    assert main([*teleop, "--device", "gamepad", "--hid"]) == 2
    said = capsys.readouterr().err
    assert "--hid: reads a 6-DOF mouse only; the profile is a gamepad's" in said
    keys = _write(tmp_path, "device: spacemouse\ndeadman: {key: Shift}\n")
    assert main([*teleop, "--profile", str(keys), "--hid"]) == 2
    assert "deadman must be a device button" in capsys.readouterr().err
    assert main([*teleop, "--hid"]) == 2
    assert "--hid: give --device spacemouse with it" in capsys.readouterr().err
    assert main([*teleop, "--device", "spacemouse", "--hid"]) == 2
    said = capsys.readouterr().err
    # This machine has no SpaceMouse; without the hid extra, hidapi is missing.
    assert "no SpaceMouse found" in said or "cbp[hid]" in said
    assert not (tmp_path / "out").exists()  # nothing ran
