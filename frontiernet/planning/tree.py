"""The frontier tree: robot poses as a chain, each frontier a child of the pose that saw it.

Paper III-F, docs/design.md item 6. The pose that registered a frontier saw it along a line of
sight, so the straight *edge* from that pose to the frontier runs through space that was
free when it was seen. When a goal frontier lies outside the mapped free space, the planner
walks back along that edge to the first point ``c*`` it can reach on the map, plans there,
then advances along the edge while mapping (:func:`walk_back`).

Without a map (the paper's map-free mode, Table III) the tree is all there is: the robot
returns along its own trajectory to the frontier's parent pose and then follows the edge.
:class:`PoseGraph` is that trajectory as a graph: consecutive poses are linked, and so are
poses the robot revisited (closer than ``link_radius_m``), so a return trip takes the short
way rather than re-tracing every detour. Positions are world metres; only x and y matter
(the robot keeps its camera height).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree


def edge_points(frontier_xy: np.ndarray, parent_xy: np.ndarray, spacing_m: float) -> np.ndarray:
    """(N, 2) points from the frontier back to its parent pose, `spacing_m` apart, both ends included."""
    frontier_xy, parent_xy = np.asarray(frontier_xy, np.float64), np.asarray(parent_xy, np.float64)
    length = float(np.linalg.norm(parent_xy - frontier_xy))
    n = max(1, int(np.ceil(length / spacing_m)))
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    return frontier_xy + t * (parent_xy - frontier_xy)


def walk_back(frontier_xy: np.ndarray, parent_xy: np.ndarray, reachable, spacing_m: float) -> int | None:
    """Index into :func:`edge_points` of ``c*``: the first point from the frontier that
    `reachable` ((N, 2) points -> (N,) bool) accepts; None when no point of the edge is."""
    points = edge_points(frontier_xy, parent_xy, spacing_m)
    ok = np.flatnonzero(reachable(points))
    return int(ok[0]) if len(ok) else None


class PoseGraph:
    """The robot's trajectory as a graph for map-free returns.

    Args:
        link_radius_m: poses closer than this are linked even when not consecutive (metres;
            ``planner.pose_link_m``).
    """

    def __init__(self, link_radius_m: float) -> None:
        self.link_radius_m = float(link_radius_m)
        self.positions: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self.positions)

    def add(self, xy: np.ndarray) -> int:
        """Append a pose's (2,) position; returns its index."""
        self.positions.append(np.asarray(xy, np.float64)[:2].copy())
        return len(self.positions) - 1

    def _matrix(self):
        xy = np.stack(self.positions)
        n = len(xy)
        rows, cols = np.arange(n - 1), np.arange(1, n)
        pairs = cKDTree(xy).query_pairs(self.link_radius_m, output_type="ndarray") if n > 1 else np.zeros((0, 2), int)
        rows = np.concatenate([rows, pairs[:, 0]]).astype(np.int64)
        cols = np.concatenate([cols, pairs[:, 1]]).astype(np.int64)
        weights = np.linalg.norm(xy[rows] - xy[cols], axis=1) + 1e-6  # zero weights would vanish
        return coo_matrix((weights, (rows, cols)), shape=(n, n)).tocsr()

    def distances_from(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(N,) metres along the graph from pose `index` to every pose, and the predecessor array."""
        return dijkstra(self._matrix(), directed=False, indices=int(index), return_predecessors=True)

    def path(self, predecessors: np.ndarray, target: int) -> np.ndarray:
        """(M, 2) positions from the source of `predecessors` to pose `target`."""
        chain = [int(target)]
        while predecessors[chain[-1]] >= 0:
            chain.append(int(predecessors[chain[-1]]))
        return np.stack([self.positions[i] for i in chain[::-1]])
