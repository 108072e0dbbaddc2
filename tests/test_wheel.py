"""The wheel works on its own: robots, configurations and examples ship in it.

Builds the wheel, installs it (without dependencies: those of the test's own
environment are put on the new environment's path) into a fresh virtual
environment, and from a folder outside the checkout copies the examples out,
runs one, includes a shipped configuration by name, and brings an arm by URDF.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import textwrap
from pathlib import Path

import pytest

from tests.test_robot_init import POST_SCENARIO

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow


def _run(*args: str | Path, cwd: Path) -> subprocess.CompletedProcess[str]:
    # Without PYTHONPATH: a checkout on it would shadow the installed wheel.
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run(
        [str(a) for a in args],
        cwd=cwd,
        capture_output=True,
        text=True,
        check=False,
        env=env,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh environment with the wheel installed; dependencies borrowed."""
    root = tmp_path_factory.mktemp("wheel")
    _run(
        sys.executable,
        "-m",
        "pip",
        "wheel",
        "--no-deps",
        "-q",
        "-w",
        root / "dist",
        ROOT,
        cwd=root,
    )
    wheel = next((root / "dist").glob("cbp-*.whl"))
    _run(sys.executable, "-m", "venv", root / "venv", cwd=root)
    python = root / "venv" / "bin" / "python"
    _run(python, "-m", "pip", "install", "-q", "--no-deps", wheel, cwd=root)
    site = _run(
        python,
        "-c",
        "import sysconfig; print(sysconfig.get_paths()['purelib'])",
        cwd=root,
    ).stdout.strip()
    # The test environment's packages (and their .pth files: pinocchio's cmeel
    # prefix), after the wheel's own: its installed cbp comes first.
    borrowed = sysconfig.get_paths()["purelib"]
    (Path(site) / "zz_borrowed.pth").write_text(
        f"import site; site.addsitedir({borrowed!r})\n"
    )
    return root / "venv" / "bin"


def test_the_installed_wheel_carries_its_data(venv: Path, tmp_path: Path) -> None:
    where = _run(
        venv / "python",
        "-c",
        "import cbp.data, cbp.robot; print(cbp.data.data_dir('robots')); "
        "print(cbp.robot.ROBOTS_DIR)",
        cwd=tmp_path,
    ).stdout.split()
    assert all("venv" in w and "_data" in w for w in where), where
    assert str(ROOT) not in " ".join(where)


def test_examples_run_from_outside_the_checkout(venv: Path, tmp_path: Path) -> None:
    _run(venv / "cbp", "examples", "ex", cwd=tmp_path)
    assert (tmp_path / "ex" / "panda_reach.yaml").is_file()
    assert (tmp_path / "ex" / "configs" / "cat.yaml").is_file()
    _run(venv / "cbp", "run", "ex/panda_reach.yaml", "--out", "out", cwd=tmp_path)
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["kinematic"]["reached"]


def test_a_scenario_includes_cat_by_name_and_brings_a_urdf(
    venv: Path, tmp_path: Path
) -> None:
    import pybullet_data

    urdf = Path(pybullet_data.getDataPath()) / "xarm" / "xarm6_robot.urdf"
    _run(
        venv / "cbp",
        "robot",
        "init",
        urdf,
        "--out",
        "arm",
        "--samples",
        "200",
        cwd=tmp_path,
    )
    # The post scenario of the robot-init tests, shorter.
    (tmp_path / "s.yaml").write_text(
        POST_SCENARIO.replace("duration: 6.0", "duration: 3.0")
    )
    sub = tmp_path / "elsewhere"
    sub.mkdir()
    # Run from another folder: the robot path is the scenario's.
    _run(venv / "cbp", "run", "../s.yaml", "--out", "out", cwd=sub)
    metrics = json.loads((sub / "out" / "metrics.json").read_text())["cat"]
    assert metrics["peak_contact_force_n"] == 0.0
    assert metrics["final_position_error_m"] < 0.02


def test_the_api_works_in_a_project_with_its_own_plugins_package(
    venv: Path, tmp_path: Path
) -> None:
    """The wheel installs its plugins as cbp.plugins: a project's `plugins` is its own."""
    site = Path(
        _run(
            venv / "python",
            "-c",
            "import sysconfig; print(sysconfig.get_paths()['purelib'])",
            cwd=tmp_path,
        ).stdout.strip()
    )
    assert (site / "cbp" / "plugins" / "tasks" / "__init__.py").is_file()
    assert not (site / "plugins").exists()
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "__init__.py").write_text("OURS = True\n")
    code = textwrap.dedent(
        """\
        import plugins
        from cbp.data import data_dir
        from cbp.scenario import load_scenario

        scenario = load_scenario(data_dir("scenarios") / "cat_boards.yaml")
        print(plugins.OURS, sorted({type(e.plugin).__module__ for e in scenario.entries}))
        """
    )
    out = _run(venv / "python", "-c", code, cwd=tmp_path).stdout
    assert out.startswith("True ['cbp.plugins.constraints."), out
    assert (
        "venv"
        in _run(
            venv / "python",
            "-c",
            "import cbp.plugins; print(cbp.plugins.__file__)",
            cwd=tmp_path,
        ).stdout
    )
