"""Figures are readable: tick labels carry the values, with no offset above an axis."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure

from cbp.plots import plot_runs
from cbp.sweep.results import _plots
from cbp.trace import Trace


@pytest.fixture
def offsets(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The offset texts of every axis of every figure saved during the test."""
    found: list[str] = []
    save = Figure.savefig

    def recording(self: Figure, *args: Any, **kwargs: Any) -> None:
        self.canvas.draw()
        for ax in self.axes:
            for axis in (ax.xaxis, ax.yaxis):
                found.append(axis.get_offset_text().get_text())
        save(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", recording)
    return found


def test_run_figures_have_no_offset_notation(
    offsets: list[str], tmp_path: Path
) -> None:
    """Values that differ in the 6th digit are still labelled as themselves."""
    m = 50
    t = np.linspace(0.0, 1.0, m)
    nan3 = np.full((m, 3), np.nan)
    trace = Trace(
        method="cat",
        t=t,
        q=1000.0 + 1e-3 * np.sin(t)[:, None] * np.ones((m, 2)),
        ee_position=np.zeros((m, 3)),
        ee_rotation=np.tile(np.eye(3), (m, 1, 1)),
        goal_position=nan3,
        goal_rotation=np.full((m, 3, 3), np.nan),
        contact_force=2.0 + 1e-5 * t,
    )
    paths = plot_runs({"cat": trace}, tmp_path, "t")
    assert {p.name for p in paths} == {"contact_force.png", "joints.png"}
    assert offsets
    assert set(offsets) == {""}


def test_sweep_figures_have_no_offset_notation(
    offsets: list[str], tmp_path: Path
) -> None:
    """The sweep's per-method and per-setting figures label values as themselves."""
    rows = [
        {
            "status": "ok",
            "method": method,
            "set.gain": 100.0 + 1e-4 * i,
            "total_time_s": 2.0 + 1e-5 * i,
            "final_position_error_m": 2.713e-05 + 1e-9 * i,
        }
        for i, method in enumerate(["cat", "ik"] * 3)
    ]
    paths = _plots(rows, ["gain"], tmp_path)
    assert [p.name for p in paths] == ["by_method.png", "vs_gain.png"]
    assert offsets
    assert set(offsets) == {""}
