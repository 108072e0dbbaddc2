"""Metaball normal refinement against voxelised tilted planes and a yawed box."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.collision import MetaballRefiner
from tests.collision.normals_study import (
    DistanceFieldNormals,
    angle_errors,
    tilted_plane,
    yawed_box,
)

PAPER = MetaballRefiner(radius_cells=1.5, offset_cells=0.0)


@pytest.mark.parametrize(
    "surface",
    [tilted_plane(20.0), tilted_plane(30.0), yawed_box(30.0)],
    ids=["plane-20deg", "plane-30deg", "box-yaw-30deg"],
)
def test_shipped_refinement_beats_the_paper_setting_and_bounds_the_worst_case(
    surface,
) -> None:
    cells, sample = surface
    raw = angle_errors(cells, sample, None, probes=20)
    paper = angle_errors(cells, sample, PAPER, probes=20)
    ours = angle_errors(cells, sample, MetaballRefiner(), probes=20)
    assert len(raw) == len(paper) == len(ours) == 20
    # Measured (docs/normal_refinement.md): ours median 0.5-2.2 deg, p90 about
    # 4 deg; the paper's literal setting median 4-7 deg; the raw normal median
    # 3.2-4 deg, p90 8-13 deg.
    assert np.median(ours) < 5.0
    assert np.median(paper) > 2.0 * np.median(ours)
    assert np.percentile(ours, 90) < np.percentile(raw, 90)


@pytest.mark.parametrize(
    "surface",
    [tilted_plane(10.0), tilted_plane(30.0), yawed_box(30.0)],
    ids=["plane-10deg", "plane-30deg", "box-yaw-30deg"],
)
def test_the_distance_field_gradient_has_no_failing_surface(surface) -> None:
    """Issue 16's alternative, measured beside the metaball (not shipped: cost).

    Three cells out its medians are 0-2 deg on every surface, the 10 deg plane
    (where the metaball's median is 10.6 deg) included.
    """
    cells, sample = surface
    field = angle_errors(cells, sample, DistanceFieldNormals(3.0), probes=20)
    assert len(field) == 20
    assert np.median(field) < 3.0
    assert np.percentile(field, 90) < 10.0
