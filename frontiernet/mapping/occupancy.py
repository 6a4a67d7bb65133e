"""A dense 3D log-odds occupancy map (OctoMap-style), integrated from depth images.

Frames and units: world frame Z-up, metres. The map is a grid of shape (X, Y, Z) that
covers ``origin + [0, shape) * voxel_size``; voxel ``(i, j, k)`` spans
``origin + [i, i+1) * voxel_size`` on x (likewise y, z), as in
:class:`~frontiernet.simulator.voxels.VoxelGrid`, whose index helpers it shares.

Each voxel holds a float32 log-odds value (0 = unknown prior) and an explicit
"observed" flag (updated at least once). A depth frame is integrated as in OctoMap's
discretised update: every ``ray_stride_px``-th pixel's ray is traversed from the camera
centre to its end point (:func:`~frontiernet.mapping.traversal.mark_depth_rays`); per
frame each voxel is updated at most once, by ``log_odds_hit`` if some ray ends in it,
else by ``log_odds_miss`` if some ray passes it, and clamped to
``[log_odds_min, log_odds_max]``. Observed voxels above ``occupied_threshold`` are
occupied, the other observed ones free, the rest unknown. Only the bounding box of the
frame's frustum is touched, so an update costs the same in a room as in a campus.

Every number comes from the ``map`` section of ``configs/explore.yaml``.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..errors import InputError, positive_number
from ..io import atomic_path
from ..simulator.voxels import VoxelGrid
from ..geometry import disks_touch_cells, image_corner_rays, pinhole_intrinsics, rigid_pose, squared_distance_to_cells
from .bands import BandViews, ChangedBox, MapUpdates, band_layers, read_only
from .checks import MapSettings, depth_edges, depth_image, grazing_pixels, finite_number, scalar
from .traversal import apply_marks, frustum_volume, mark_depth_rays

UNKNOWN, FREE, OCCUPIED = 0, 1, 2
"""Voxel states returned by :meth:`OccupancyMap.state_at` (int8)."""

_FORMAT = "frontiernet-occupancy-1"
_KEYS_ADDED_AFTER_FILES = {"depth_edge_rtol": None, **dict.fromkeys(("monocular_hit_range_m", "monocular_log_odds_miss",
                           "monocular_free_fraction", "monocular_far_hit_max", "monocular_max_incidence_deg")),
                           "monocular_normal_window_px": 9}
"""Map settings a file written before them lacks, as such a file was made: no depth-edge filter, no monocular model."""


class OccupancyMap:
    """Dense 3D log-odds voxel grid (world frame, Z-up, metres); see the module docstring.

    Args:
        origin: (3,) float64 world position (metres) of the corner of voxel (0, 0, 0).
        shape: (X, Y, Z) number of voxels per axis.
        conf: the ``map`` section of ``configs/explore.yaml`` (DictConfig, dict or
            :class:`MapSettings`).
    Attributes:
        origin: as given; voxel_size: edge length, metres (``settings.voxel_size``); shape: the
            (X, Y, Z) voxel counts; settings: the checked :class:`MapSettings`.
    Raises:
        InputError: a bad origin, shape or config value.
    """

    # index helpers shared with VoxelGrid (they only use origin, voxel_size and shape)
    world_to_index = VoxelGrid.world_to_index
    index_to_world = VoxelGrid.index_to_world
    in_grid = VoxelGrid.in_grid
    bounds = VoxelGrid.bounds

    def __init__(self, origin: np.ndarray, shape: tuple[int, int, int], conf) -> None:
        self.settings = MapSettings.from_config(conf)
        self.origin = np.asarray(origin, np.float64)
        if self.origin.shape != (3,) or not np.all(np.isfinite(self.origin)):
            raise InputError(f"map origin must be a finite (3,) world point in metres, got {origin!r}")
        dims = tuple(int(n) for n in np.asarray(shape).reshape(-1)) if np.size(shape) == 3 else ()
        if len(dims) != 3 or min(dims) < 1:
            raise InputError(f"map shape must be 3 positive voxel counts (X, Y, Z), got {shape!r}")
        # plain attributes, not properties: VoxelGrid's index helpers read them without calling back here
        self.voxel_size = float(self.settings.voxel_size)
        self.shape: tuple[int, int, int] = dims  # type: ignore[assignment]
        self._log_odds = np.zeros(dims, np.float32)
        self._observed = np.zeros(dims, bool)
        self._known_voxels = 0
        self._latest_frame: tuple[np.ndarray, np.ndarray] | None = None  # (box lo, voxels seen)
        # slice_2d's views, patched where the map changes (the arrays are only ever updated in place)
        self._bands = BandViews(self._observed, self._log_odds, self.settings.occupied_threshold)
        self._updates = MapUpdates(self._observed, self._log_odds, self.settings.occupied_threshold, self._bands)
        self._view_directions: dict[tuple[int, float], np.ndarray] = {}

    @classmethod
    def like(cls, voxels: VoxelGrid, conf) -> OccupancyMap:
        """An empty map over the same grid (origin, voxel size, shape) as a scene's `voxels`.

        Raises:
            InputError: ``map.voxel_size`` differs from the grid's voxel size.
        """
        settings = MapSettings.from_config(conf)
        if not np.isclose(settings.voxel_size, voxels.voxel_size, rtol=1e-9, atol=0.0):
            raise InputError(f"map.voxel_size {settings.voxel_size} m differs from the scene grid's "
                             f"{voxels.voxel_size} m (voxels.voxel_size of configs/sim.yaml)")
        return cls(voxels.origin, voxels.shape, settings)

    @classmethod
    def from_bounds(cls, bounds: np.ndarray, conf) -> OccupancyMap:
        """An empty map covering `bounds`, (2, 3) float64 world [min, max] corners in metres
        (the upper side is rounded up to whole voxels)."""
        settings = MapSettings.from_config(conf)
        bounds = np.asarray(bounds, np.float64)
        if bounds.shape != (2, 3) or not np.all(np.isfinite(bounds)) or not np.all(bounds[1] > bounds[0]):
            raise InputError(f"map bounds must be finite [min, max] corners, max > min, got {bounds.round(3).tolist()}")
        shape = np.maximum(np.ceil((bounds[1] - bounds[0]) / settings.voxel_size - 1e-9), 1).astype(np.int64)
        return cls(bounds[0], tuple(shape.tolist()), settings)

    # -- geometry and state ----------------------------------------------------------------------

    @property
    def log_odds(self) -> np.ndarray:
        """(X, Y, Z) float32 log-odds of occupancy (read-only view; 0 where unknown)."""
        return read_only(self._log_odds)

    @property
    def latest_frame(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, seen) of the latest integrated frame: (3,) int64 index box corner and the box's
        (bool) mask of the voxels that frame observed (nothing else sets them observed); None before."""
        return None if self._latest_frame is None else (self._latest_frame[0].copy(), read_only(self._latest_frame[1]))

    @property
    def observed(self) -> np.ndarray:
        """(X, Y, Z) bool, voxels updated at least once (read-only view)."""
        return read_only(self._observed)

    def occupied_mask(self) -> np.ndarray:
        """(X, Y, Z) bool, observed voxels with log-odds above ``occupied_threshold``."""
        return self._observed & (self._log_odds > self.settings.occupied_threshold)

    def free_mask(self) -> np.ndarray:
        """(X, Y, Z) bool, observed voxels with log-odds at or below ``occupied_threshold``."""
        return self._observed & (self._log_odds <= self.settings.occupied_threshold)

    def unknown_mask(self) -> np.ndarray:
        return ~self._observed  # (X, Y, Z) bool, voxels never updated

    @property
    def known_volume_m3(self) -> float:
        """Volume of the observed (free or occupied) voxels, cubic metres."""
        return self._known_voxels * self.voxel_size ** 3

    def cylinder_touches_occupied(self, xy: np.ndarray, radius_m: float, z_min: float, z_max: float) -> bool:
        """Whether an upright cylinder of `radius_m` around world point `xy` ((2,) metres) over the
        height band [z_min, z_max] (the layers :meth:`slice_2d` takes) overlaps an occupied voxel (exact
        disk-square test): the planning grid's view of a body there, so a move it allows is one the grid
        could have planned."""
        xy, radius, lo, window = self._disk_window(xy, radius_m, z_min, z_max, "cylinder_touches_occupied")
        if window is None:
            return False
        occupied = np.any(self._observed[window] & (self._log_odds[window] > self.settings.occupied_threshold), axis=2)
        return bool(disks_touch_cells(occupied, self.origin[:2] + lo * self.voxel_size, self.voxel_size,
                                      xy[None], radius)[0])

    def nearest_unknown_in_disk(self, xy: np.ndarray, radius_m: float, z: float,
                                exclude: np.ndarray | None = None) -> np.ndarray | None:
        """The centre ((2,) float64 world xy, metres) of the unknown voxel nearest to `xy` among those
        of the layer holding height `z` whose squares overlap the disk of `radius_m` around `xy`
        ((2,) metres); None when all of them are observed (cells off the grid do not count).
        `exclude`: (K, 2) world xy points (metres) whose cells of the layer do not count.

        The explorer's move check asks it at the camera's height: a wall end the camera never saw
        is unknown, not occupied, and a body passing beside it would touch it."""
        xy, radius, lo, window = self._disk_window(xy, radius_m, z, z, "nearest_unknown_in_disk")
        if window is None:
            return None
        unknown = ~self._observed[window][:, :, 0]
        if exclude is not None and len(exclude):
            exclude = np.asarray(exclude, np.float64).reshape(-1, 2)
            skip = self.world_to_index(np.column_stack([exclude, np.full(len(exclude), z)]))[:, :2] - lo
            inside = np.all((skip >= 0) & (skip < unknown.shape), axis=1)
            unknown[skip[inside, 0], skip[inside, 1]] = False
        if not unknown.any():
            return None
        cells = lo + np.argwhere(unknown)
        squared = squared_distance_to_cells(cells, self.origin[:2], self.voxel_size, xy)
        if squared.min() >= radius ** 2:
            return None
        return self.origin[:2] + (cells[int(np.argmin(squared))] + 0.5) * self.voxel_size

    def _disk_window(self, xy, radius_m, z_min, z_max, what: str):
        """Checked (2,) `xy` and `radius_m`, and the index window (a tuple of slices, with its (2,)
        xy corner index `lo`) of the map columns under the disk over the band's layers; window
        None when the band misses the grid. A local window: no whole-map slice per query."""
        xy = np.asarray(xy, np.float64).reshape(-1)[:2]
        if xy.shape != (2,) or not np.all(np.isfinite(xy)):
            raise InputError(f"{what} needs a finite (2,) world point, got {xy!r}")
        radius = positive_number(scalar(radius_m), f"{what} radius_m", "metres", allow_zero=True)
        k0, k1 = self._band_layers(z_min, z_max, what)
        size, origin = self.voxel_size, self.origin[:2]
        lo = np.clip(np.floor((xy - radius - origin) / size).astype(np.int64), 0, self.shape[:2])
        hi = np.clip(np.floor((xy + radius - origin) / size).astype(np.int64) + 1, 0, self.shape[:2])
        if k1 <= k0:
            return xy, radius, lo, None
        return xy, radius, lo, (slice(lo[0], hi[0]), slice(lo[1], hi[1]), slice(k0, k1))

    def state_at(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points (metres) -> (N,) int8 :data:`UNKNOWN` / :data:`FREE` / :data:`OCCUPIED`
        of the voxels holding them (UNKNOWN off the grid or for non-finite points)."""
        points = np.asarray(points, np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"points must be an (N, 3) array of world points, got shape {points.shape}")
        index = self.world_to_index(points)
        inside = self.in_grid(index)
        i, j, k = index[inside].T
        states = np.full(len(points), UNKNOWN, np.int8)
        occupied = self._log_odds[i, j, k] > self.settings.occupied_threshold
        states[inside] = np.where(self._observed[i, j, k], np.where(occupied, OCCUPIED, FREE), UNKNOWN)
        return states

    # -- updates ---------------------------------------------------------------------------------

    def integrate(self, depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray,
                  monocular: bool = False) -> None:
        """Integrate one depth frame (see the module docstring for the update rule).

        Args:
            depth: (H, W) float z-depth in metres, NaN (or <= 0) where invalid. Depth beyond
                ``max_range_m`` is no hit: the ray is free up to ``max_range_m``. Invalid
                pixels are free up to ``max_range_m`` or skipped, per ``invalid_depth``.
            K: (3, 3) float64 pinhole intrinsics of the depth image, pixels (centres at
                integer coordinates).
            T_world_cam: (4, 4) float64 camera pose (OpenCV camera frame to world).
            monocular: the depth of a monocular network (a source with
                :attr:`~frontiernet.depth.base.DepthSource.flying_pixels`): the pixels at depth
                discontinuities are left out (:func:`depth_edges` with ``depth_edge_rtol``;
                nothing when that is null), as their "flying pixels" would be hits in free space,
                and the ``monocular_*`` keys of the map section apply (all off when null).
        Raises:
            InputError: a depth image that is not 2D, bad intrinsics (or a principal point
                outside the image), a non-finite or non-rigid pose.
        """
        depth = depth_image(depth)
        K = pinhole_intrinsics(K, depth.shape)
        T = rigid_pose(T_world_cam)
        s = self.settings
        corners = image_corner_rays(K, depth.shape) * s.max_range_m @ T[:3, :3].T + T[:3, 3]
        lo, hi = self._index_box(np.vstack([corners, T[:3, 3]]))
        if np.any(hi <= lo):
            return  # the frustum misses the grid
        passed = np.zeros(tuple(hi - lo), bool)
        hit = np.zeros_like(passed)
        rays = s.ray_model(monocular)
        skip = depth_edges(depth, rays.depth_edge_rtol) if rays.depth_edge_rtol is not None else np.zeros((0, 0), bool)
        if rays.max_incidence_deg is not None:
            grazing = grazing_pixels(depth, K, rays.max_incidence_deg, rays.normal_window_px, s.ray_stride_px)
            skip = skip | grazing if skip.size else grazing
        weak = rays.far_hit_max is not None
        far = np.zeros_like(passed) if weak else np.zeros((0, 0, 0), bool)
        mark_depth_rays(depth, K[0, 0], K[1, 1], K[0, 2], K[1, 2], s.ray_stride_px, np.ascontiguousarray(T[:3, :3]),
                        np.ascontiguousarray(T[:3, 3]), s.max_range_m, s.invalid_depth == "free",
                        self.origin + lo * self.voxel_size, self.voxel_size, passed, hit, skip, rays.hit_range_m,
                        rays.free_fraction, far)
        self._latest_frame = (lo, passed | hit | far if weak else passed | hit)
        before = self._updates.before(lo, hi)
        self._known_voxels += apply_marks(self._log_odds, self._observed, lo, passed, hit,
                                          np.float32(s.log_odds_hit), np.float32(rays.log_odds_miss),
                                          np.float32(s.log_odds_min), np.float32(s.log_odds_max), far,
                                          np.float32(rays.far_hit_max if weak else s.log_odds_max))
        self._updates.after(lo, hi, before)

    def changes(self, status_only: bool = False) -> ChangedBox:
        """A record of the index box that this map's updates (:meth:`integrate`, :meth:`clear_sphere`,
        :meth:`mark_contact`) touch from now on (:meth:`ChangedBox.take`); no voxel outside it changed.
        `status_only`: the box of the voxels whose state (unknown, free, occupied) flipped."""
        return self._updates.record(status_only)

    def clear_sphere(self, centre: np.ndarray, radius_m: float) -> None:
        """Mark the voxels whose centres lie within `radius_m` of `centre` ((3,) world metres)
        as free (observed, log-odds at most ``log_odds_miss``): where the robot stands is free."""
        box, inside = self._sphere(centre, radius_m, "clear_sphere")
        lo, hi = np.array([b.start for b in box]), np.array([b.stop for b in box])
        before = self._updates.before(lo, hi)
        self._known_voxels += int(np.count_nonzero(inside & ~self._observed[box]))
        self._observed[box] |= inside
        miss = np.float32(max(self.settings.log_odds_miss, self.settings.log_odds_min))
        self._log_odds[box] = np.where(inside, np.minimum(self._log_odds[box], miss), self._log_odds[box])
        self._updates.after(lo, hi, before)

    def mark_contact(self, point: np.ndarray) -> None:
        """Hold the voxel holding `point` ((3,) world metres; none off the grid) occupied at ``log_odds_max``
        from now on, whatever later frames and :meth:`clear_sphere` say: where the robot's bump sensor
        (:attr:`~frontiernet.simulator.agent.MoveResult.contact_point`) felt what its camera never mapped."""
        index = self.world_to_index(np.asarray(point, np.float64).reshape(1, 3))[0]
        if self.in_grid(index):
            before = self._updates.before(index, index + 1)
            self._known_voxels += int(not self._observed[tuple(index)])
            self._updates.pin(index, self.settings.log_odds_max)
            self._updates.after(index, index + 1, before)

    # -- queries ---------------------------------------------------------------------------------

    def visible_known_volume(self, T_world_cams: np.ndarray, width_px: int, focal_px: float,
                             max_depth_m: float, latest_frame_only: bool = False) -> np.ndarray:
        """Known free volume each virtual camera sees, up to occlusion by occupied voxels.

        Each camera is a square pinhole of `width_px` pixels, focal length `focal_px`
        and principal point at the image centre; its rays pass free and unknown voxels,
        stop at occupied ones, at the grid border or at `max_depth_m` (z-depth), and sum
        the free volume they cross (:func:`~frontiernet.mapping.traversal.frustum_volume`).
        A camera outside the grid sees 0.

        Args:
            T_world_cams: (V, 4, 4) float64 camera poses (or one (4, 4) pose).
            width_px: image width = height, pixels; focal_px: pixels; max_depth_m: metres.
            latest_frame_only: count only the free voxels that the latest :meth:`integrate`
                call observed (what one frame saw; 0 before any frame).
        Returns:
            (V,) float64 cubic metres.
        """
        return self._visible_volume(T_world_cams, width_px, focal_px, max_depth_m,
                                    "latest_frame" if latest_frame_only else "known")

    def visible_unknown_volume(self, T_world_cams: np.ndarray, width_px: int, focal_px: float,
                               max_depth_m: float) -> np.ndarray:
        """(V,) float64 unknown volume (m^3) each virtual camera sees: as
        :meth:`visible_known_volume`, summing the unobserved voxels the rays cross instead."""
        return self._visible_volume(T_world_cams, width_px, focal_px, max_depth_m, "unknown")

    def _visible_volume(self, T_world_cams, width_px, focal_px, max_depth_m, counted: str) -> np.ndarray:
        T = np.asarray(T_world_cams, np.float64)
        T = T[None] if T.shape == (4, 4) else T
        if T.ndim != 3 or T.shape[1:] != (4, 4) or not np.all(np.isfinite(T)):
            raise InputError(f"T_world_cams must be finite (V, 4, 4) poses, got shape {T.shape}")
        if not isinstance(scalar(width_px), int) or isinstance(width_px, bool) or width_px < 1:
            raise InputError(f"width_px must be a positive integer, got {width_px!r}")
        focal = positive_number(scalar(focal_px), "focal_px", "pixels")
        max_depth = positive_number(scalar(max_depth_m), "max_depth_m", "metres")
        volumes = np.zeros(len(T), np.float64)
        if len(T) == 0:
            return volumes
        directions = self._pixel_directions(int(width_px), focal)
        corners = np.einsum("vij,cj->vci", T[:, :3, :3], directions[[0, -1, int(width_px) - 1, -int(width_px)]])
        lo, hi = self._index_box(np.vstack([(corners * max_depth + T[:, None, :3, 3]).reshape(-1, 3), T[:, :3, 3]]))
        if np.any(hi <= lo):
            return volumes
        box = tuple(slice(a, b) for a, b in zip(lo, hi))
        observed, occupied = self._observed[box], self._log_odds[box] > self.settings.occupied_threshold
        if counted == "unknown":
            counted_mask = ~observed
        elif counted == "latest_frame":
            counted_mask = observed & ~occupied & self._latest_frame_mask(lo, hi)
        else:
            counted_mask = observed & ~occupied
        frustum_volume(np.ascontiguousarray(T[:, :3, 3]), np.ascontiguousarray(T[:, :3, :3]), directions, max_depth,
                       focal, self.origin + lo * self.voxel_size, self.voxel_size, ~(observed & occupied),
                       counted_mask, volumes)
        return volumes

    def slice_2d(self, z_min: float, z_max: float) -> tuple[np.ndarray, np.ndarray]:
        """A 2D planning view of the height band [z_min, z_max] (world metres).

        The band holds the voxel layers overlapping it (at least the one holding z_min).
        Returns (free, occupied), both (X, Y) bool: a column is occupied when any of its
        band voxels is occupied, free when all of them are free; a band off the grid
        gives all False (unknown). The arrays are read-only: each band's view is kept (map frontiers,
        the planner and the video take the same bands each step) and patched where the map changes
        (:class:`~frontiernet.mapping.bands.BandViews`).
        """
        k0, k1 = self._band_layers(z_min, z_max, "slice_2d")
        if k1 <= k0:
            empty = np.zeros(self.shape[:2], bool)
            return empty, empty.copy()
        return self._bands.view(k0, k1)

    # -- files -----------------------------------------------------------------------------------

    def save(self, path: str | Path) -> Path:
        """Write the map (grid, state and settings) to an ``.npz`` file, atomically."""
        with atomic_path(path) as tmp, open(tmp, "wb") as handle:
            np.savez_compressed(handle, format=_FORMAT, origin=self.origin, log_odds=self._log_odds,
                                observed=self._observed, settings=np.array(repr(asdict(self.settings))))
        return Path(path)

    @classmethod
    def load(cls, path: str | Path) -> OccupancyMap:
        """Read a map written by :meth:`save` (InputError for a missing or foreign file)."""
        import ast

        try:
            with np.load(path, allow_pickle=False) as data:
                if str(data["format"]) != _FORMAT:
                    raise InputError(f"{path}: not an occupancy map file (format {str(data['format'])!r})")
                settings = {**_KEYS_ADDED_AFTER_FILES, **ast.literal_eval(str(data["settings"]))}
                occupancy = cls(data["origin"], data["log_odds"].shape, settings)
                occupancy._log_odds[...] = data["log_odds"]
                occupancy._observed[...] = data["observed"]
        except (OSError, KeyError, ValueError, SyntaxError, EOFError) as error:
            if isinstance(error, InputError):
                raise
            raise InputError(f"{path}: cannot read an occupancy map ({error.__class__.__name__}: {error})") from None
        occupancy._known_voxels = int(np.count_nonzero(occupancy._observed))
        return occupancy

    # -- pieces ----------------------------------------------------------------------------------

    def _sphere(self, centre, radius_m, what: str) -> tuple[tuple, np.ndarray]:
        """The index box (a tuple of slices) around a ball and the (bool) mask of the box's voxels
        whose centres lie within it."""
        centre = np.asarray(centre, np.float64)
        if centre.shape != (3,) or not np.all(np.isfinite(centre)):
            raise InputError(f"{what} centre must be a finite (3,) world point, got {centre!r}")
        radius = positive_number(scalar(radius_m), f"{what} radius_m", "metres", allow_zero=True)
        lo, hi = self._index_box(np.stack([centre - radius, centre + radius]), margin=0)
        box = tuple(slice(a, b) for a, b in zip(lo, hi))
        axes = [self.origin[a] + (np.arange(lo[a], hi[a]) + 0.5) * self.voxel_size - centre[a] for a in range(3)]
        squared = axes[0][:, None, None] ** 2 + axes[1][None, :, None] ** 2 + axes[2][None, None, :] ** 2
        return box, squared <= radius ** 2

    def _band_layers(self, z_min: float, z_max: float, what: str) -> tuple[int, int]:
        """Voxel layer range [k0, k1) of the height band [z_min, z_max] (world metres): the layers
        overlapping it, at least the one holding z_min, clipped to the grid (empty: k1 <= k0)."""
        z_min, z_max = finite_number(z_min, "z_min"), finite_number(z_max, "z_max")
        if z_max < z_min:
            raise InputError(f"{what} needs z_min <= z_max, got {z_min}, {z_max}")
        return band_layers(self.origin[2], self.voxel_size, self.shape[2], z_min, z_max)

    def _latest_frame_mask(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """(hi - lo) bool: the voxels of the index box [lo, hi) that the latest frame observed."""
        mask = np.zeros(tuple(hi - lo), bool)
        if self._latest_frame is None:
            return mask
        frame_lo, touched = self._latest_frame
        a, b = np.maximum(lo, frame_lo), np.minimum(hi, frame_lo + np.asarray(touched.shape))
        if np.all(b > a):
            mask[tuple(slice(x, y) for x, y in zip(a - lo, b - lo))] = \
                touched[tuple(slice(x, y) for x, y in zip(a - frame_lo, b - frame_lo))]
        return mask

    def _index_box(self, points: np.ndarray, margin: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Voxel index range [lo, hi) (two (3,) int64) of the bounding box of (N, 3) world
        points grown by `margin` voxels, clipped to the grid (empty where hi <= lo)."""
        lo = np.floor((points.min(axis=0) - self.origin) / self.voxel_size).astype(np.int64) - margin
        hi = np.floor((points.max(axis=0) - self.origin) / self.voxel_size).astype(np.int64) + 1 + margin
        shape = np.asarray(self.shape)
        return np.clip(lo, 0, shape), np.clip(hi, 0, shape)

    def _pixel_directions(self, width: int, focal: float) -> np.ndarray:
        """(width * width, 3) float64 camera-frame directions (unit z) of a square virtual camera."""
        key = (width, focal)
        if key not in self._view_directions:
            from ..simulator.camera import PinholeCamera

            centre = (width - 1) / 2.0
            camera = PinholeCamera(width, width, focal, focal, centre, centre, np.inf)  # directions only: no range
            self._view_directions[key] = camera.ray_directions().reshape(-1, 3).astype(np.float64)
        return self._view_directions[key]
