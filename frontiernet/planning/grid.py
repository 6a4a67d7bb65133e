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
