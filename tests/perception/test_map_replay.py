# SPDX-License-Identifier: Apache-2.0
"""Recorded frames give the map the cells they gave it when they were recorded.

``data/shelf_frames.npz``: fifteen frames of the five cameras of a CAT run in
the shelf (``cat_shelf_reach`` with ``configs/cat.yaml``'s cameras, ray cast,
virtual clock): their first frames at 0 s, then two rounds at 1.33 s and 1.4 s
with the arm moving, depth subsampled to 160 x 120 (the wrist camera's own
size), each with the configuration and time it was taken at. In the last
round a patch of each image comes nearer (something came between: hidden
space, moving cells). The digests below
are what the map's passes gave on them before they were reworked for speed
(grouped arrays, bricks of free cells skipped, the robot filter behind a box,
the index's bits from the shell's pass):
cell states, misses, the obstacle shell and its index (runs, occupied
places as bits), the blocked mask and the moving cells after every frame. A change of any cell's state fails here.

The grid has since grown a layer of unknown cells around its bounds (space
outside them is unknown): the digests were recorded again then, after the
cells within the bounds, their misses, the counts seen, carved and hidden and
the moving cells were checked to be those of the passes before, frame by
frame (the readings inserted now count those that fall in the layer). Then
hidden space came to stop two cells farther from the robot's padded shapes,
and a cell entered only when it was not occupied: the last five frames' hidden
counts fell (24877 to 24255, ...) and the robot's shapes no longer carve
hidden space back (92, 70, 70, 63 to 0).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from cbp.perception.frame import DepthFrame
from cbp.perception.occupancy import OccupancyGrid
from cbp.scenario import load_scenario
from cbp.state import RobotState

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).parent / "data" / "shelf_frames.npz"

#: Per frame: (valid pixels, robot points, inserted, seen, carved, hidden), and
#: the digest of the map after it (as the passes gave them before the speed-up).
EXPECTED: list[tuple[tuple[int, ...], str]] = [
    ((19175, 1293, 4013, 1386966, 44166, 0), "b6ce1710f3dca79f"),
    ((19160, 1115, 5789, 274682, 0, 0), "d4f4336314a73b9d"),
    ((19155, 1147, 5786, 185222, 0, 0), "38b0d03429971f7c"),
    ((19159, 1752, 12112, 38607, 0, 0), "0e40e87782638adf"),
    ((19151, 0, 19151, 7566, 0, 0), "d167d444983c3477"),
    ((19168, 1206, 3939, 590, 25, 0), "55580cf822b6fba4"),
    ((19169, 1055, 5795, 949, 0, 0), "c15ff5026f9bfb82"),
    ((19158, 1138, 5786, 2468, 0, 0), "02f33a7dbc471302"),
    ((19166, 2129, 12112, 153, 0, 0), "f1b00f7c8b749992"),
    ((19160, 0, 19160, 298, 0, 0), "bdcdf0b9374aba33"),
    ((19161, 808, 4337, 198, 0, 24255), "1eefa20b4e82277a"),
    ((19166, 811, 6027, 7823, 0, 12276), "33358f7b530ef50f"),
    ((19156, 912, 6023, 7066, 0, 12058), "ef379bfa24dddaa1"),
    ((19163, 1794, 12454, 21352, 0, 825), "7ba88bd54972d60d"),
    ((19166, 0, 19166, 1706, 0, 0), "d7e34154636ef413"),
]


def replay(whole_frame_every: int = 1) -> list[tuple[tuple[int, ...], str]]:
    """Integrate the recorded frames one by one, snapshot after each: what each gave.

    ``whole_frame_every``: as ``perception.whole_frame_every`` (1: every frame
    whole, as the passes were recorded with).
    """
    scenario = load_scenario(
        ROOT / "scenarios" / "cat_shelf_reach.yaml",
        overrides={
            "perception.source": "depth_camera",
            "perception.whole_frame_every": str(whole_frame_every),
            # The region the frames were recorded in (configs/cat.yaml's then).
            "perception.bounds": "[[-0.2, -0.8, -0.015], [1.2, 0.8, 1.0]]",
        },
    )
    geometry = scenario.new_world().geometry
    grid = OccupancyGrid(scenario.spec.perception, geometry)
    state = RobotState(geometry.robot)
    data = np.load(DATA)
    out: list[tuple[tuple[int, ...], str]] = []
    for n, t in enumerate(data["t"]):
        depth = data[f"depth{n}"].astype(float)
        near, far = float(data["near"][n]), float(data["far"][n])
        if n >= 10:  # something comes between: 20 % nearer in a patch
            patch = depth[40:70, 60:100]
            metric = far * near / (far - (far - near) * patch)
            patch[:] = far / (far - near) * (1.0 - near / (0.8 * metric))
        frame = DepthFrame(
            depth,
            data[f"view{n}"],
            data[f"projection{n}"],
            near,
            far,
            str(data["camera"][n]),
            float(data["min_range"][n]),
        )
        state.update(data[f"q{n}"])
        s = grid.integrate(frame, state, float(t))
        env = grid.environment()
        digest = hashlib.sha256()
        for array in (
            grid.cells,
            grid.misses,
            env.centres,
            env.index.start,
            env.index.slots,
            env.index.occupied,
            env.blocked.mask if env.blocked is not None else np.zeros(0),
            grid.moving_centres(float(t)),
        ):
            digest.update(np.ascontiguousarray(array).tobytes())
        counts = (s.robot_points, s.inserted, s.seen, s.carved, s.hidden)
        valid = round(s.valid_fraction * frame.depth.size)
        out.append(((valid, *counts), digest.hexdigest()[:16]))
    return out


def test_recorded_frames_give_the_cells_they_gave_before() -> None:
    """Each recorded frame, integrated whole, leaves the map as the passes before the speed-up left it."""
    got = replay()
    assert len(got) == len(EXPECTED)
    for n, (summary, expected) in enumerate(zip(got, EXPECTED, strict=True)):
        assert summary == expected, f"frame {n}"
