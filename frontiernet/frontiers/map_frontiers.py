"""Classic map-based frontiers: Yamauchi, "A frontier-based approach for autonomous
exploration" (CIRA 1997), the baseline the exploration benchmark compares against.

1. Slice the map at ``z +- planner.height_band_m`` (the planner's band: frontiers lie on its grid).
2. Frontier cells: free cells with at least one unknown 4-neighbour (cells off the map are
   not unknown: there is nothing to explore there).
3. Frontier regions: 8-connected groups of frontier cells; groups of fewer than ``min_cells``
   cells are noise (Yamauchi keeps regions above a minimum size). A region longer than
   ``max_extent_m`` is cut along its principal axis into pieces, so one long wall-side
   frontier gives several goals.
4. One :class:`~frontiernet.frontiers.anchoring.FrontierObservation` per piece, for the
   :class:`~frontiernet.frontiers.FrontierTracker` and the planner.

Frames: world Z-up, metres; cell ``[i, j]`` of ``OccupancyMap.slice_2d`` is centred at ``origin[:2]
+ ([i, j] + 0.5) * voxel_size``. Numbers: ``map_frontiers`` of ``configs/explore.yaml``, the band of
``planner`` and the gain view of ``tracking`` (one view for every gain in the run).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import InputError, positive_number
from ..geometry import atan2, rigid_pose, rotation_from_yaw_pitch
from ..mapping.checks import finite_number, scalar
from .anchoring import FrontierObservation

GAINS = ("unknown_volume", "uniform")  # the valid values of map_frontiers' `gain`

# setting -> (config path, integer): the band is the planner's, the gain view the tracker's
_SETTINGS = {"height_band_m": (("planner", "height_band_m"), False),
             "min_cells": (("map_frontiers", "min_cells"), True),
             "max_extent_m": (("map_frontiers", "max_extent_m"), False),
             "uniform_gain_m3": (("map_frontiers", "uniform_gain_m3"), False),
             "width_px": (("tracking", "gain_view", "width_px"), True),
             "focal_px": (("tracking", "gain_view", "focal_px"), False),
             "max_depth_m": (("tracking", "gain_view", "max_depth_m"), False)}


def map_frontiers(occupancy, z: float, conf, T_world_cam: np.ndarray,
                  gain: str = "unknown_volume") -> list[FrontierObservation]:
    """Frontiers of the occupancy map at height `z`, one per frontier region (Yamauchi 1997).

    Args:
        occupancy: an :class:`~frontiernet.mapping.OccupancyMap` (``slice_2d``, ``voxel_size``,
            ``origin``, ``visible_unknown_volume``).
        z: world height of the slice (the robot's camera height), metres.
        conf: the explore config (``configs/explore.yaml``, dict or DictConfig): its
            ``map_frontiers`` section, ``planner.height_band_m`` and ``tracking.gain_view``.
        T_world_cam: (4, 4) float64 pose of the robot's camera, stored in each observation.
        gain: ``unknown_volume``: the unknown volume (m^3) a level virtual camera at the
            frontier, looking along its direction, sees in the map (the tracker's gain view);
            ``uniform``: ``map_frontiers.uniform_gain_m3`` for every frontier.
    Returns:
        One observation per piece: position (3,) float64 = the member cell centre nearest the
        centroid, at height `z` (on the frontier); direction (3,) float64 level unit mean of the
        steps from the members to their unknown 4-neighbours; num_pixels = its cell count;
        pixel = [nan, nan] (no image); T_world_cam = a copy of the given pose.
    Raises:
        InputError: an unknown `gain`, a non-finite `z`, a non-rigid pose or a bad config value.
    """
    if gain not in GAINS:
        raise InputError(f"map_frontiers gain must be one of {', '.join(GAINS)}, got {gain!r}")
    z = finite_number(z, "map_frontiers z")
    T_world_cam = rigid_pose(T_world_cam)
    settings = frontier_settings(conf)
    band = settings["height_band_m"]
    is_frontier, toward_unknown = frontier_cells(*occupancy.slice_2d(z - band, z + band))
    cell = float(occupancy.voxel_size)
    cells, piece = frontier_regions(is_frontier, settings["min_cells"], settings["max_extent_m"] / cell)
    if not len(piece):
        return []
    sizes = np.bincount(piece)
    centres = cells[_nearest_to_centroid(cells, piece, sizes)]
    positions = np.column_stack([np.asarray(occupancy.origin[:2], np.float64) + (centres + 0.5) * cell,
                                 np.full(len(sizes), z)])
    steps = toward_unknown[cells[:, 0], cells[:, 1]].astype(np.float64)
    directions = _level_directions(np.stack([np.bincount(piece, steps[:, a]) for a in (0, 1)], axis=1),
                                   positions, T_world_cam[:3, 3])
    if gain == "uniform":
        gains = np.full(len(sizes), settings["uniform_gain_m3"])
    else:
        poses = np.tile(np.eye(4), (len(sizes), 1, 1))
        poses[:, :3, :3] = rotation_from_yaw_pitch(atan2(directions[:, 1], directions[:, 0]))
        poses[:, :3, 3] = positions
        gains = occupancy.visible_unknown_volume(poses, settings["width_px"], settings["focal_px"],
                                                 settings["max_depth_m"])
    return [FrontierObservation(position, direction, float(volume), int(size), np.full(2, np.nan),
                                T_world_cam.copy()) for position, direction, volume, size in
            zip(positions, directions, gains, sizes)]


def frontier_settings(conf) -> dict:
    """The checked settings of :func:`map_frontiers` from the explore config (:data:`_SETTINGS`):
    floats for the metres, pixels and m^3, ints for ``min_cells`` and ``width_px``; InputError
    naming the first missing or non-positive key by its config path."""
    settings = {}
    for key, (path, integer) in _SETTINGS.items():
        name, value = ".".join(path), conf
        for part in path:
            value = value.get(part) if hasattr(value, "get") else None
        if value is None:
            raise InputError(f"{name} is missing from the explore config")
        value = positive_number(scalar(value), name)
        if integer and not value.is_integer():
            raise InputError(f"{name} must be a positive integer, got {value!r}")
        settings[key] = int(value) if integer else value
    return settings


def frontier_cells(free: np.ndarray, occupied: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frontier cells of a 2D slice (cells neither free nor occupied are unknown).

    Args:
        free, occupied: (X, Y) bool, as returned by ``OccupancyMap.slice_2d``.
    Returns:
        is_frontier: (X, Y) bool, free cells with at least one unknown 4-neighbour.
        toward_unknown: (X, Y, 2) int8, the sum of the unit steps (di, dj) from each cell to its
            unknown 4-neighbours (zero where none; cells off the slice are not unknown).
    """
    free, occupied = np.asarray(free, bool), np.asarray(occupied, bool)
    if free.ndim != 2 or free.shape != occupied.shape:
        raise InputError(f"free and occupied must be (X, Y) slices of one shape, got {free.shape}, {occupied.shape}")
    X, Y = free.shape
    unknown = np.pad(~free & ~occupied, 1, constant_values=False).astype(np.int8)
    toward_unknown, has_unknown = np.zeros((X, Y, 2), np.int8), np.zeros((X, Y), bool)
    for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):  # the 4-neighbourhood
        neighbour = unknown[1 + di:1 + di + X, 1 + dj:1 + dj + Y]
        toward_unknown[..., 0] += di * neighbour
        toward_unknown[..., 1] += dj * neighbour
        has_unknown |= neighbour.astype(bool)
    return free & has_unknown, toward_unknown


def frontier_regions(is_frontier: np.ndarray, min_cells: int, max_extent_cells: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """8-connected frontier regions of at least `min_cells` cells, cut into pieces whose extent
    (:func:`principal_frame`) is at most `max_extent_cells`.

    Args:
        is_frontier: (X, Y) bool frontier cells.
    Returns:
        cells: (N, 2) int64 indices (i, j) of the kept frontier cells.
        piece: (N,) int64 piece of each cell, 0 .. P-1 (every piece has a cell).
    """
    labels, count = ndimage.label(is_frontier, structure=np.ones((3, 3), bool))
    cells, region = np.argwhere(is_frontier), labels[is_frontier] - 1
    keep = np.bincount(region, minlength=count)[region] >= min_cells
    cells, region = cells[keep], np.unique(region[keep], return_inverse=True)[1].reshape(-1)
    next_id = len(region)  # above every region id
    for too_long in np.flatnonzero(principal_frame(cells, region)[1] > max_extent_cells):
        for part in _split_long(np.flatnonzero(region == too_long), cells, max_extent_cells):
            region[part], next_id = next_id, next_id + 1
    return cells, np.unique(region, return_inverse=True)[1].reshape(-1).astype(np.int64)


def principal_frame(cells: np.ndarray, region: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each region's principal axis (of its cells' 2x2 covariance), for (N, 2) cells with (N,)
    region ids 0 .. R-1: (N,) float64 coordinate of each cell along its region's axis, and (R,)
    float64 extents in cells = the diagonal of the region's bounding box in its principal axes,
    between cell centres (at least the largest distance between two of its cells)."""
    sizes = np.bincount(region)
    centred = cells - np.column_stack([np.bincount(region, cells[:, a]) / sizes for a in (0, 1)])[region]
    cii, cjj, cij = (np.bincount(region, centred[:, a] * centred[:, b]) for a, b in ((0, 0), (1, 1), (0, 1)))
    angle = 0.5 * atan2(2 * cij, cii - cjj)[region]
    along = centred[:, 0] * np.cos(angle) + centred[:, 1] * np.sin(angle)
    across = centred[:, 1] * np.cos(angle) - centred[:, 0] * np.sin(angle)
    spans = []
    for values in (along, across):
        high, low = np.full(len(sizes), -np.inf), np.full(len(sizes), np.inf)
        np.maximum.at(high, region, values)
        np.minimum.at(low, region, values)
        spans.append(high - low)
    return along, np.hypot(*spans)


def _split_long(members: np.ndarray, cells: np.ndarray, max_extent_cells: float) -> list[np.ndarray]:
    """Cut a region (indices `members` into (N, 2) `cells`) along its principal axis into
    ceil(extent / max) chunks of equal cell counts, again for any chunk still too long (a bent
    region), until every piece is short enough; returns the pieces' index arrays."""
    todo, pieces = [members], []
    while todo:
        part = todo.pop()
        along, (extent,) = principal_frame(cells[part], np.zeros(len(part), np.int64))
        if extent <= max_extent_cells:
            pieces.append(part)
            continue
        # at most one chunk per cell: a chunk of a bent region can hold a few cells far apart
        chunks = min(int(np.ceil(extent / max_extent_cells)), len(part))
        todo.extend(reversed(np.array_split(part[np.argsort(along, kind="stable")], chunks)))
    return pieces


def _nearest_to_centroid(cells: np.ndarray, piece: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """(P,) int64 index into (N, 2) `cells` of each piece's member nearest the piece's centroid
    (on the frontier, unlike the centroid of a curved region)."""
    centroids = np.column_stack([np.bincount(piece, cells[:, a]) / sizes for a in (0, 1)])
    distance = ((cells - centroids[piece]) ** 2).sum(axis=1)
    order = np.lexsort((distance, piece))
    return order[np.r_[0, np.cumsum(sizes)[:-1]]]


def _level_directions(sums: np.ndarray, positions: np.ndarray, robot: np.ndarray) -> np.ndarray:
    """(R, 3) level unit directions from (R, 2) summed steps towards unknown; where they cancel
    (a 1-cell free corridor between unknown sides), the heading from the robot to the frontier,
    or +x if the robot stands on it."""
    for fallback in (positions[:, :2] - robot[:2], np.array([1.0, 0.0])):
        flat = np.linalg.norm(sums, axis=1) < 1e-9
        sums[flat] = np.broadcast_to(fallback, sums.shape)[flat]
    return np.column_stack([sums / np.linalg.norm(sums, axis=1, keepdims=True), np.zeros(len(sums))])
