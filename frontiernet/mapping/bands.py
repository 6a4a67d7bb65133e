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
    <frontiernet.mapping.OccupancyMap.changes>`). With `status_only`, the box of the voxels whose
    state (:func:`voxel_states`: unknown, free, occupied) an update flipped: what a consumer that
    reads the states alone, not the log-odds, needs (a frame that sees again what the map knows
    flips little of the box it touches)."""

    def __init__(self, status_only: bool = False) -> None:
        self.status_only = bool(status_only)
        self._box: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """The voxels in the index box [lo, hi) ((3,) int) may have changed."""
        lo, hi = np.asarray(lo, np.int64), np.asarray(hi, np.int64)
        self._box = (lo, hi) if self._box is None else (np.minimum(self._box[0], lo), np.maximum(self._box[1], hi))

    def take(self) -> tuple[slice, slice, slice] | None:
        """The box as three slices, or None when nothing changed; the record starts again empty."""
        box, self._box = self._box, None
        return None if box is None else tuple(slice(int(a), int(b)) for a, b in zip(*box))


def voxel_states(observed: np.ndarray, log_odds: np.ndarray, occupied_threshold: float, box: tuple) -> np.ndarray:
    """(bx, by, bz) int8 states of the voxels of a map's `observed` and `log_odds` arrays in `box`
    (three slices): 0 unknown, 1 free (observed, log-odds at or below `occupied_threshold`), 2 occupied."""
    seen = observed[box]
    return seen.astype(np.int8) + (seen & (log_odds[box] > occupied_threshold))


def flipped_box(before: np.ndarray, after: np.ndarray, lo: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The index box [lo', hi') of the voxels whose :func:`voxel_states` differ between `before` and
    `after` (the same box, whose first voxel is at index `lo` (3,)), or None when none does."""
    flipped = before != after
    spans = [np.flatnonzero(np.any(flipped, axis=tuple(other for other in range(3) if other != axis)))
             for axis in range(3)]
    if not len(spans[0]):
        return None
    lo = np.asarray(lo, np.int64)
    return lo + [span[0] for span in spans], lo + [span[-1] + 1 for span in spans]


class MapUpdates:
    """Who a map tells of its in-place updates: its :class:`BandViews` `bands` and the
    :class:`ChangedBox` records it handed out (:meth:`record`). An update of the index box [lo, hi)
    of `observed` and `log_odds` calls :meth:`before`, updates, then :meth:`after`."""

    def __init__(self, observed: np.ndarray, log_odds: np.ndarray, occupied_threshold: float, bands) -> None:
        self._observed, self._log_odds, self._threshold = observed, log_odds, float(occupied_threshold)
        self._bands, self._records = bands, []
        self._pinned, self._pinned_log_odds = np.empty((0, 3), np.int64), np.empty(0, np.float32)

    def pin(self, index: np.ndarray, log_odds: float) -> None:
        """Hold voxel `index` ((3,) int) observed at `log_odds` through every later update (each
        :meth:`after` sets it again): call between :meth:`before` and :meth:`after` of its box."""
        self._pinned = np.vstack([self._pinned, np.asarray(index, np.int64).reshape(1, 3)])
        self._pinned_log_odds = np.append(self._pinned_log_odds, np.float32(log_odds))

    def record(self, status_only: bool = False) -> ChangedBox:
        """A new :class:`ChangedBox`, told of every update from now on."""
        self._records.append(ChangedBox(status_only))
        return self._records[-1]

    def _states(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        box = tuple(slice(int(a), int(b)) for a, b in zip(lo, hi))
        return voxel_states(self._observed, self._log_odds, self._threshold, box)

    def before(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
        """The voxel states of the box about to be updated, when a status-only record needs them (else None)."""
        return self._states(lo, hi) if any(record.status_only for record in self._records) else None

    def after(self, lo: np.ndarray, hi: np.ndarray, before: np.ndarray | None) -> None:
        """The box [lo, hi) ((3,) int) was updated; its states were `before` (:meth:`before`). The
        pinned voxels in it (:meth:`pin`) are set again first."""
        inside = np.all((self._pinned >= lo) & (self._pinned < hi), axis=1) if len(self._pinned) else ()
        if np.any(inside):
            index = tuple(self._pinned[inside].T)
            self._log_odds[index], self._observed[index] = self._pinned_log_odds[inside], True
        self._bands.changed(lo, hi)
        flipped = None if before is None else flipped_box(before, self._states(lo, hi), lo)
        for record in self._records:
            if not record.status_only or before is None:
                record.add(lo, hi)
            elif flipped is not None:
                record.add(*flipped)


def read_only(array: np.ndarray) -> np.ndarray:
    """A view of `array` that cannot be written through."""
    view = array.view()
    view.flags.writeable = False
    return view
