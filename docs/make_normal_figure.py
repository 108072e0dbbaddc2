"""Regenerate docs/normal_refinement.png and the table in docs/normal_refinement.md.

Run: .venv/bin/python docs/make_normal_figure.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from cbp.collision import MetaballRefiner

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the study's folder
from tests.collision.normals_study import (
    DistanceFieldNormals,
    angle_errors,
    tilted_plane,
    yawed_box,
)

HERE = Path(__file__).parent
METHODS = {
    "raw normal (the link's, toward the nearest cell)": None,
    "metaball R=1.5 cells at the witness (CAT paper)": MetaballRefiner(
        radius_cells=1.5, offset_cells=0.0
    ),
    "metaball R=3 cells, 0.5 cell out (shipped)": MetaballRefiner(),
    "distance-field gradient, 1.5 cells out": DistanceFieldNormals(1.5),
    "distance-field gradient, 3 cells out": DistanceFieldNormals(3.0),
}
SURFACES = {
    "plane tilted 10 deg": tilted_plane(10.0),
    "plane tilted 20 deg": tilted_plane(20.0),
    "plane tilted 30 deg": tilted_plane(30.0),
    "plane tilted 45 deg": tilted_plane(45.0),
    "box yawed 30 deg": yawed_box(30.0),
}


def main() -> None:
    """Measure every method on every surface; write the figure and the table."""
    rows = []
    fig, ax = plt.subplots(figsize=(10, 4.5))
    width = 0.8 / len(METHODS)
    for m, (method, refiner) in enumerate(METHODS.items()):
        medians = []
        for surface, (cells, sample) in SURFACES.items():
            errors = angle_errors(cells, sample, refiner, probes=50)
            med, p90 = float(np.median(errors)), float(np.percentile(errors, 90))
            medians.append(med)
            rows.append(f"| {surface} | {method} | {med:.1f} | {p90:.1f} |")
        x = np.arange(len(SURFACES)) + (m - (len(METHODS) - 1) / 2) * width
        ax.bar(x, medians, width, label=method)
    ax.set_xticks(np.arange(len(SURFACES)), list(SURFACES), fontsize=8)
    ax.set_ylabel("median normal error [deg]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "normal_refinement.png", dpi=120)
    table = "\n".join(
        ["| surface | method | median [deg] | p90 [deg] |", "|---|---|---|---|", *rows]
    )
    text = (HERE / "normal_refinement.md").read_text()
    start = text.index("<!-- table -->") + len("<!-- table -->")
    end = text.index("<!-- /table -->")
    (HERE / "normal_refinement.md").write_text(
        text[:start] + "\n" + table + "\n" + text[end:]
    )


if __name__ == "__main__":
    main()
