# SPDX-License-Identifier: Apache-2.0
"""Compiled loops of the occupancy map: seen space, robot volume, obstacle shell.

Each pass visits cells of a dense ``uint8`` grid (:data:`UNKNOWN`, :data:`FREE`,
:data:`OCCUPIED`) a few dozen flops at a time, which numpy could only batch at
the cost of temporaries the size of the grid. They release the GIL, so the map
thread runs beside the control loop.

By what they compute: :mod:`~cbp.perception.kernels.arrays` (the states and
the arrays the passes share), :mod:`~cbp.perception.kernels.pixels` (a depth
image's pixels: eroded ranges, changes, windows),
:mod:`~cbp.perception.kernels.seen` (the cells a frame sees through),
:mod:`~cbp.perception.kernels.readings` (readings into cells: occupied, the
robot's own, hidden space, cells entered) and
:mod:`~cbp.perception.kernels.shell` (the robot's volume made free, the
obstacles' shell). They are compiled (or loaded from numba's cache) by the map
process's warm-up, which integrates small frames into a throwaway copy of its
grid (:mod:`cbp.perception.map_process`).
"""

from cbp.perception.kernels.arrays import (
    FREE,
    KEPT_NONE,
    KEPT_ROBOT,
    OCCUPIED,
    UNKNOWN,
    FrameArrays,
    GridArrays,
    KeptPixels,
    PixelHistory,
    RobotShapes,
    SlotArray,
)
from cbp.perception.kernels.pixels import (
    eroded_ranges,
    eroded_ranges_in,
    frame_changes,
    tile_windows,
)
from cbp.perception.kernels.readings import (
    insert_readings,
    merge_entered,
    occupied_centres,
)
from cbp.perception.kernels.seen import mark_seen
from cbp.perception.kernels.shell import carve_shapes, shell_update

__all__ = [
    "FREE",
    "KEPT_NONE",
    "KEPT_ROBOT",
    "OCCUPIED",
    "UNKNOWN",
    "FrameArrays",
    "GridArrays",
    "KeptPixels",
    "PixelHistory",
    "RobotShapes",
    "SlotArray",
    "carve_shapes",
    "eroded_ranges",
    "eroded_ranges_in",
    "frame_changes",
    "insert_readings",
    "mark_seen",
    "merge_entered",
    "occupied_centres",
    "shell_update",
    "tile_windows",
]
