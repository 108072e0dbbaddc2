"""Teleoperation latency from the browser: a key in Chromium to the robot and back.

A :class:`~cbp.teleop.TeleopSession` on the boards runs in real time with its
page open in headless Chromium (Debian's ``chromium`` and ``chromium-driver``,
software WebGL). The script presses the page's ``w`` and ``s`` keys (real key
events through ChromeDriver, 0.3 s apart: the goal jogs 2 cm along +x, then
back) and measures per key, on the machine's wall clock:

- **to the server**: from the key event (``performance.timeOrigin +
  event.timeStamp`` in the page) to the goal's arrival in the session (the
  page's key handler clicks the jog button, viser sends the click over its
  websocket, the server moves the goal);
- **to the command**: to the moment the first trajectory planned for that goal
  starts to be commanded to the robot (the splice point);
- **hand on page**: to the first animation frame after the page received a
  drawn hand that has moved 1 mm toward the new goal (the page sends the hand
  with every update; a marker of its position in the panel is watched by a
  MutationObserver, and the frame that follows it is the one that draws it).

Idle, and with two CPU-bound processes beside it (``--burners``). The browser
and the server read the same system clock; the script checks that they agree
(their difference is printed). The load average is recorded: the machine may
be shared.

Run: .venv/bin/python benchmarks/teleop_browser_latency.py --append benchmarks/RESULTS.md
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from results_file import put_section  # this folder: scripts run from it

from cbp.teleop import TeleopSession
from cbp.teleop.goal_page import TeleopPage
from cbp.teleop.page import MAX_UPDATE_RATE

ROOT = Path(__file__).resolve().parents[1]
#: Hand motion that counts as the page showing the moved hand [m].
MOVED = 0.001

# In the page: the key events' times, and each change of the hand marker
# (its time, the animation frame after it, and the hand's x) .
_WATCH = """
window.cbpKeysAt = [];
window.addEventListener('keydown', e => {
  window.cbpKeysAt.push(performance.timeOrigin + e.timeStamp);
}, true);
window.cbpHand = [];
let last = null;
let el = null;
new MutationObserver(() => {
  if (!el || !el.isConnected) {
    el = [...document.querySelectorAll('p, span, div')].find(
      n => n.childElementCount === 0 && n.textContent.startsWith('hand x '));
  }
  if (!el || el.textContent === last) return;
  last = el.textContent;
  const x = parseFloat(el.textContent.slice(7));
  const seen = performance.timeOrigin + performance.now();
  requestAnimationFrame(() => window.cbpHand.push(
    [seen, performance.timeOrigin + performance.now(), x]));
}).observe(document.body, {subtree: true, childList: true, characterData: true});
"""


# Before the page's scripts: when each message batch from the websocket worker
# (viser's client receives in a web worker) reaches the page's main thread.
_MESSAGES = """
window.cbpMessages = [];
const NativeWorker = window.Worker;
window.Worker = class extends NativeWorker {
  constructor(...args) {
    super(...args);
    this.addEventListener('message', () => window.cbpMessages.push(
      performance.timeOrigin + performance.now()));
  }
};
"""


def _tree_cpu(root: int) -> float:
    """CPU time [s] used so far by process ``root`` and its descendants (Linux)."""
    parents: dict[int, int] = {}
    times: dict[int, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parents[int(entry.name)] = int(fields[1])
        times[int(entry.name)] = (int(fields[11]) + int(fields[12])) / tick
    total, stack = 0.0, [root]
    while stack:
        pid = stack.pop()
        total += times.get(pid, 0.0)
        stack += [child for child, parent in parents.items() if parent == pid]
    return total


def _percentiles(values: list[float]) -> tuple[float, float]:
    if not values:
        return (float("nan"), float("nan"))
    a = np.array(values)
    return float(np.median(a)), float(np.percentile(a, 95))


def measure(keys: int, burners: int) -> dict[str, Any]:
    """One session: ``keys`` key presses, ``burners`` CPU-bound processes beside it."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    sys.path.insert(0, str(ROOT))
    from tests.conftest import headless_chromium

    session = TeleopSession(ROOT / "scenarios" / "cat_boards.yaml", "cat")
    page = TeleopPage(session, port=0)
    marker = page.server.gui.add_markdown("hand x 0")
    update = page.update

    sent: list[tuple[float, float]] = []  # (server time, the hand's x) per update
    page_cpu = [0.0]

    def marked() -> None:
        start = time.thread_time()
        update()
        page_cpu[0] += time.thread_time() - start
        if page.shown is not None:
            x = float(page.shown.hand[0])
            marker.content = f"hand x {x:.5f}"
            sent.append((time.time(), x))

    page.update = marked  # type: ignore[method-assign]
    arrivals: dict[int, float] = {}
    set_goal = session.goal.set

    def stamped(position: Any, rotation: Any) -> int:
        number = set_goal(position, rotation)
        arrivals[number] = time.time()
        return number

    session.goal.set = stamped  # type: ignore[method-assign]
    burning = [
        subprocess.Popen([sys.executable, "-c", "while True: pass"])
        for _ in range(burners)
    ]
    browser = headless_chromium()
    load = [os.getloadavg()[0]]
    try:
        session.start()
        page.start()
        browser.execute_cdp_cmd(
            "Page.addScriptToEvaluateOnNewDocument", {"source": _MESSAGES}
        )
        browser.get(page.url)
        deadline = time.monotonic() + 120
        while not browser.find_elements(By.XPATH, "//button[normalize-space()='+x']"):
            if time.monotonic() > deadline:
                raise RuntimeError("the page never showed its jog buttons")
            time.sleep(0.2)
        browser.execute_script(_WATCH)
        time.sleep(3.0)  # the robot drawn, the page settled
        checks = []  # (round trip, browser clock - server clock) [ms]
        for _ in range(5):
            before = time.time()
            now = float(
                browser.execute_script(
                    "return performance.timeOrigin + performance.now()"
                )
            )
            after = time.time()
            checks.append((1e3 * (after - before), now - 1e3 * (before + after) / 2))
        trip_ms, clock_ms = min(checks)
        perf_to_epoch = time.time() - time.perf_counter()
        body = browser.find_element(By.TAG_NAME, "body")
        driver_pid = browser.service.process.pid
        cpu0 = (_tree_cpu(driver_pid), time.process_time(), page_cpu[0])
        wall0 = time.perf_counter()
        for k in range(keys):
            ActionChains(browser).send_keys_to_element(body, "ws"[k % 2]).perform()
            time.sleep(0.3)
            load.append(os.getloadavg()[0])
        time.sleep(0.5)
        wall = time.perf_counter() - wall0
        cpu = (
            (_tree_cpu(driver_pid) - cpu0[0]) / wall,
            (time.process_time() - cpu0[1]) / wall,
            (page_cpu[0] - cpu0[2]) / wall,
        )
        keys_at = [t / 1e3 for t in browser.execute_script("return window.cbpKeysAt")]
        hand = [
            (a / 1e3, b / 1e3, x)
            for a, b, x in browser.execute_script("return window.cbpHand")
        ]
        messages = np.array(browser.execute_script("return window.cbpMessages")) / 1e3
    finally:
        for burner in burning:
            burner.kill()
            burner.wait()
        browser.quit()
        page.close()
        session.stop()
    done = {c.number: c for c in session.commands()}
    commands = {n: c.commanded + perf_to_epoch for n, c in done.items()}
    numbers = sorted(arrivals)
    to_server, to_command, on_page, on_dom, to_sent = [], [], [], [], []
    # The moved hand's way through the browser: server sent -> main thread
    # got the batch -> panel changed -> animation frame [ms].
    browser_part: dict[str, list[float]] = {"received": [], "dom": [], "frame": []}
    stages: dict[str, list[float]] = {"taken": [], "planned": [], "commanded": []}
    for c in done.values():
        stages["taken"].append(1e3 * (c.sampled - c.arrival))
        stages["planned"].append(1e3 * (c.planned - c.sampled))
        stages["commanded"].append(1e3 * (c.commanded - c.planned))
    for i, pressed in enumerate(keys_at[: len(numbers)]):
        number = numbers[i]
        to_server.append(1e3 * (arrivals[number] - pressed))
        if number in commands:
            to_command.append(1e3 * (commands[number] - pressed))
        shown_before = [x for seen, _, x in hand if seen <= pressed]
        if not shown_before:
            continue
        sign = 1.0 if i % 2 == 0 else -1.0
        moved = [
            (seen, frame)
            for seen, frame, x in hand
            if seen > pressed and sign * (x - shown_before[-1]) >= MOVED
        ]
        if moved:
            on_dom.append(1e3 * (moved[0][0] - pressed))
            on_page.append(1e3 * (moved[0][1] - pressed))
        x0 = [x for at, x in sent if at <= pressed]
        moved_sent = [
            at for at, x in sent if at > pressed and x0 and sign * (x - x0[-1]) >= MOVED
        ]
        if moved_sent:
            to_sent.append(1e3 * (moved_sent[0] - pressed))
        if moved and moved_sent:
            seen, frame = moved[0]
            before = messages[(messages <= seen) & (messages >= moved_sent[0] - 0.002)]
            if before.size:
                browser_part["received"].append(1e3 * (before[0] - moved_sent[0]))
                browser_part["dom"].append(1e3 * (seen - before[0]))
                browser_part["frame"].append(1e3 * (frame - seen))
    return {
        "burners": burners,
        "keys": len(keys_at),
        "goals": len(numbers),
        "to_server": _percentiles(to_server),
        "to_command": _percentiles(to_command),
        "stages": {k: _percentiles(v) for k, v in stages.items()},
        "browser": {k: _percentiles(v) for k, v in browser_part.items()},
        "n_command": len(to_command),
        "on_dom": _percentiles(on_dom),
        "to_sent": _percentiles(to_sent),
        "on_page": _percentiles(on_page),
        "n_page": len(on_page),
        "clock_ms": clock_ms,
        "trip_ms": trip_ms,
        "cpu": cpu,
        "load": (min(load), max(load)),
        "misses": sum(1 for p in session.parts.log.periods if p.missed),
        "periods": len(session.parts.log.periods),
    }


def main() -> None:
    """Measure idle and beside CPU-bound processes; print or append."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keys", type=int, default=60)
    parser.add_argument("--burners", type=int, default=2)
    parser.add_argument("--append", type=Path, default=None)
    parser.add_argument(
        "--only", type=int, default=None, help="one row: this many CPU-bound processes"
    )
    args = parser.parse_args()
    loads = (0, args.burners) if args.only is None else (args.only,)
    rows = [measure(args.keys, b) for b in loads]
    for r in rows:
        print(
            f"{r['burners']} CPU-bound: goal arrival -> taken by the loop -> "
            "planned -> commanded, median / p95 [ms]: "
            + ", ".join(f"{a:.1f} / {b:.1f}" for a, b in r["stages"].values())
        )
        print(
            f"{r['burners']} CPU-bound: moved hand sent -> batch on the page's main "
            "thread -> panel changed -> animation frame, median / p95 [ms]: "
            + ", ".join(f"{a:.1f} / {b:.1f}" for a, b in r["browser"].values())
        )
    lines = [
        "",
        "## Teleoperation: latency from a key in the browser "
        "(benchmarks/teleop_browser_latency.py)",
        "",
        "Boards, CAT, the page in headless Chromium (software WebGL) updated at "
        f"each change of the session (at most {MAX_UPDATE_RATE:g} Hz); {args.keys} presses of the page's w and s keys "
        "(real key events through ChromeDriver, 0.3 s apart; each jogs the goal "
        "2 cm along x). From the key event in the page to the goal's arrival in "
        "the session (to server), to the first command of the trajectory planned "
        "for it (to command), and to the first animation frame after the page "
        f"received a hand moved {MOVED * 1e3:g} mm toward the new goal (hand on "
        "page; also the medians of when the server sent the moved hand and when "
        "the panel's marker of it changed in the page). "
        f"{platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}. Command: `.venv/bin/python "
        "benchmarks/teleop_browser_latency.py --append benchmarks/RESULTS.md`.",
        "",
        "| CPU-bound processes | load average | keys / goals | to server median / p95 [ms] | to command median / p95 [ms] | hand on page median / p95 [ms] | moved hand sent / marker changed, medians [ms] | deadline misses | CPU: Chromium / session (page updates) [cores] | browser clock - server clock [ms] |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['burners']} | {r['load'][0]:.1f}-{r['load'][1]:.1f} | "
            f"{r['keys']} / {r['goals']} | "
            f"{r['to_server'][0]:.1f} / {r['to_server'][1]:.1f} | "
            f"{r['to_command'][0]:.1f} / {r['to_command'][1]:.1f} | "
            f"{r['on_page'][0]:.1f} / {r['on_page'][1]:.1f} | "
            f"{r['to_sent'][0]:.0f} / {r['on_dom'][0]:.0f} | "
            f"{r['misses']} of {r['periods']} | {r['cpu'][0]:.2f} / {r['cpu'][1]:.2f} "
            f"({r['cpu'][2]:.2f}) | {r['clock_ms']:.1f} "
            f"(+-{r['trip_ms'] / 2:.1f}) |"
        )
    text = "\n".join(lines) + "\n"
    print(text)
    if args.append is not None:
        put_section(args.append, text)


if __name__ == "__main__":
    main()
