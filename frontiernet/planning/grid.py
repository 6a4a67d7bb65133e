"""Shortest paths on 2D cost grids with scikit-image's minimum-cost-path search.

Grids are (H, W) arrays indexed ``[row, col]``; a cost is the price of crossing a
cell (``inf`` = blocked). ``MCP_Geometric`` charges diagonal moves sqrt(2) times the
cell cost, so with unit costs path lengths are Euclidean-ish cell distances.
"""

from __future__ import annotations

import numpy as np
from skimage.graph import MCP_Geometric


def clearance_cost(clearance_m: np.ndarray, min_clearance_m: float, weight: float = 1.0) -> np.ndarray:
    """Cell costs from clearance (metres to the nearest obstacle): blocked below
    `min_clearance_m`, otherwise ``1 + weight / clearance`` so paths keep to the middle."""
    cost = 1.0 + weight / np.maximum(clearance_m, 1e-3)
    cost[clearance_m < min_clearance_m] = np.inf
    return cost


def geodesic_distance(cost: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """(H, W) float64 accumulated cost from `start` (row, col) to every cell; inf if unreachable."""
    graph = MCP_Geometric(np.where(np.isfinite(cost), cost, -1.0))  # negative = impassable
    cumulative, _ = graph.find_costs([tuple(int(i) for i in start)])
    cumulative[~np.isfinite(cost)] = np.inf
    return cumulative


def reachable_region(open_cells: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: the cells reachable from `start` (row, col) by 8-neighbour moves through the (H, W)
    bool `open_cells`: ``np.isfinite(geodesic_distance(np.where(open_cells, 1.0, np.inf), start))``
    exactly (a blocked `start` reaches on through its open neighbours, as the search does; off the grid:
    nothing), by connected-component labelling, tens of times faster than the search."""
    from scipy import ndimage

    open_cells = np.asarray(open_cells, bool)
    i, j = (int(v) for v in start)
    if not (0 <= i < open_cells.shape[0] and 0 <= j < open_cells.shape[1]):
        return np.zeros(open_cells.shape, bool)
    labels, _ = ndimage.label(open_cells, structure=np.ones((3, 3), bool))
    if open_cells[i, j]:
        return labels == labels[i, j]
    around = labels[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2]
    return np.isin(labels, np.unique(around[around > 0]))


def geodesic_paths(cost: np.ndarray, start: tuple[int, int]):
    """One search from `start` for many goals: ``(cumulative, path_to)`` where `cumulative` is
    :func:`geodesic_distance`'s array and ``path_to(goal)`` the (N, 2) int64 cells from `start`
    to `goal` (None when unreachable)."""
    graph = MCP_Geometric(np.where(np.isfinite(cost), cost, -1.0))
    cumulative, _ = graph.find_costs([tuple(int(i) for i in start)])
    cumulative[~np.isfinite(cost)] = np.inf

    def path_to(goal: tuple[int, int]) -> np.ndarray | None:
        if not np.isfinite(cumulative[tuple(goal)]):
            return None
        return np.asarray(graph.traceback(tuple(int(i) for i in goal)), np.int64)

    return cumulative, path_to


def shortest_path(cost: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> np.ndarray | None:
    """(N, 2) int64 cells (row, col) of the cheapest path from `start` to `goal`, or None."""
    graph = MCP_Geometric(np.where(np.isfinite(cost), cost, -1.0))
    cumulative, _ = graph.find_costs([tuple(int(i) for i in start)], [tuple(int(i) for i in goal)])
    if not np.isfinite(cumulative[tuple(goal)]) or not np.isfinite(cost[tuple(goal)]):
        return None
    return np.asarray(graph.traceback(tuple(int(i) for i in goal)), np.int64)
