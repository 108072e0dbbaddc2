"""Long commands say how far they are: plain lines when not on a terminal."""

from __future__ import annotations

from pathlib import Path

import pytest

from cbp.progress import Progress
from tests.conftest import run_cbp

ROOT = Path(__file__).resolve().parents[1]


def test_progress_prints_a_line_per_item_off_a_terminal(capsys) -> None:
    with Progress(2, "compare", lines=True) as bar:
        bar.advance("cat")
        bar.advance("ik", failed=True)
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("compare: 1/2 cat, ")
    assert err[1].startswith("compare: 2/2 ik (failed), ")


def test_progress_is_silent_unless_asked(capsys) -> None:
    with Progress(1, "sweep") as bar:
        bar.advance("cat")
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_cbp_compare_reports_each_method(tmp_path: Path) -> None:
    done = run_cbp(
        "compare",
        str(ROOT / "scenarios" / "cat_free_step.yaml"),
        "--methods",
        "cat,ik",
        "--set",
        "duration=0.4",
        "--out",
        str(tmp_path / "out"),
    )
    assert done.returncode == 0, done.stderr
    assert "compare: 1/2 cat" in done.stderr
    assert "compare: 2/2 ik" in done.stderr


def test_cbp_run_reports_simulated_time(tmp_path: Path) -> None:
    done = run_cbp(
        "run",
        str(ROOT / "scenarios" / "panda_reach.yaml"),
        "--set",
        "duration=1",
        "--out",
        str(tmp_path / "out"),
    )
    assert done.returncode == 0, done.stderr
    lines = [x for x in done.stderr.splitlines() if x.startswith("panda_reach")]
    assert len(lines) == 10, done.stderr  # a line every tenth of the run
    assert lines[-1] == "panda_reach (kinematic): 1.0 of 1.0 s"
