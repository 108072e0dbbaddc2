"""Session-scoped robots and a seeded random generator."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from cbp.robot import RobotModel


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


def run_cbp(*args: str) -> subprocess.CompletedProcess[str]:
    """Run the ``cbp`` command line in a subprocess; output captured as text."""
    return subprocess.run(
        [sys.executable, "-m", "cbp", *args],
        capture_output=True,
        text=True,
        check=False,
    )
