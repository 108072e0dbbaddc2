"""``cbp view``: a finished comparison replayed in a real browser (Chromium).

The replay is served in this process; headless Chromium (Debian's ``chromium``
and ``chromium-driver``, through selenium) opens the page. The test waits for
the browser to connect and draw, scrubs the timeline, and checks the robots
and the readout follow; it also writes a .viser recording.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from cbp.compare import compare
from tests.conftest import free_port, headless_chromium

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow

viser = pytest.importorskip("viser", reason="the viewer extra is not installed")
webdriver = pytest.importorskip("selenium.webdriver")


@pytest.fixture(scope="module")
def comparison(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("view") / "boards"
    compare(
        ROOT / "scenarios" / "cat_boards.yaml",
        ["cat", "ik"],
        out,
        overrides={"duration": "1.5"},
    )
    return out


def test_the_replay_page_opens_and_follows_the_timeline(comparison: Path) -> None:
    from selenium.webdriver.common.by import By

    from cbp.viewer import Replay

    replay = Replay(comparison, port=free_port())
    serving = threading.Thread(target=replay.run, daemon=True)
    serving.start()
    browser = headless_chromium()
    try:
        browser.get(replay.url)
        deadline = time.monotonic() + 60
        while not replay.server.get_clients() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert replay.server.get_clients(), "the browser never connected"
        while time.monotonic() < deadline:
            canvases = browser.find_elements(By.TAG_NAME, "canvas")
            if canvases and "time [s]" in browser.page_source:
                break
            time.sleep(0.2)
        assert browser.find_elements(By.TAG_NAME, "canvas"), "nothing drawn"
        assert "time [s]" in browser.page_source
        # Both methods' robots are in the scene; scrubbing moves them.
        cat = next(r for r in replay._robots if r[0].method == "cat")
        before = cat[1]._urdf.cfg.copy()
        replay.time.value = 1.2
        time.sleep(0.5)
        assert "t = 1.200 s" in replay.readout.content
        assert "**cat**" in replay.readout.content
        assert "**ik**" in replay.readout.content
        assert not np.allclose(cat[1]._urdf.cfg, before)
        # The readout reaches the page too.
        deadline = time.monotonic() + 10
        while "t = 1.200 s" not in browser.page_source and time.monotonic() < deadline:
            time.sleep(0.2)
        assert "t = 1.200 s" in browser.page_source
        artifacts = ROOT / "out" / "test-artifacts"
        artifacts.mkdir(parents=True, exist_ok=True)
        time.sleep(1.0)
        browser.save_screenshot(str(artifacts / "replay_page.png"))
    finally:
        browser.quit()
        replay.close()


def test_the_timeline_plays_to_the_end(comparison: Path) -> None:
    from cbp.viewer import Replay

    replay = Replay(comparison, port=free_port())
    serving = threading.Thread(target=replay.run, daemon=True)
    serving.start()
    try:
        replay.speed.value = 4.0
        replay.playing.value = True
        seen = [0.0]
        deadline = time.monotonic() + 10
        # Plays forward, reaches the end, and starts over from 0.
        while time.monotonic() < deadline:
            t = float(replay.time.value)
            if t < seen[-1]:
                break
            seen.append(t)
            time.sleep(0.02)
        assert max(seen) > replay.duration - 0.2
        assert float(replay.time.value) < max(seen)  # wrapped around
    finally:
        replay.close()


def test_a_replay_exports_a_recording(comparison: Path, tmp_path: Path) -> None:
    from cbp.viewer import Replay

    replay = Replay(comparison, port=free_port())
    try:
        path = replay.export(tmp_path / "boards.viser", rate=10.0)
    finally:
        replay.close()
    assert path.stat().st_size > 10_000


def test_the_replay_moves_objects_and_plots_the_curves(tmp_path: Path) -> None:
    """A pushed obstacle is drawn where it was; the plots follow the cursor."""
    from cbp.viewer import Replay

    out = tmp_path / "pushed"
    compare(
        ROOT / "scenarios" / "cat_pushed_obstacle.yaml",
        ["cat"],
        out,
        overrides={"duration": "3.0"},
    )
    replay = Replay(out, port=free_port())
    try:
        (name,) = replay._tracks
        replay.show(0.2)
        before = np.array(replay._objects[name].position)
        error = replay.plots["goal_error"].data
        replay.show(2.5)
        after = np.array(replay._objects[name].position)
        # Pushed at 5 cm/s from 0.5 s: 10 cm along -y by 2.5 s.
        np.testing.assert_allclose(after - before, [0.0, -0.10, 0.0], atol=0.01)
        later = replay.plots["goal_error"].data
        assert later[0][-1] == pytest.approx(2.5, abs=0.05)  # up to the cursor
        assert later[0][0] == pytest.approx(0.0, abs=0.05)
        assert len(later[0]) > len(error[0])
        assert np.all(np.isfinite(later[1]))
        force = replay.plots["contact_force"].data
        assert len(force) == 2  # time and the one method
    finally:
        replay.close()
