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
  starts to be commanded to the robot (the splice point), and its stages: the
  control loop took the goal, planned for it, commanded it
  (:class:`~cbp.teleop.goal_session.Commanded`);
- **hand drawn**: to the end of the animation frame that drew a hand moved
  1 mm toward the new goal. The server sends the robot's pose at each change
  of the session, ahead of each page update (a marker of the hand in the
  panel at each update); a script installed before the page's own
  records when each message batch from viser's websocket worker reaches the
  page's main thread and when each animation frame that issues WebGL draws
  begins and ends. The batch that carried the moved hand is the first to
  arrive after the server sent it; the frame that drew it, the first drawing
  frame to begin after that (viser applies a batch at the start of a frame).
  The GL commands are issued then; SwiftShader rasterizes them and the
  compositor shows them after, so the start of the next drawing frame is
  given too. The earlier measure (the panel's marker changed, watched by a
  MutationObserver, then the next animation frame) is printed as well.

Idle, and with two CPU-bound processes beside it (``--burners``; started once
the page is up). The browser and the server read the same system clock; the
script checks that they agree (their difference is printed). The load average
is recorded: the machine may be shared.

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
from teleop_latency import publish_table  # this folder: scripts run from it

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
window.cbpLong = [];
new PerformanceObserver(list => {
  for (const e of list.getEntries()) window.cbpLong.push(e.duration);
}).observe({entryTypes: ['longtask']});
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
# (viser's client receives in a web worker) reaches the page's main thread, and
# the start and end of each animation frame that drew the scene (WebGL draws).
_MESSAGES = """
window.cbpMessages = [];
window.cbpFrames = [];
window.cbpDraws = 0;
for (const C of [WebGLRenderingContext, WebGL2RenderingContext]) {
  for (const f of ['drawElements', 'drawArrays', 'drawElementsInstanced',
                   'drawArraysInstanced']) {
    const native = C.prototype[f];
    if (native) C.prototype[f] = function (...a) {
      window.cbpDraws++;
      return native.apply(this, a);
    };
  }
}
const nativeFrame = window.requestAnimationFrame.bind(window);
window.requestAnimationFrame = cb => nativeFrame(ts => {
  const draws = window.cbpDraws;
  const start = performance.timeOrigin + performance.now();
  try { cb(ts); } finally {
    if (window.cbpDraws > draws) window.cbpFrames.push(
      [start, performance.timeOrigin + performance.now()]);
  }
});
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


def measure(
    keys: int, burners: int, dpr: float | None = None, flags: tuple[str, ...] = ()
) -> dict[str, Any]:
    """One session: ``keys`` key presses, ``burners`` CPU-bound processes beside it.

    ``dpr``: the page's pixel ratio (viser's ``fixedDpr``; None: its adaptive one).
    ``flags``: Chromium's command-line flags beyond the tests' own.
    """
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    sys.path.insert(0, str(ROOT))
    from tests.conftest import headless_chromium

    session = TeleopSession(ROOT / "scenarios" / "cat_boards.yaml", "cat")
    page = TeleopPage(session, port=0)
    marker = page.server.gui.add_markdown("hand x 0")
    update, send_first = page.update, page.send_first

    # (server time, the hand's x) per robot pose sent: ahead of each update,
    # alone, and at each change between updates (TeleopPage.update_first).
    sent: list[tuple[float, float]] = []
    page_cpu = [0.0]
    posed = [page.posed]
    # When the pose's messages were queued (sent at the end of the batch).
    queued = [0.0]
    assert page.robot_pose is not None
    pose = page.robot_pose.pose

    def timed_pose(values: Any) -> bool:
        queued[0] = time.time()
        return pose(values)

    page.robot_pose.pose = timed_pose  # type: ignore[method-assign]

    def record() -> None:
        if page.posed is not posed[0] and page.posed is not None:
            posed[0] = page.posed
            sent.append((queued[0], float(page.posed[1][0])))

    def marked() -> None:
        start = time.thread_time()
        update()
        page_cpu[0] += time.thread_time() - start
        record()
        if page.shown is not None:
            marker.content = f"hand x {float(page.shown.hand[0]):.5f}"

    def first() -> bool:
        start = time.thread_time()
        done = send_first()
        page_cpu[0] += time.thread_time() - start
        record()
        return done

    page.update = marked  # type: ignore[method-assign]
    page.send_first = first  # type: ignore[method-assign]
    arrivals: dict[int, float] = {}
    set_goal = session.goal.set

    def stamped(position: Any, rotation: Any) -> int:
        number = set_goal(position, rotation)
        arrivals[number] = time.time()
        return number

    session.goal.set = stamped  # type: ignore[method-assign]
    burning: list[subprocess.Popen[bytes]] = []
    browser = headless_chromium(flags)
    # On a shared machine beside the CPU-bound processes, one answer of the
    # page took over the driver's default 120 s.
    browser.command_executor.client_config.timeout = 300
    load = [os.getloadavg()[0]]
    try:
        session.start()
        page.start()
        browser.execute_cdp_cmd(
            "Page.addScriptToEvaluateOnNewDocument", {"source": _MESSAGES}
        )
        browser.get(page.url if dpr is None else f"{page.url}/?fixedDpr={dpr:g}")
        deadline = time.monotonic() + 120
        while not browser.find_elements(By.XPATH, "//button[normalize-space()='+x']"):
            if time.monotonic() > deadline:
                raise RuntimeError("the page never showed its jog buttons")
            time.sleep(0.2)
        browser.execute_script(_WATCH)
        # Started once the page is up (on a loaded machine, Chromium beside
        # them took over the driver's 120 s to load it).
        burning += [
            subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(burners)
        ]
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
        long_tasks = browser.execute_script("return window.cbpLong")
        frames = np.array(browser.execute_script("return window.cbpFrames")) / 1e3
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
    drawn, next_frame = [], []
    # The moved hand's way through the browser: server sent -> main thread
    # got the batch -> the frame that drew it began -> ended [ms].
    browser_part: dict[str, list[float]] = {"received": [], "begun": [], "drawn": []}
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
        if not moved_sent:
            continue
        # The batch that carried it: the first to reach the page after it was
        # sent (the clocks agree to about 2 ms); the frame that drew it: the
        # first frame with WebGL draws that began after the batch came.
        got = messages[messages >= moved_sent[0] - 0.002]
        if not got.size or not frames.size:
            continue
        after = frames[frames[:, 0] >= got[0]]
        if not after.size:
            continue
        begun, ended = after[0]
        later = frames[frames[:, 0] >= ended]
        browser_part["received"].append(1e3 * (got[0] - moved_sent[0]))
        browser_part["begun"].append(1e3 * (begun - got[0]))
        browser_part["drawn"].append(1e3 * (ended - begun))
        drawn.append(1e3 * (ended - pressed))
        if later.size:
            next_frame.append(1e3 * (later[0, 0] - pressed))
    return {
        "burners": burners,
        "dpr": dpr,
        "keys": len(keys_at),
        "goals": len(numbers),
        "to_server": _percentiles(to_server),
        "to_command": _percentiles(to_command),
        "stages": {k: _percentiles(v) for k, v in stages.items()},
        "browser": {k: _percentiles(v) for k, v in browser_part.items()},
        "long_tasks": (len(long_tasks), sum(long_tasks) / 1e3 / wall),
        "n_command": len(to_command),
        "on_dom": _percentiles(on_dom),
        "to_sent": _percentiles(to_sent),
        "on_page": _percentiles(on_page),
        "drawn": _percentiles(drawn),
        "next_frame": _percentiles(next_frame),
        "frame_ms": _percentiles(list(1e3 * np.diff(frames[:, 0])))
        if len(frames) > 1
        else (float("nan"),) * 2,
        "n_page": len(on_page),
        "clock_ms": clock_ms,
        "trip_ms": trip_ms,
        "cpu": cpu,
        "load": (min(load), max(load)),
        "misses": sum(1 for p in session.parts.log.periods if p.missed),
        "late": sum(
            "made after their lead" in p.note for p in session.parts.log.periods
        ),
        "periods": len(session.parts.log.periods),
    }


def main() -> None:
    """Measure idle and beside CPU-bound processes; print or append."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keys", type=int, default=60)
    parser.add_argument("--burners", type=int, default=2)
    parser.add_argument("--append", type=Path, default=None)
    parser.add_argument(
        "--dpr", type=float, default=None, help="the page's fixed pixel ratio"
    )
    parser.add_argument(
        "--flag",
        action="append",
        default=[],
        help="a Chromium flag (repeat for more), e.g. --flag=--disable-gpu-compositing",
    )
    parser.add_argument(
        "--only", type=int, default=None, help="one row: this many CPU-bound processes"
    )
    args = parser.parse_args()
    loads = (0, args.burners) if args.only is None else (args.only,)
    rows = []
    for burners in loads:
        rows.append(r := measure(args.keys, burners, args.dpr, tuple(args.flag)))
        print(
            f"{r['burners']} CPU-bound: goal arrival -> taken by the loop -> "
            "planned -> commanded, median / p95 [ms]: "
            + ", ".join(f"{a:.1f} / {b:.1f}" for a, b in r["stages"].values())
            + f"; periods with a plan made after its lead: {r['late']}"
        )
        print(
            f"{r['burners']} CPU-bound: moved hand sent -> batch on the page's main "
            "thread -> the frame that drew it begun -> ended, median / p95 [ms]: "
            + ", ".join(f"{a:.1f} / {b:.1f}" for a, b in r["browser"].values())
            + "; the page's main thread in tasks over 50 ms: "
            f"{r['long_tasks'][1]:.0%} of the time ({r['long_tasks'][0]} tasks); "
            f"frames drawn every {r['frame_ms'][0]:.0f} / {r['frame_ms'][1]:.0f} ms; "
            f"hand drawn {r['drawn'][0]:.0f} / {r['drawn'][1]:.0f} ms after the key, "
            f"next frame {r['next_frame'][0]:.0f} / {r['next_frame'][1]:.0f} ms; "
            f"the earlier measure (panel marker, then a frame) {r['on_page'][0]:.0f}"
            f" / {r['on_page'][1]:.0f} ms"
        )
    dpr = "" if args.dpr is None else f" (`?fixedDpr={args.dpr:g}`)"
    if args.flag:
        dpr += " with " + " ".join(f"`{f}`" for f in args.flag)
    lines = [
        "",
        "## Teleoperation: latency from a key in the browser "
        "(benchmarks/teleop_browser_latency.py)",
        "",
        f"Boards, CAT, the page in headless Chromium{dpr} (software WebGL), "
        "updated at each change of the session (at most "
        f"{MAX_UPDATE_RATE:g} Hz); {args.keys} presses of the page's w and s keys "
        "(real key events through ChromeDriver, 0.3 s apart; each jogs the goal "
        "2 cm along x). From the key event in the page to the goal's arrival in "
        "the session (to server), to the first command of the trajectory planned "
        "for it (to command; its stages, medians: the loop took the goal, "
        "planned for it, commanded it), and to the end of the animation frame "
        f"that drew the hand moved {MOVED * 1e3:g} mm toward the new goal (hand "
        "drawn: the first frame with WebGL draws after the batch that carried "
        "it reached the page's main thread; SwiftShader's rasterization and "
        "the compositor come after it, so also the next drawing frame's start). "
        "The moved hand's way, medians: sent by the server, its batch on the "
        "page's main thread, the drawing frame begun, ended. "
        f"{platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}. Command: `.venv/bin/python "
        "benchmarks/teleop_browser_latency.py --append benchmarks/RESULTS.md`.",
        "",
        "| CPU-bound processes | load average | keys / goals | to server median / p95 [ms] | to command median / p95 [ms] | taken / planned / commanded, medians [ms] | hand drawn median / p95 [ms] | next frame median / p95 [ms] | sent / on page / frame begun / drawn, medians [ms] | frame interval median [ms] | deadline misses | CPU: Chromium / session (page updates) [cores] | browser clock - server clock [ms] |",
        "|---:|---|---:|---:|---:|---|---:|---:|---|---:|---:|---|---:|",
    ]
    publish_table(lines, [_row(r) for r in rows], args.append)


def _row(r: dict[str, Any]) -> str:
    """One row of the table: a session's figures."""
    st, br = r["stages"], r["browser"]
    sent = r["to_sent"][0]
    on_page = sent + br["received"][0]
    begun = on_page + br["begun"][0]
    return (
        f"| {r['burners']} | {r['load'][0]:.1f}-{r['load'][1]:.1f} | "
        f"{r['keys']} / {r['goals']} | "
        f"{r['to_server'][0]:.1f} / {r['to_server'][1]:.1f} | "
        f"{r['to_command'][0]:.1f} / {r['to_command'][1]:.1f} | "
        f"{st['taken'][0]:.1f} / {st['planned'][0]:.1f} / "
        f"{st['commanded'][0]:.1f} | "
        f"{r['drawn'][0]:.0f} / {r['drawn'][1]:.0f} | "
        f"{r['next_frame'][0]:.0f} / {r['next_frame'][1]:.0f} | "
        f"{sent:.0f} / {on_page:.0f} / {begun:.0f} / "
        f"{begun + br['drawn'][0]:.0f} | {r['frame_ms'][0]:.0f} | "
        f"{r['misses']} of {r['periods']} | {r['cpu'][0]:.2f} / {r['cpu'][1]:.2f} "
        f"({r['cpu'][2]:.2f}) | {r['clock_ms']:.1f} "
        f"(+-{r['trip_ms'] / 2:.1f}) |"
    )


if __name__ == "__main__":
    main()
