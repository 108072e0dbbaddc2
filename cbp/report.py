# SPDX-License-Identifier: Apache-2.0
"""Outputs of a run: trace.csv, metrics.json, plots and report.md.

One writer for every executor, one method or several (:func:`write_outputs`):
each file holds the columns, metrics and figures the traces have
(:class:`~cbp.trace.Trace`).
"""

from __future__ import annotations

import contextlib
import csv
import json
import logging
import shutil
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.files import OutputClaim, claim_output_folder
from cbp.interrupts import Interrupted, SignalGuard
from cbp.metrics import run_metrics
from cbp.plots import plot_runs
from cbp.robot import FloatArray
from cbp.scenario.runtime import Scenario
from cbp.scene_file import write_scene
from cbp.story import SCENE_FIGURE, plot_scene, run_sentence
from cbp.trace import Trace

__all__ = ["summary_line", "write_outputs"]

log = logging.getLogger(__name__)

#: Events listed in report.md per method (all of them are in metrics.json).
REPORT_EVENTS = 50


def write_outputs(
    scenario: Scenario,
    traces: Mapping[str, Trace],
    out: Path,
    extra_files: Mapping[str, Path] | None = None,
    claim: OutputClaim | None = None,
    guard: SignalGuard | None = None,
) -> dict[str, dict[str, Any]]:
    """Write the outputs of one or several runs of ``scenario`` as the folder ``out``.

    First the record, put in place as a whole (an earlier output there is
    replaced, concurrent runs never mix their files: :meth:`OutputClaim.publish
    <cbp.files.OutputClaim.publish>`): ``trace.csv`` (``trace_<method>.csv``
    for several methods), ``metrics.json`` (one object per method, with its
    events), ``scene.json`` (for ``cbp view``) and copies of ``extra_files``
    (by name). Then the figures (:func:`cbp.plots.plot_runs`, the scene's)
    and ``report.md``, each put in place whole, and ``metrics.json`` again.

    A stop signal (SIGINT, SIGTERM, SIGHUP) never loses the record: while it
    is written one is only noted; while the figures and the report are drawn
    one cuts them short, and ``metrics.json`` lists them as not written.
    ``guard`` is the caller's :class:`~cbp.interrupts.SignalGuard`, installed
    around the call; without one, the call installs its own and, once the
    outputs are safe, delivers what it noted as it would have been (SIGTERM
    ends the process, Ctrl-C raises KeyboardInterrupt).

    A stage after the control loop that fails (the metrics, the plots, the
    scene description, the report) leaves the others written, an event names
    it and ``incomplete`` in ``metrics.json`` lists it (with the trace's own,
    the clearance for example: :attr:`~cbp.trace.Trace.incomplete`).

    ``claim`` is the folder claimed for ``out`` when the run began
    (:func:`cbp.files.claim_output_folder`); without one, it is claimed now,
    removing what dead processes left but refusing nothing (the run is over:
    its outputs must be kept).

    Returns:
        The metrics, by method.

    Raises:
        ConfigError: ``out`` holds something other than a cbp output (the
            record is kept beside it; the message says where).
    """
    claim = claim or claim_output_folder(out, refuse_live=False)
    own = guard is None
    guard = guard or SignalGuard()
    with guard if own else contextlib.nullcontext(guard):
        try:
            metrics = _write_record(scenario, traces, claim, extra_files or {})
        except BaseException:
            claim.release(remove=not claim.released)
            raise
        try:
            _write_figures(scenario, traces, metrics, claim, guard)
        finally:
            claim.release(remove=True)
    if own:
        guard.deliver()
    return metrics


def _write_record(
    scenario: Scenario,
    traces: Mapping[str, Trace],
    claim: OutputClaim,
    extra_files: Mapping[str, Path],
) -> dict[str, dict[str, Any]]:
    """The traces, metrics, scene description and extra files, put in place whole.

    On a ConfigError from :meth:`~cbp.files.OutputClaim.publish` (``out``
    changed meanwhile) the claim is released and its folder kept.
    """
    staging = claim.staging
    end = max((float(t.t[-1]) for t in traces.values() if t.t.size), default=0.0)
    metrics = {name: _metrics(trace, scenario) for name, trace in traces.items()}
    for name, trace in traces.items():
        csv_name = "trace.csv" if len(traces) == 1 else f"trace_{name}.csv"
        _write_csv(trace, staging / csv_name)
    try:
        write_scene(staging, scenario, end)
    except Exception as exc:  # the replay needs it, the rest does not
        for trace in traces.values():
            _failed_stage(trace, "scene description", exc)
    for name, source in extra_files.items():
        shutil.copyfile(source, staging / name)
    _settle(metrics, traces)
    (staging / "metrics.json").write_text(_metrics_document(metrics, traces))
    try:
        claim.publish()
    except ConfigError:
        claim.release()
        raise
    log.info("%s: trace and metrics written; drawing the figures", claim.out)
    return metrics


def _write_figures(
    scenario: Scenario,
    traces: Mapping[str, Trace],
    metrics: dict[str, dict[str, Any]],
    claim: OutputClaim,
    guard: SignalGuard,
) -> None:
    """The figures and report.md, then metrics.json again; a signal cuts them short.

    The stages a signal leaves undone are listed under ``incomplete``.
    """
    staging, title = claim.staging, scenario.spec.name
    figures: list[Path] = []
    scene: Path | None = None
    stages = ["plots", "scene figure", "report"]
    try:
        with guard.interruptible():
            try:
                figures = plot_runs(traces, staging, title)
            except Exception as exc:
                _failed_stages(traces, "plots", exc)
            stages.remove("plots")
            try:
                objects = scenario.spec.world.objects
                scene = plot_scene(objects, traces, staging / SCENE_FIGURE, title)
            except Exception as exc:
                _failed_stages(traces, "scene figure", exc)
            stages.remove("scene figure")
            for figure in [*figures, *([scene] if scene else [])]:
                claim.put(figure.name)
            _settle(metrics, traces)
            try:
                report = _report(scenario, traces, metrics, figures, scene)
            except Exception as exc:
                _failed_stages(traces, "report", exc)
                report = f"# {title}\n\nNo report: see metrics.json.\n"
            stages.remove("report")
            (staging / "report.md").write_text(report)
            claim.put("report.md")
    except Interrupted as exc:
        for stage in stages:
            _failed_stages(traces, stage, exc)
    _settle(metrics, traces)
    (staging / "metrics.json").write_text(_metrics_document(metrics, traces))
    claim.put("metrics.json")


def _metrics_document(
    metrics: Mapping[str, Mapping[str, Any]], traces: Mapping[str, Trace]
) -> str:
    """metrics.json: each method's metrics with its events."""
    document = {
        name: {
            **metrics[name],
            "events": [{"t": t, "message": m} for t, m in trace.events],
        }
        for name, trace in traces.items()
    }
    return json.dumps(document, indent=2) + "\n"


def _failed_stages(traces: Mapping[str, Trace], stage: str, exc: BaseException) -> None:
    """Record that ``stage`` failed for every trace."""
    for trace in traces.values():
        _failed_stage(trace, stage, exc)


def _failed_stage(trace: Trace, stage: str, exc: BaseException) -> None:
    """Record that ``stage`` failed for ``trace``: an event and ``incomplete``."""
    from cbp.run.faults import describe

    end = float(trace.t[-1]) if trace.t.size else 0.0
    trace.events.append((end, f"{stage} not written: {describe(exc)}"))
    trace.incomplete.append(stage)


def _metrics(trace: Trace, scenario: Scenario) -> dict[str, Any]:
    """The run's metrics; the ones every run has when they cannot be computed."""
    try:
        return run_metrics(trace, scenario.robot)
    except Exception as exc:
        _failed_stage(trace, "metrics", exc)
        return {
            "samples": int(trace.t.size),
            "events": len(trace.events),
            "aborted": trace.aborted,
        }


def _settle(metrics: dict[str, dict[str, Any]], traces: Mapping[str, Trace]) -> None:
    """Count the events (failed stages add some) and list the failed stages."""
    for name, trace in traces.items():
        metrics[name]["events"] = len(trace.events)
        if trace.incomplete:
            metrics[name]["incomplete"] = list(trace.incomplete)


def _report(
    scenario: Scenario,
    traces: Mapping[str, Trace],
    metrics: Mapping[str, Mapping[str, Any]],
    figures: list[Path],
    scene: Path | None,
) -> str:
    """report.md: a sentence per method, the scene, the metrics, the figures, events."""
    keys = list(dict.fromkeys(k for m in metrics.values() for k in m))
    story = [run_sentence(name, trace, metrics[name]) for name, trace in traces.items()]
    lines = [
        f"# {scenario.spec.name}: {', '.join(traces)}",
        "",
        scenario.spec.description.strip(),
        "",
        *(f"- {sentence}" for sentence in story if sentence),
        "",
        *(
            [f"![the scene, the goal's path and each method's hand path]({scene.name})"]
            if scene is not None
            else []
        ),
        "",
        "| metric | " + " | ".join(traces) + " |",
        "|---|" + "---|" * len(traces),
        *(
            f"| {key} | "
            + " | ".join(_fmt(metrics[m].get(key, "")) for m in traces)
            + " |"
            for key in keys
        ),
        "",
        *(f"![{f.stem}]({f.name})" for f in figures),
        "",
    ]
    for name, trace in traces.items():
        if trace.events:
            lines += [f"## Events: {name}", ""]
            lines += [f"- t = {t:.3f} s: {m}" for t, m in trace.events[:REPORT_EVENTS]]
            if len(trace.events) > REPORT_EVENTS:
                more = len(trace.events) - REPORT_EVENTS
                lines.append(f"- ... {more} more in metrics.json")
            lines.append("")
    return "\n".join(lines) + "\n"


def summary_line(scenario: Scenario, method: str, metrics: Mapping[str, Any]) -> str:
    """One line that sums up a run for the terminal, from the metrics it has."""
    parts = [f"{scenario.spec.name} ({method}):"]
    if "reached" in metrics:
        error = metrics["final_position_error_m"]
        shown = "n/a" if error is None else f"{error * 1e3:.1f} mm"
        parts.append(f"reached {metrics['reached']}, final error {shown},")
    if "peak_contact_force_n" in metrics:
        parts.append(f"peak contact force {metrics['peak_contact_force_n']:.1f} N,")
    if metrics.get("distance_error_max_m") is not None:
        parts.append(
            f"distance error <= {metrics['distance_error_max_m'] * 1e3:.1f} mm,"
        )
    if metrics.get("view_error_max_deg") is not None:
        parts.append(f"view error <= {metrics['view_error_max_deg']:.2f} deg,")
    parts.append(f"{metrics['samples']} samples, {metrics['events']} events")
    if metrics.get("aborted"):
        parts.append(f"; ABORTED: {metrics['aborted']}")
    return " ".join(parts)


def _fmt(value: object) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _write_csv(trace: Trace, path: Path) -> None:
    """One row per sample, one column per recorded value."""
    columns = dict(_columns(trace))
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["t", *columns])
        values = np.column_stack(list(columns.values()))
        for t, row in zip(trace.t, values, strict=True):
            writer.writerow([f"{t:.4f}", *(f"{v:.6g}" for v in row)])


def _columns(trace: Trace) -> Iterator[tuple[str, FloatArray]]:
    """(name, column) of everything the trace recorded, in a fixed order."""
    for prefix, positions, rotations in (
        ("goal", trace.goal_position, trace.goal_rotation),
        ("ee", trace.ee_position, trace.ee_rotation),
    ):
        quaternions = np.array([_quaternion(R) for R in rotations]).reshape(-1, 4)
        for i, c in enumerate("xyz"):
            yield f"{prefix}_{c}", positions[:, i]
        for i, c in enumerate(("qx", "qy", "qz", "qw")):
            yield f"{prefix}_{c}", quaternions[:, i]
    yield from _named("q", trace.q, trace.q_names)
    if trace.q_cmd is not None:
        yield from _named("q_cmd", trace.q_cmd, trace.q_names)
    if trace.u is not None:
        yield from _named("u", trace.u, trace.v_names)
    for name in (
        "compute_s",
        "contact_force",
        "wrist_force",
        "penetration",
        "clearance",
        "step_penetration",
    ):
        column = getattr(trace, name)
        if column is not None:
            yield name, column
    for name, values in trace.inputs.items():
        for i, column in enumerate(np.reshape(values, (trace.t.size, -1)).T):
            yield f"input_{name}_{i}", column
    yield from trace.signals.items()


def _named(
    prefix: str, values: FloatArray, names: list[str]
) -> Iterator[tuple[str, FloatArray]]:
    """Columns ``<prefix>_<name>``, or ``<prefix><i>`` without a name per column."""
    n = values.shape[1]
    labels = [f"{prefix}_{x}" for x in names] if len(names) == n else None
    for i in range(n):
        yield (labels[i] if labels else f"{prefix}{i}"), values[:, i]


def _quaternion(R: FloatArray) -> FloatArray:
    """(x, y, z, w) of a rotation matrix; NaN if it is not finite."""
    if not np.all(np.isfinite(R)):
        return np.full(4, np.nan)
    q = pin.Quaternion(np.asarray(R))
    return np.array([q.x, q.y, q.z, q.w])
