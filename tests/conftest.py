"""Session-scoped robots, a seeded random generator, the virtual clock, browser helpers."""

from __future__ import annotations

import contextlib
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence

import numpy as np
import pytest

from cbp.robot import RobotModel
from cbp.scenario import Scenario, load_scenario

#: Scenario values that put every trajectory executor on the virtual clock:
#: planning budgets are counted in work done, not wall-clock time, so a test's
#: outcome does not depend on how busy the machine is. Tests of wall-clock
#: behaviour itself (live sessions, the clocks' own tests) do without.
VIRTUAL_CLOCK = {f"method.{m}.timing.clock": "virtual" for m in ("cat", "ik", "mp")}


def load_virtual(path: object, overrides: dict[str, str] | None = None) -> Scenario:
    """``load_scenario`` on the virtual clock (:data:`VIRTUAL_CLOCK`)."""
    return load_scenario(path, overrides={**VIRTUAL_CLOCK, **(overrides or {})})  # type: ignore[arg-type]


@pytest.fixture(scope="session")
def robots() -> dict[str, RobotModel]:
    """The Panda on fixed, planar and floating bases; the youBot on its planar base."""
    return {
        "panda": RobotModel.load("franka_panda"),
        "panda_planar": RobotModel.load("franka_panda", base="planar"),
        "panda_floating": RobotModel.load("franka_panda", base="floating"),
        "youbot": RobotModel.load("kuka_youbot", base="planar"),
    }


@pytest.fixture
def rng() -> np.random.Generator:
    """A generator with a fixed seed."""
    return np.random.default_rng(20261122)


@contextlib.contextmanager
def teleop_process(*args: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """``cbp teleop ARGS`` on a free port, in a subprocess, once its page is up.

    Yields the process and what it printed up to the page's address (viser's
    banner, a device's port, then ``teleoperation of``); a process still
    running at the end is killed.
    """
    process = subprocess.Popen(
        [sys.executable, "-m", "cbp", "teleop", *args, "--port", str(free_port())],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert process.stdout is not None
        said = ""
        for _ in range(100):
            said += process.stdout.readline()
            if "teleoperation of" in said:
                break
        yield process, said
    finally:
        if process.poll() is None:
            process.kill()


def run_cbp(*args: str) -> subprocess.CompletedProcess[str]:
    """Run the ``cbp`` command line in a subprocess; output captured as text."""
    return subprocess.run(
        [sys.executable, "-m", "cbp", *args],
        capture_output=True,
        text=True,
        check=False,
    )


def headless_chromium(extra_flags: Sequence[str] = ()):  # type: ignore[no-untyped-def]
    """Debian's Chromium through selenium, headless, 1280 x 900; fails without it.

    The browser tests are slow tests; ``make test-slow`` installs the browser.
    ``extra_flags``: more command-line flags for Chromium.
    """
    webdriver = pytest.importorskip("selenium.webdriver")
    chromium, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if chromium is None or driver is None:
        pytest.fail(
            "Chromium is needed: apt-get install chromium chromium-driver "
            "(make test-slow installs them)"
        )
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-dev-shm-usage",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--window-size=1280,900",
        *extra_flags,
    ):
        options.add_argument(flag)
    service = webdriver.ChromeService(executable_path=driver)
    return webdriver.Chrome(options=options, service=service)


def free_port() -> int:
    """A TCP port free on localhost now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_until(condition: Callable[[], object], timeout: float) -> bool:
    """Poll ``condition`` until it holds or ``timeout`` [s] passes (generous).

    For what another thread or process does (a page, a device): the timeout
    bounds a failing test, it is no budget of a passing one.
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return bool(condition())
