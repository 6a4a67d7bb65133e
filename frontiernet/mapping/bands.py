"""The 2D band views of an occupancy map (:meth:`~frontiernet.mapping.occupancy.OccupancyMap.slice_2d`),
kept between map updates: after an update only the columns of the box it changed are computed
again, so a large map's step costs what its frame changes, not its whole band."""

from __future__ import annotations

import numpy as np


def band_layers(origin_z: float, voxel_size: float, layers: int, z_min: float, z_max: float) -> tuple[int, int]:
    """Voxel layer range [k0, k1) of the height band [z_min, z_max] (world metres) of a grid whose
    bottom is at `origin_z` with `layers` layers of `voxel_size`: the layers overlapping the band, at
    least the one holding z_min, clipped to the grid (empty: k1 <= k0)."""
    k0 = int(np.floor((z_min - origin_z) / voxel_size))
    k1 = max(int(np.ceil((z_max - origin_z) / voxel_size)), k0 + 1)
    return max(k0, 0), min(k1, int(layers))


class BandViews:
    """(free, occupied) (X, Y) bool views per layer range [k0, k1) of a map's `observed` ((X, Y, Z)
    bool) and `log_odds` ((X, Y, Z) float32, occupied above `occupied_threshold`) arrays, which the
    map updates in place; returned read-only. A column is occupied when any of its band voxels is
    observed and occupied, free when all of them are observed and free.

    A view is computed whole once, then patched: :meth:`changed` records the index box a map
    update touched, and the next :meth:`view` of a band whose layers it overlaps recomputes the
    box's columns into a copy (a view handed out earlier never changes under its holder)."""

    def __init__(self, observed: np.ndarray, log_odds: np.ndarray, occupied_threshold: float) -> None:
        self._observed, self._log_odds, self._threshold = observed, log_odds, float(occupied_threshold)
        self._views: dict[tuple[int, int], list] = {}  # (k0, k1) -> [free, occupied, ChangedBox of stale columns]

    def _columns(self, k0: int, k1: int, window: tuple) -> tuple[np.ndarray, np.ndarray]:
        """(free, occupied) bool columns of layers [k0, k1) over the (X, Y) `window` (two slices)."""
        observed = self._observed[window + (slice(k0, k1),)]
        occupied = self._log_odds[window + (slice(k0, k1),)] > self._threshold
        return np.all(observed & ~occupied, axis=2), np.any(observed & occupied, axis=2)

    def view(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray]:
        entry = self._views.get((k0, k1))
        stale = None if entry is None else entry[2].take()
        if entry is None:
            free, occupied = self._columns(k0, k1, (slice(None), slice(None)))
        elif stale is not None:
            window = stale[:2]
            free, occupied = entry[0].copy(), entry[1].copy()
            free[window], occupied[window] = self._columns(k0, k1, window)
        else:
            return entry[0], entry[1]
        self._views[k0, k1] = entry = [read_only(free), read_only(occupied), ChangedBox()]
        return entry[0], entry[1]

    def changed(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """The map's voxels in the index box [lo, hi) ((3,) int, (X, Y, Z)) may have changed."""
        for (k0, k1), entry in self._views.items():
            if lo[2] < k1 and hi[2] > k0:
                entry[2].add(lo, hi)


class ChangedBox:
    """The index box (X, Y, Z) that a map's updates have touched since it was last taken: a consumer
    that keeps something derived from the map patches that box only (:meth:`OccupancyMap.changes
    <frontiernet.mapping.OccupancyMap.changes>`)."""

    def __init__(self) -> None:
        self._box: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """The voxels in the index box [lo, hi) ((3,) int) may have changed."""
        lo, hi = np.asarray(lo, np.int64), np.asarray(hi, np.int64)
        self._box = (lo, hi) if self._box is None else (np.minimum(self._box[0], lo), np.maximum(self._box[1], hi))

    def take(self) -> tuple[slice, slice, slice] | None:
        """The box as three slices, or None when nothing changed; the record starts again empty."""
        box, self._box = self._box, None
        return None if box is None else tuple(slice(int(a), int(b)) for a, b in zip(*box))


def read_only(array: np.ndarray) -> np.ndarray:
    """A view of `array` that cannot be written through."""
    view = array.view()
    view.flags.writeable = False
    return view
