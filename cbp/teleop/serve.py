# SPDX-License-Identifier: Apache-2.0
"""``cbp teleop``: serve a live session's page until its stop, then save it."""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

from cbp.errors import CbpError, ConfigError
from cbp.teleop.goal_page import TeleopPage
from cbp.teleop.goal_session import TeleopSession, latency_summary
from cbp.teleop.input_session import InputSession
from cbp.teleop.inputs_page import InputsPage

__all__ = ["serve_teleop"]


def serve_teleop(
    scenarios: list[Path],
    method: str,
    host: str,
    port: int,
    out: Path | None,
    overrides: dict[str, str],
) -> int:
    """``cbp teleop``: serve the session until the page's stop or Ctrl-C.

    One scenario of a trajectory executor: a goal session
    (:class:`TeleopPage`). Velocity-executor scenarios (one or several
    configurations of one robot, switched on the page): an input session
    (:class:`InputsPage`). Then the outputs are written. Exit 2 for a scenario
    or method that cannot start (nothing runs).
    """
    from cbp.files import check_output_folder
    from cbp.scenario import load_scenario

    page: TeleopPage | InputsPage
    try:
        first = load_scenario(scenarios[0])
        velocity = first.spec.method.name == "velocity"
        if not velocity and len(scenarios) > 1:
            raise ConfigError(
                "several scenarios are configurations of the velocity executor "
                "to switch between; a goal session takes one"
            )
        out = out or Path("out") / f"{first.spec.name}_teleop"
        check_output_folder(out)
        if velocity:
            inputs = InputSession(scenarios, overrides)
            page = InputsPage(inputs, host=host, port=port)
            inputs.start()
        else:
            session = TeleopSession(scenarios[0], method, overrides)
            page = TeleopPage(session, host=host, port=port)
            session.start()
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    print(f"teleoperation of {scenarios[0]}: {page.url} (stop on the page or Ctrl-C)")
    try:
        with contextlib.suppress(KeyboardInterrupt):
            page.run()
    finally:
        page.close()
    if velocity:
        inputs.write(inputs.stop(), out)
        print(f"wrote {out}")
        return 0
    session.stop()
    goal_file = session.write(out)
    latency = latency_summary(session.latency_ms())
    print(
        f"wrote {out}; the operator's goals: {goal_file} "
        f"(replay: cbp compare {scenarios[0]} --goal {goal_file})"
    )
    if latency["n"]:
        print(
            f"goal-to-command latency: median {latency['median_ms']:.1f} ms, "
            f"p95 {latency['p95_ms']:.1f} ms over {latency['n']} goals"
        )
    return 0
