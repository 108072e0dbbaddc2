"""The code of the driver guide (``docs/drivers.md``) does what the guide says.

The guide's template driver passes the whole conformance suite over a
stand-in for an arm's SDK (its joints reach each setpoint by the next 2 ms
cycle) and a stand-in camera that sees a box through the guide's pinhole
frame; the pinhole frame puts a plane where it is. The code is taken from the
guide's blocks, so the page and what is tested are one copy.
"""

from __future__ import annotations

import re
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cbp.driver import RobotDriver
from cbp.driver.conformance import CHECKS, Bench, KnownBox
from cbp.robot import FloatArray, RobotModel

GUIDE = Path(__file__).parents[2] / "docs" / "drivers.md"

#: The conformance scene's box and camera (tests/driver/test_conformance.py).
BOX = KnownBox("front", np.array([0.55, -0.05, 0.25]), np.array([0.65, 0.05, 0.35]))
EYE = np.array([1.3, 0.0, 0.3])
#: The camera's optical frame (+z along the axis, +y down): it looks along -x.
OPTICAL = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
#: An off-centre pinhole camera, 320 x 240 pixels [px].
FX, FY, CX, CY = 207.8, 207.8, 160.2, 118.2


def _guide_module(name: str) -> ModuleType:
    """The guide's block that starts with ``# <name>.py``, run as a module."""
    text = GUIDE.read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    found = [b for b in blocks if b.startswith(f"# {name}.py\n")]
    assert len(found) == 1, f"{len(found)} blocks '# {name}.py' in {GUIDE}"
    module = ModuleType(name)
    sys.modules[name] = module  # what typing and dataclasses look names up in
    try:
        exec(compile(found[0], f"{GUIDE}:{name}.py", "exec"), module.__dict__)
    finally:
        del sys.modules[name]
    return module


@pytest.fixture(scope="module")
def camera() -> ModuleType:
    """The guide's camera block."""
    return _guide_module("my_camera")


@pytest.fixture(scope="module")
def template() -> ModuleType:
    """The guide's template driver."""
    return _guide_module("my_arm_driver")


def _pose(rotation: FloatArray, eye: FloatArray) -> FloatArray:
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rotation, eye
    return pose


def _rays(w: int, h: int, rotation: FloatArray) -> FloatArray:
    """Each pixel's ray in the world, scaled to depth 1 along the axis (H, W, 3)."""
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    optical = np.stack([(u - CX) / FX, (v - CY) / FY, np.ones((h, w))], axis=-1)
    return np.asarray(optical @ rotation.T)


def test_a_pinhole_frame_puts_a_plane_where_it_is(camera: ModuleType) -> None:
    """Every pixel's point is on the plane, where its ray meets it."""
    w, h = 64, 48
    rotation = Rotation.from_euler("xyz", [-90, 3, -95], degrees=True).as_matrix()
    eye = np.array([0.1, 0.2, 0.5])
    normal = np.array([-1.0, 0.1, 0.05]) / np.linalg.norm([-1.0, 0.1, 0.05])
    offset = normal @ (eye + 1.2 * rotation[:, 2])
    rays = _rays(w, h, rotation)
    depth = (offset - normal @ eye) / (rays @ normal)  # along the optical axis
    truth = eye + rays * depth[..., None]
    depth[0, 0], depth[1, 1] = 0.0, np.nan  # no reading
    frame = camera.pinhole_frame(
        depth, FX, FY, CX, CY, _pose(rotation, eye), "cam", 0.01, 3.0, 0.1
    )
    points, hit = frame.points()
    assert hit.sum() == w * h - 2
    assert not hit[0, 0]
    assert not hit[1, 1]
    assert np.max(np.linalg.norm(points - truth, axis=-1)[hit]) < 1e-9
    rows, cols, _ = frame.project(truth.reshape(-1, 3))
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    assert np.array_equal(rows.reshape(h, w), v)
    assert np.array_equal(cols.reshape(h, w), u)
    assert np.allclose(frame.position, eye)


class StandInArm:
    """Stands in for an arm's SDK: the joints reach each setpoint by the next cycle.

    Its clock ticks every ``period`` of the wall clock (a late read skips
    ticks, as a real arm's cycle does not wait).
    """

    def __init__(self, q0: FloatArray, period: float = 0.002) -> None:
        """Stand at ``q0``."""
        self.period = period
        self._q = np.array(q0, dtype=float)
        self._v = np.zeros_like(self._q)
        self._target = self._q.copy()
        self._t0 = time.monotonic()
        self._last = 0.0

    def read(self) -> tuple[float, FloatArray, FloatArray]:
        """Wait for the next tick: its time, the joints there."""
        now = time.monotonic() - self._t0
        tick = int(np.floor(now / self.period)) + 1
        time.sleep(max(0.0, tick * self.period - now))
        t = tick * self.period
        self._v = (self._target - self._q) / (t - self._last)
        self._q, self._last = self._target.copy(), t
        return t, self._q.copy(), self._v.copy()

    def write(self, q: FloatArray) -> None:
        """Reach ``q`` by the next tick."""
        self._target = np.array(q, dtype=float)

    def halt(self) -> None:
        """Stay where the joints are."""
        self._target = self._q.copy()


class StandInCamera:
    """A fixed depth camera that sees the box before a wall, 15 frames a second."""

    def __init__(self, driver: Any, camera: ModuleType) -> None:
        """Start capturing into ``driver``'s camera callback."""
        w, h = 320, 240
        rays = _rays(w, h, OPTICAL)
        on_face = EYE + rays * (EYE[0] - BOX.upper[0])  # the plane x = 0.65 m
        inside = (np.abs(on_face[..., 1]) <= BOX.upper[1]) & (
            (on_face[..., 2] >= BOX.lower[2]) & (on_face[..., 2] <= BOX.upper[2])
        )
        depth = np.where(inside, EYE[0] - BOX.upper[0], EYE[0])  # wall at x = 0
        self.frame = camera.pinhole_frame(
            depth, FX, FY, CX, CY, _pose(OPTICAL, EYE), BOX.camera, 0.01, 3.0, 0.1
        )
        self._driver = driver
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._done.wait(1.0 / 15.0):
            self._driver.captured(BOX.camera, time.monotonic(), self.frame)

    def close(self) -> None:
        """Stop capturing."""
        self._done.set()
        self._thread.join(timeout=1.0)


@pytest.fixture
def bench(template: ModuleType, camera: ModuleType) -> Iterator[Bench]:
    """The template driving a stand-in Panda at home, a stand-in camera with it."""
    robot = RobotModel.load("franka_panda")
    driver = template.MyArmDriver(StandInArm(robot.home()), robot)
    assert isinstance(driver, RobotDriver)
    eyes = StandInCamera(driver, camera)
    try:
        yield Bench(driver, time.sleep, BOX)
    finally:
        eyes.close()
        driver.close()


@pytest.mark.slow
@pytest.mark.parametrize("check", CHECKS)
def test_the_guide_template_passes(bench: Bench, check: str) -> None:
    """Each check of the suite, in real time (about a second each)."""
    CHECKS[check](bench)
