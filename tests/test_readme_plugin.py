"""The README's plugin example runs exactly as shown, from Python and from YAML."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from cbp.executors.kinematic import run_kinematic
from cbp.scenario import load_scenario

README = Path(__file__).resolve().parents[1] / "README.md"


def _readme_files(folder: Path) -> dict[str, Path]:
    """Write every README code block whose first line names a file; return them."""
    files = {}
    text = README.read_text(encoding="utf-8")
    for body in re.findall(r"```(?:python|yaml)\n(.*?)```", text, re.S):
        first = body.splitlines()[0]
        name = first.removeprefix("# ").strip()
        if first.startswith("# ") and name.endswith((".py", ".yaml")):
            files[name] = folder / name
            files[name].write_text(body, encoding="utf-8")
    return files


def test_readme_plugin_checks_from_python(tmp_path: Path) -> None:
    """The README's Jacobian check script passes on the README's plugin."""
    files = _readme_files(tmp_path)
    assert {"hand_above.py", "check_hand_above.py"} <= set(files)
    done = subprocess.run(
        [sys.executable, str(files["check_hand_above.py"])],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr


def test_readme_plugin_holds_the_hand_up_from_a_scenario(tmp_path: Path) -> None:
    """Used from the README's scenario, the hand stops at 30 cm, short of the goal."""
    files = _readme_files(tmp_path)
    scenario = load_scenario(files["hand_above_reach.yaml"])
    trace = run_kinematic(scenario)
    # The constraint is linearized each step: it may pass the plane by a hair.
    assert trace.ee_position[:, 2].min() >= 0.3 - 1e-4
    assert abs(trace.ee_position[-1, 2] - 0.3) < 1e-3
    assert np.isclose(trace.position_error[-1], 0.2, atol=2e-3)
