"""A controller killed mid-run: its robot, in its own process, brakes and rests.

The issue's target: SIGKILL the controller of a wall-clock run; the simulated
robot brakes within two command periods and nothing moves after. The robot
writes its recording when its controller is gone (:mod:`cbp.driver.process`).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cbp.driver import COMMAND_TIMEOUT

ROOT = Path(__file__).parents[2]
#: CAT's command period [s] (scenarios/configs/cat.yaml).
PERIOD = 1.0 / 30.0


@pytest.mark.slow
@pytest.mark.parametrize("simulator", ["pybullet", "mujoco"])
def test_a_killed_controller_leaves_its_robot_braked_at_rest(
    tmp_path: Path, simulator: str
) -> None:
    """SIGKILL while the arm moves: braked within two periods, still after."""
    controller = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "cbp",
            "run",
            str(ROOT / "scenarios" / "cat_free_continuous.yaml"),
            "--method",
            "cat",
            "--set",
            "simulation.own_process=true",
            "--set",
            f"simulator={simulator}",
            "--out",
            str(tmp_path / "out"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "TMPDIR": str(tmp_path)},
    )
    assert controller.stdout is not None
    lines = []
    try:
        for line in controller.stdout:
            lines.append(line)
            done = re.search(r"([0-9.]+) of [0-9.]+ s", line)
            if done and float(done.group(1)) >= 1.0:  # on its way to the goal
                break
        else:
            pytest.fail("the run ended before 1 s:\n" + "".join(lines))
        killed = time.monotonic()
        os.kill(controller.pid, signal.SIGKILL)
    finally:
        controller.kill()
        controller.wait()
        controller.stdout.close()
    record = tmp_path / f"cbp-robot-{controller.pid}.npz"
    deadline = time.monotonic() + 60.0
    while not record.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert record.exists(), "the robot wrote no recording"
    data = np.load(record)
    t, q, v = data["t"], data["q"], data["v"]
    kill = killed - float(data["t0"])
    at_kill = np.searchsorted(t, kill)
    assert np.max(np.abs(v[at_kill])) > 0.05, "the arm was not moving at the kill"
    trips = data["stale_at"][data["stale_at"] > kill - COMMAND_TIMEOUT]
    assert len(trips), "the watchdog never braked"
    print(f"{simulator}: braked {1e3 * (trips[0] - kill):.1f} ms after the kill")
    assert trips[0] - kill <= 2 * PERIOD, f"braked {trips[0] - kill:.3f} s after"
    after = t > trips[0] + 1.0
    assert after.sum() > 10
    assert np.max(np.abs(q[after] - q[after][-1])) < 1e-3, "the arm moved after"
    assert np.max(np.abs(v[after])) < 0.01
