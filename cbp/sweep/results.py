# SPDX-License-Identifier: Apache-2.0
"""A sweep's results: one table of every run, a report with summaries and plots.

``DIR/results.parquet`` (with pyarrow) and ``DIR/results.csv``: one row per run
with its id, scenario, method, seed, swept values (a column per key, prefixed
``set.``), status, error, attempts, wall time and real-time factor, and every
metric of :func:`cbp.metrics.run_metrics`.

``DIR/report.md``: per method, the runs done and failed, the reach rate, the
contact-force distribution, response and total time; box plots of those per
method; and each metric against each swept numeric value.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cbp.plots import colour, readable_axes

if TYPE_CHECKING:
    from cbp.sweep.runner import SweepOutcome
    from cbp.sweep.spec import SweepSpec

__all__ = ["table_rows", "write_results"]

#: Metrics drawn per method and against the swept values.
PLOTTED = (
    "peak_contact_force_n",
    "total_time_s",
    "response_time_s",
    "final_position_error_m",
)


def table_rows(outcome: SweepOutcome) -> list[dict[str, Any]]:
    """One flat row per run of the sweep, in run order (done or not)."""
    rows = []
    for run in outcome.runs:
        record = outcome.records.get(run.id)
        row: dict[str, Any] = {
            "id": run.id,
            "scenario_file": run.scenario,
            "scenario": record.get("scenario") if record else None,
            "method": run.method,
            "seed": run.seed,
            **{f"set.{k}": v for k, v in run.values.items()},
            "status": record["status"] if record else "not run",
            "error": record.get("error") if record else None,
            "attempts": record.get("attempts") if record else 0,
            "wall_s": record.get("wall_s") if record else None,
            "sim_s": record.get("sim_s") if record else None,
        }
        wall, sim = row["wall_s"], row["sim_s"]
        row["realtime_factor"] = sim / wall if wall and sim else None
        for key, value in ((record or {}).get("metrics") or {}).items():
            if isinstance(value, bool | int | float | str) or value is None:
                row[key] = value
        rows.append(row)
    return rows


def write_results(outcome: SweepOutcome, spec: SweepSpec, path: Path) -> None:
    """results.parquet, results.csv, report.md and figures in ``outcome.out``."""
    out = outcome.out
    rows = table_rows(outcome)
    columns = list(dict.fromkeys(k for row in rows for k in row))
    _write_csv(out / "results.csv", rows, columns)
    _write_parquet(out / "results.parquet", rows, columns)
    figures = _plots(rows, list(spec.grid) + _sampled(spec), out)
    lines = [
        f"# Sweep {spec.name}",
        "",
        f"From `{path}`: {len(outcome.runs)} runs ({outcome.skipped} done before "
        f"this invocation), clock `{spec.clock}`, backend {outcome.backend}.",
        "",
        "| method | runs | ok | errors | failed | reached | peak force median / "
        "p90 / max [N] | response median [s] | total median [s] | "
        "real-time factor median |",
        "|---|---:|---:|---:|---:|---:|---|---:|---:|---:|",
    ]
    for method in spec.methods:
        mine = [r for r in rows if r["method"] == method]
        ok = [r for r in mine if r["status"] == "ok"]
        force = _values(ok, "peak_contact_force_n")
        shown = (
            f"{np.median(force):.3g} / {np.percentile(force, 90):.3g} / "
            f"{np.max(force):.3g}"
            if force.size
            else "n/a"
        )
        reached = _values(ok, "reached")
        lines.append(
            f"| {method} | {len(mine)} | {len(ok)} | "
            f"{sum(r['status'] == 'error' for r in mine)} | "
            f"{sum(r['status'] == 'failed' for r in mine)} | "
            + (f"{np.mean(reached) * 100:.0f} %" if reached.size else "n/a")
            + f" | {shown} | {_median(ok, 'response_time_s')} | "
            f"{_median(ok, 'total_time_s')} | {_median(ok, 'realtime_factor')} |"
        )
    lines += ["", *(f"![{f.stem}]({f.name})" for f in figures), ""]
    problems = [r for r in rows if r["status"] not in ("ok", "not run")]
    if problems:
        lines += ["## Runs that did not finish", ""]
        lines += [
            f"- `{r['id']}` ({r['method']}, {Path(r['scenario_file']).name}): "
            f"{r['status']}: {r['error']}"
            for r in problems
        ]
        lines.append("")
    (out / "report.md").write_text("\n".join(lines) + "\n")


def _sampled(spec: SweepSpec) -> list[str]:
    return list(spec.samples.values) if spec.samples is not None else []


def _values(rows: list[dict[str, Any]], key: str) -> np.ndarray:
    values = [r.get(key) for r in rows]
    return np.array(
        [float(v) for v in values if v is not None and math.isfinite(float(v))]
    )


def _median(rows: list[dict[str, Any]], key: str) -> str:
    values = _values(rows, key)
    return f"{np.median(values):.3g}" if values.size else "n/a"


def _write_csv(path: Path, rows: list[dict[str, Any]], columns: list[str]) -> None:
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    tmp.replace(path)


def _write_parquet(path: Path, rows: list[dict[str, Any]], columns: list[str]) -> None:
    """The table through pyarrow (skipped, with the CSV kept, without it)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return
    data = {c: [_cell(r.get(c)) for r in rows] for c in columns}
    table = pa.table({c: pa.array(v) for c, v in data.items()})
    tmp = path.with_suffix(".parquet.tmp")
    pq.write_table(table, tmp)
    tmp.replace(path)


def _cell(value: Any) -> Any:
    """Parquet columns have one type: lists and mappings become text."""
    if isinstance(value, list | dict):
        return str(value)
    return value


@readable_axes
def _plots(rows: list[dict[str, Any]], swept: list[str], out: Path) -> list[Path]:
    """Box plots per method, and each metric against each swept value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r["status"] == "ok"]
    methods = list(dict.fromkeys(r["method"] for r in ok))
    metrics = [m for m in PLOTTED if any(r.get(m) is not None for r in ok)]
    paths: list[Path] = []
    if not ok or not metrics:
        return paths
    fig, axes = plt.subplots(1, len(metrics), figsize=(4 * len(metrics), 4))
    for ax, metric in zip(np.atleast_1d(axes), metrics, strict=True):
        data = [_values([r for r in ok if r["method"] == m], metric) for m in methods]
        ax.boxplot([d if d.size else [np.nan] for d in data], tick_labels=methods)
        ax.set_title(metric)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    paths.append(out / "by_method.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    for key in swept:
        column = f"set.{key}"
        if not all(isinstance(r.get(column), int | float) for r in ok):
            continue
        fig, axes = plt.subplots(1, len(metrics), figsize=(4 * len(metrics), 4))
        for ax, metric in zip(np.atleast_1d(axes), metrics, strict=True):
            for m in methods:
                mine = [r for r in ok if r["method"] == m and r.get(metric) is not None]
                ax.plot(
                    [r[column] for r in mine],
                    [r[metric] for r in mine],
                    "o",
                    alpha=0.6,
                    color=colour(m),
                    label=m,
                )
            ax.set_xlabel(key)
            ax.set_title(metric)
            ax.grid(alpha=0.3)
        np.atleast_1d(axes)[0].legend()
        fig.tight_layout()
        paths.append(out / f"vs_{key.replace('.', '_')}.png")
        fig.savefig(paths[-1], dpi=90)
        plt.close(fig)
    return paths
