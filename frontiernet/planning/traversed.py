"""Where the robot has been: the planning-grid cells its centre passed through.

With ``planner.traversed_is_free`` these cells count as traversable for the planner
(:meth:`~frontiernet.planning.planner.PlanningGrid.from_map`) and the move check, whatever the
map says of them now: the body has been there, so the way back is open. It is the trajectory's
part of the footprint clearing of ROS costmap_2d (the obstacle layer's ``footprint_clearing_enabled``
clears the cells under the robot's footprint), kept for the whole trajectory: a noisy depth source
(monocular) smears walls into doorways the robot has walked through, its map seals them, and
every frontier behind them becomes unreachable (blacklisted), to the end of the run.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import cells_inside, cells_near, grid_cells, grid_values


@dataclass
class TraversedCells:
    """The cells of a 2D grid that a path of world points passed through.

    Attributes:
        origin_xy: (2,) float64 world corner of cell (0, 0), metres (the map's).
        cell_m: cell size, metres (the map's voxel size).
        mask: (X, Y) bool, indexed [i, j] for ``x = origin_x + (i + 0.5) * cell_m`` (the
            planning grid's cells).
        last_xy: (2,) float64 the path's last point, metres (None before the first).
    """

    origin_xy: np.ndarray
    cell_m: float
    mask: np.ndarray
    last_xy: np.ndarray | None = field(default=None, repr=False)

    @classmethod
    def like(cls, occupancy) -> "TraversedCells":
        """An empty record on the XY grid of an :class:`~frontiernet.mapping.OccupancyMap`."""
        return cls(np.asarray(occupancy.origin[:2], np.float64), float(occupancy.voxel_size),
                   np.zeros(occupancy.shape[:2], bool))

    def add(self, xy: np.ndarray) -> None:
        """Extend the path to world point `xy` ((2,) metres): every cell the straight segment from
        the previous point passes through is marked (sampled every quarter cell; the first call
        marks the cell under `xy`)."""
        xy = np.asarray(xy, np.float64)[:2]
        start = xy if self.last_xy is None else self.last_xy
        count = int(np.ceil(np.linalg.norm(xy - start) / (0.25 * self.cell_m))) + 1
        points = start + np.linspace(0.0, 1.0, count)[:, None] * (xy - start)
        cells = grid_cells(points, self.origin_xy, self.cell_m)
        cells = cells[cells_inside(cells, self.mask.shape)]
        self.mask[cells[:, 0], cells[:, 1]] = True
        self.last_xy = xy.copy()

    def forget(self, xy: np.ndarray, radius_m: float) -> None:
        """Unmark the cells whose squares come within `radius_m` of world point `xy` ((2,) metres):
        the robot bumped into something there, which is newer than its passing (the map's clearance
        rule decides those cells again; kept open, a route cut the corner it bumped into)."""
        cells, near = cells_near(np.asarray(xy, np.float64)[:2], self.origin_xy, self.cell_m, radius_m)
        cells = cells[0][near[0] & cells_inside(cells[0], self.mask.shape)]
        self.mask[cells[:, 0], cells[:, 1]] = False

    def contains(self, xy: np.ndarray) -> bool:
        """Whether the cell under world point `xy` ((2,) metres) was passed through."""
        return bool(grid_values(self.mask, self.origin_xy, self.cell_m, np.asarray(xy)[:2], outside=0.0)[0])


__all__ = ["TraversedCells"]
