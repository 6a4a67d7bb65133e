"""SEER, ``--method seer``: views around the map's frontier clusters scored through a predicted map
(Tao et al., "SEER: Safe Efficient Exploration for Aerial Robots using Learning to Predict Scene
Extents"; tyuezhan/SEER ``frontier_finder.cpp`` and ``bg_exploration_manager.cpp``).

Each frame (numbers: the ``seer`` section of ``configs/explore.yaml``, with their sources):

1. **Clusters.** The map's frontier cells at the camera's height (:mod:`~frontiernet.frontiers.map_frontiers`),
   8-connected, cut into pieces of at most ``seer.cluster_max_extent_m`` (SEER splits a cluster
   with a cell farther than ``frontier/cluster_size_xy`` 1.2 m from its average).
2. **Prediction.** For each cluster, SEER's 80 x 80 x 24 voxel crop around its average, standing on
   the floor, is predicted by the ``seer`` map predictor (``predictOnFrontiers``); its unknown
   voxels above the predictor's threshold (SEER's ``p_pred_occ`` 0.65) are *predicted occupied*.
3. **Candidate views** on circles around the cluster's average (``sampleViewpointsIG``: radii
   ``candidate_rmin_m`` .. ``candidate_rmax_m`` in ``candidate_rnum`` steps, every
   ``candidate_dphi_deg``), kept where the robot can go: reachable cells of the planning grid
   (SEER: not near unknown or obstacles), at least ``min_view_distance_m`` from the robot
   (``getTopViewpointsBC``).
4. **Gain** (``computeInfoGain``): the camera at the view, looking along the mean bearing of the
   cluster's cells turned by each of ``yaw_offsets_deg`` (SEER's six 80-degree groups of its 10-degree
   slices), sees unknown volume along rays that stop at real occupied voxels *and at predicted
   occupied ones*; outside the crop unknown space counts as SEER counts it (as seen). The best
   heading is the view's; the cluster's view is its best-gain one (SEER sorts by gain).
5. **Utility** (``computeFrontierUtilities``, ``ViewNode::computePathTimeCost``): ``gain / (L / vm +
   w_dir * theta)``, L the path length to the view (here the planning grid's, metres), theta the
   angle between the robot's heading and the straight line to the view.

How it fits the shared loop: one :class:`~frontiernet.frontiers.anchoring.FrontierObservation` per
cluster (its view: position, heading, gain) with ``fresh_frontiers``, ranked by the planner's
``rate`` rule (gain / route length). The proposal's ``gain_m3`` is the view's gain times
``L / (L + vm * w_dir * theta)``, so that gain / L is SEER's utility times vm; the proposals of a frame
are then scaled by one factor so that the smallest reaches ``tracking.min_gain_m3`` (the tracker
drops a proposal below it; views whose gain itself is below it are not proposed). A common factor
leaves the ranking as it is.

Cost per step: frontier extraction and one frustum integration per (view, heading) at a
``view_width_px`` raster (numba; ~96 views x 6 headings a cluster), and one crop prediction for each
cluster whose crop is new or has learnt ``repredict_new_voxels`` since it was predicted, at most
``max_predictions_per_step`` a step (the 136k-parameter network: ~0.2-0.4 s a crop on 2 busy cores;
crops are cached and shared by clusters whose average lies within ``reuse_distance_m`` of theirs).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError, positive_number
from ..frontiers.anchoring import FrontierObservation
from ..frontiers.map_frontiers import frontier_cells, frontier_regions
from ..geometry import poses_from_headings
from ..mapping.occupancy import UNKNOWN
from ..mapping.traversal import frustum_volume
from ..planning.grid import geodesic_distance
from ..planning.planner import PlanningGrid
from ..simulator.camera import PinholeCamera
from .motion import yaw_of
from .perception import plain_view
from .predicted import check_predictor, open_predictor
from .sources import FrontierSource, Method, widened_min_cells


@dataclass
class ViewGains:
    """The gains of one cluster's ring of views kept between frames: `crop` the prediction they were
    integrated with, `box` ((2,) lo, (2,) hi) the map's xy index box their rays can reach, `gains`
    {index into the ring: (headings,) m^3}."""

    crop: object
    box: tuple[np.ndarray, np.ndarray]
    gains: dict


@dataclass
class Crop:
    """A cached crop prediction: `corner` (3,) int64 map index of its first voxel, `centre` (2,) world xy
    it was predicted around, `occupied` (X, Y, Z) bool predicted occupied (unknown voxels only),
    `known` the observed voxels of its box when it was predicted."""

    corner: np.ndarray
    centre: np.ndarray
    occupied: np.ndarray
    known: int


def wrap(angle):
    """Angles (radians, any shape) wrapped to (-pi, pi]."""
    return np.pi - (np.pi - np.asarray(angle, np.float64)) % (2 * np.pi)


def _setting(settings, key: str, integer: bool = False) -> float:
    value = positive_number(settings.get(key), f"seer.{key}")
    if integer and not float(value).is_integer():
        raise InputError(f"seer.{key} must be a positive integer, got {value!r}")
    return int(value) if integer else value


class SeerSource(FrontierSource):
    """SEER's views, one per frontier cluster (see the module docstring); prediction timed as
    ``perception``, the rest as ``anchoring``.

    Args:
        predictor: a loaded ``seer`` :class:`~frontiernet.mapprediction.MapPredictor`.
        occupancy: the run's map. conf: the run config (``seer``, ``planner``, ``map_frontiers``,
            ``tracking``, ``motion``). camera: the sim config's ``camera``.
    """

    def __init__(self, predictor, occupancy, conf, camera) -> None:
        if occupancy is None:
            raise InputError("seer needs the run's map (a MethodContext with voxels)")
        s = conf.seer
        self.predictor, self.map, self.conf = predictor, occupancy, conf
        rnum = _setting(s, "candidate_rnum", True)
        self.radii = np.linspace(_setting(s, "candidate_rmin_m"), _setting(s, "candidate_rmax_m"), rnum + 1)
        dphi = np.radians(_setting(s, "candidate_dphi_deg"))
        self.phis = -np.pi + dphi * np.arange(int(np.ceil(2 * np.pi / dphi - 1e-9)))
        self.offsets = np.radians(np.asarray(list(s.yaw_offsets_deg), np.float64))
        if not len(self.offsets):
            raise InputError("seer.yaw_offsets_deg must list at least one heading")
        self.min_view_m = _setting(s, "min_view_distance_m")
        self.time_per_rad = float(s.w_dir)  # s/rad
        self.vm = _setting(s, "max_velocity_mps")
        self.min_cells = _setting(s, "cluster_min_cells", True)
        self.max_extent_m = _setting(s, "cluster_max_extent_m")
        self.repredict = _setting(s, "repredict_new_voxels", True)
        self.per_step = _setting(s, "max_predictions_per_step", True)
        self.reuse_m = _setting(s, "reuse_distance_m")
        self.width = _setting(s, "view_width_px", True)
        self.focal = float(camera.focal_px) * self.width / float(camera.width)  # the camera's field of view
        self.max_depth = float(camera.max_depth)
        centre = (self.width - 1) / 2.0
        self.directions = PinholeCamera(self.width, self.width, self.focal, self.focal, centre, centre,
                                        np.inf).ray_directions().reshape(-1, 3).astype(np.float64)
        self.pitch = np.radians(float(conf.motion.pitch_deg))
        self.band = float(conf.planner.height_band_m)
        self.threshold = predictor.occupied_threshold
        self.min_gain = float(conf.tracking.min_gain_m3)
        budget = s.get("max_scored_clusters_per_step")
        self.score_budget = None if budget is None else _setting(s, "max_scored_clusters_per_step", True)
        self.crops: list[Crop] = []
        self.predictions = 0  # crops predicted so far
        self._last: dict[bytes, tuple[np.ndarray, tuple]] = {}  # cluster key -> (its average xy, its last view)
        # a view's gain changes only when a voxel within its rays' reach changes state (unknown, free,
        # occupied): the gains of each cluster's ring of views are kept (per cluster cells and crop)
        # until a voxel near it does (a frame that sees again what the map knows flips little)
        self.reach = self.max_depth / np.cos(np.arctan(np.sqrt(2.0) * (self.width / 2.0) / self.focal))
        self._changes = occupancy.changes(status_only=True)  # the gains read observed and occupied alone
        self._view_gains: dict[bytes, ViewGains] = {}
        self._used: set[bytes] = set()  # the keys of this frame's clusters
        # within this of the robot the grid's unknown band under the camera is open (omniscient.py's ring)
        lowest = np.arctan(float(camera.height) / 2.0 / float(camera.focal_px)) - self.pitch
        self.ring_m = float(conf.planner.clearance_m) + self.band / np.tan(lowest)

    def __call__(self, frame, depth, stopwatch):
        T = frame.T_world_cam
        z = float(T[2, 3])
        with stopwatch("anchoring"):
            clusters = self.clusters(z)
        with stopwatch("perception"):
            crops = self.crops_for(clusters, z - float(self.conf.motion.camera_height_m))
        with stopwatch("anchoring"):
            observations = self.views(clusters, crops, T)
        return observations, plain_view(frame, depth)

    def widen(self) -> bool:
        """Once a run would stop: clusters down to ``map_frontiers.min_cells_before_stop`` cells from then on
        (:func:`~.sources.widened_min_cells`; once: the next stop is the run's end)."""
        smallest = widened_min_cells(self.conf, self.min_cells)
        if smallest is None:
            return False
        self.min_cells = smallest
        return True

    # -- clusters and their predictions ---------------------------------------------------------

    def clusters(self, z: float) -> list[np.ndarray]:
        """The frontier clusters at camera height `z`: a list of (N, 2) float64 world xy of their cells."""
        free, occupied = self.map.slice_2d(z - self.band, z + self.band)
        cells, piece = frontier_regions(frontier_cells(free, occupied)[0], self.min_cells,
                                        self.max_extent_m / float(self.map.voxel_size))
        xy = np.asarray(self.map.origin[:2], np.float64) + (cells + 0.5) * float(self.map.voxel_size)
        return [xy[piece == p] for p in range(int(piece.max()) + 1 if len(piece) else 0)]

    def _known(self, corner: np.ndarray) -> int:
        lo = np.clip(corner, 0, self.map.shape)
        hi = np.clip(corner + np.asarray(self.predictor.spec.crop_shape), 0, self.map.shape)
        return int(self.map.observed[tuple(slice(a, b) for a, b in zip(lo, hi))].sum())

    def crops_for(self, clusters: list[np.ndarray], floor_z: float) -> list[Crop | None]:
        """Each cluster's crop prediction: a cached one whose centre lies within ``reuse_distance_m`` of
        the cluster's average and whose box has learnt fewer than ``repredict_new_voxels`` since, else
        a new one (largest clusters first, at most ``max_predictions_per_step``; beyond them a stale
        crop or none)."""
        out: list[Crop | None] = [None] * len(clusters)
        fresh: dict[int, bool] = {}
        budget = self.per_step
        for index in sorted(range(len(clusters)), key=lambda k: -len(clusters[k])):
            centre = clusters[index].mean(axis=0)
            near = [k for k, crop in enumerate(self.crops) if np.hypot(*(crop.centre - centre)) <= self.reuse_m]
            near.sort(key=lambda k: np.hypot(*(self.crops[k].centre - centre)))
            if near:
                k = near[0]
                if k not in fresh:
                    fresh[k] = self._known(self.crops[k].corner) - self.crops[k].known < self.repredict
                if fresh[k] or budget == 0:
                    out[index] = self.crops[k]
                    continue
                del self.crops[k]
                fresh = {}
            if budget == 0:
                continue
            prediction = self.predictor.predict_crop(self.map, centre, floor_z)
            occupied = (prediction.probability > self.threshold) & (prediction.states == UNKNOWN)
            crop = Crop(prediction.corner, centre, occupied, self._known(prediction.corner))
            self.crops.append(crop)
            fresh[len(self.crops) - 1] = True
            out[index] = crop
            budget -= 1
            self.predictions += 1
        self.crops = [crop for crop in self.crops if any(crop is used for used in out)]  # the clusters' crops only
        return out

    # -- views --------------------------------------------------------------------------------

    def gains(self, poses: np.ndarray, crop: Crop | None) -> np.ndarray:
        """(V,) unknown volume (m^3) the (V, 4, 4) camera poses see through the map, rays stopping at
        occupied voxels and at the predicted occupied ones of `crop` (None: none predicted)."""
        volumes = np.zeros(len(poses))
        if not len(poses):
            return volumes
        voxel, origin = float(self.map.voxel_size), np.asarray(self.map.origin, np.float64)
        lo = np.floor((poses[:, :3, 3].min(axis=0) - self.reach - origin) / voxel).astype(np.int64)
        hi = np.ceil((poses[:, :3, 3].max(axis=0) + self.reach - origin) / voxel).astype(np.int64) + 1
        lo, hi = np.clip(lo, 0, self.map.shape), np.clip(hi, 0, self.map.shape)
        box = tuple(slice(a, b) for a, b in zip(lo, hi))
        observed = self.map.observed[box]
        blocked = observed & (self.map.log_odds[box] > self.map.settings.occupied_threshold)
        if crop is not None:
            c_lo, c_hi = np.maximum(lo, crop.corner), np.minimum(hi, crop.corner + np.asarray(crop.occupied.shape))
            if np.all(c_hi > c_lo):
                inner = tuple(slice(a - b, c - b) for a, b, c in zip(c_lo, lo, c_hi))
                in_crop = tuple(slice(a - b, c - b) for a, b, c in zip(c_lo, crop.corner, c_hi))
                blocked[inner] |= crop.occupied[in_crop] & ~observed[inner]
        frustum_volume(np.ascontiguousarray(poses[:, :3, 3]), np.ascontiguousarray(poses[:, :3, :3]), self.directions,
                       self.max_depth, self.focal, origin + lo * voxel, voxel, np.ascontiguousarray(~blocked),
                       np.ascontiguousarray(~observed), volumes)
        return volumes

    def _open_cells(self, T: np.ndarray, z: float):
        """(grid, (X, Y) float64 path length in metres from the robot, inf where it cannot go)."""
        xy = T[:2, 3]
        grid = PlanningGrid.from_map(self.map, z, self.conf.planner, xy)
        start = grid.cell(xy)
        if not grid.inside(*start):
            return grid, np.full(grid.cost.shape, np.inf)
        i, j = np.indices(grid.cost.shape)
        centre = (np.asarray(xy) - grid.origin_xy) / grid.cell_m - 0.5
        ring = (i - centre[0]) ** 2 + (j - centre[1]) ** 2 <= (self.ring_m / grid.cell_m) ** 2
        open_cells = np.isfinite(grid.cost) | ring
        return grid, geodesic_distance(np.where(open_cells, 1.0, np.inf), start) * grid.cell_m

    def best_view(self, cells: np.ndarray, centre: np.ndarray, key: bytes, crop: Crop | None, grid, length: np.ndarray,
                  robot: np.ndarray, z: float):
        """(xy (2,), yaw, gain m^3, path length m) of the best-gain view of the cluster of (N, 2) world xy
        `cells` (average `centre`, identity `key`: :meth:`_key`), or None."""
        ring = np.array([[r * np.cos(p), r * np.sin(p)] for r in self.radii for p in self.phis])
        xy = centre + ring
        index = grid.cells(xy)
        inside = (index[:, 0] >= 0) & (index[:, 1] >= 0) & (index[:, 0] < grid.cost.shape[0]) \
            & (index[:, 1] < grid.cost.shape[1])
        keep = np.flatnonzero(inside)
        keep = keep[np.isfinite(grid.cost[index[keep, 0], index[keep, 1]])
                    & np.isfinite(length[index[keep, 0], index[keep, 1]])
                    & (np.hypot(*(xy[keep] - robot).T) >= self.min_view_m)]
        if not len(keep):
            return None
        sample = cells[:: max(1, len(cells) // 64)]  # the bearing of the cluster (SEER: its down-sampled cells)
        bearings = np.arctan2(sample[None, :, 1] - xy[keep, None, 1], sample[None, :, 0] - xy[keep, None, 0])
        mean = bearings[:, 0] + wrap(bearings - bearings[:, :1]).mean(axis=1)
        yaws = mean[:, None] + self.offsets[None, :]  # (kept views, headings)
        kept = self._kept_gains(key, crop, centre)
        missing = [k for k, ring_index in enumerate(keep) if ring_index not in kept.gains]
        if missing:
            poses = poses_from_headings(np.column_stack([np.repeat(xy[keep[missing]], len(self.offsets), axis=0),
                                                         np.full(len(missing) * len(self.offsets), z)]),
                                        yaws[missing].reshape(-1), self.pitch)
            for k, view_gains in zip(missing, self.gains(poses, crop).reshape(len(missing), len(self.offsets))):
                kept.gains[int(keep[k])] = view_gains
        gains = np.array([kept.gains[int(ring_index)] for ring_index in keep])
        best = np.unravel_index(int(np.argmax(gains)), gains.shape)
        cell = index[keep[best[0]]]
        return xy[keep[best[0]]], float(wrap(yaws[best])), float(gains[best]), float(length[cell[0], cell[1]])

    def _key(self, cells: np.ndarray, z: float) -> bytes:
        """A cluster's identity between frames: its (N, 2) world xy `cells` and the camera height `z`."""
        return np.round(cells / float(self.map.voxel_size)).astype(np.int64).tobytes() + np.float64(z).tobytes()

    def _scored(self, key: bytes, crop: Crop | None) -> bool:
        """Whether the ring of views of the cluster `key` has gains kept with `crop` (only views newly
        reachable to score)."""
        kept = self._view_gains.get(key)
        return kept is not None and kept.crop is crop

    def _stale_view(self, key: bytes, centre: np.ndarray, grid, length: np.ndarray, previous: dict):
        """The last view of this cluster (by `key`, else of the last frame's cluster whose average lies
        within ``reuse_distance_m`` of `centre`), its path length measured again on this frame's grid; None
        when there is none or it is out of reach now."""
        record = previous.get(key)
        if record is None and previous:
            near = min(previous.values(), key=lambda item: float(np.hypot(*(item[0] - centre))))
            record = near if np.hypot(*(near[0] - centre)) <= self.reuse_m else None
        if record is None:
            return None
        xy, yaw, gain, _ = record[1]
        cell = grid.cells(np.asarray(xy)[None])[0]
        if not (0 <= cell[0] < length.shape[0] and 0 <= cell[1] < length.shape[1]) \
                or not np.isfinite(length[cell[0], cell[1]]):
            return None
        return xy, yaw, gain, float(length[cell[0], cell[1]])

    def _kept_gains(self, key: bytes, crop: Crop | None, centre: np.ndarray) -> ViewGains:
        """The :class:`ViewGains` of the cluster `key` (average `centre`) with `crop` (a new, empty one when
        none is kept for it, or it was integrated with another crop)."""
        kept = self._view_gains.get(key)
        if kept is None or kept.crop is not crop:
            reach = self.radii[-1] + self.reach
            origin, voxel = np.asarray(self.map.origin[:2], np.float64), float(self.map.voxel_size)
            box = (np.floor((centre - reach - origin) / voxel).astype(np.int64),
                   np.ceil((centre + reach - origin) / voxel).astype(np.int64) + 1)
            kept = self._view_gains[key] = ViewGains(crop, box, {})
        self._used.add(key)
        return kept

    def _forget_changed(self) -> None:
        """Drop the kept gains of clusters whose box holds a voxel whose state flipped since the last frame."""
        changed = self._changes.take()
        if changed is None:
            return
        lo, hi = np.array([changed[0].start, changed[1].start]), np.array([changed[0].stop, changed[1].stop])
        for key in [k for k, kept in self._view_gains.items() if np.all(kept.box[0] < hi) and np.all(lo < kept.box[1])]:
            del self._view_gains[key]

    def views(self, clusters, crops, T: np.ndarray) -> list[FrontierObservation]:
        """One observation per cluster with a view of at least ``tracking.min_gain_m3`` (see the module
        docstring for its gain)."""
        z, robot, heading = float(T[2, 3]), T[:2, 3], yaw_of(T)
        if not clusters:
            return []
        grid, length = self._open_cells(T, z)
        self._forget_changed()
        self._used = set()
        previous, self._last = self._last, {}
        budget = self.score_budget
        found = []
        # nearest clusters first: with seer.max_scored_clusters_per_step, those beyond the budget whose views
        # must be scored anew keep their last view (its gain from then) this frame
        order = range(len(clusters)) if budget is None else \
            sorted(range(len(clusters)), key=lambda k: float(np.hypot(*(clusters[k].mean(axis=0) - robot))))
        for index in order:
            cells, crop = clusters[index], crops[index]
            key, centre = self._key(cells, z), cells.mean(axis=0)
            if budget is not None and not self._scored(key, crop):
                if budget == 0:
                    view = self._stale_view(key, centre, grid, length, previous)
                    if view is not None:
                        self._last[key] = (centre, view)
                    if view is None or view[2] < self.min_gain:
                        continue
                    found.append(self._observation(view, cells, robot, heading, z, T))
                    continue
                budget -= 1
            view = self.best_view(cells, centre, key, crop, grid, length, robot, z)
            if view is not None:
                self._last[key] = (centre, view)
            if view is None or view[2] < self.min_gain:
                continue
            found.append(self._observation(view, cells, robot, heading, z, T))
        self._view_gains = {key: kept for key, kept in self._view_gains.items() if key in self._used}  # this frame's
        if not found:
            return []
        scale = max(1.0, self.min_gain / min(o.gain_m3 for o in found))  # no proposal below g_min; order kept
        return [replace(o, gain_m3=o.gain_m3 * scale) for o in found]

    def _observation(self, view: tuple, cells: np.ndarray, robot: np.ndarray, heading: float, z: float,
                     T: np.ndarray) -> FrontierObservation:
        """The proposal of a cluster's view (xy, yaw, gain, path length): its gain weighted by SEER's heading
        cost (module docstring, 5.)."""
        xy, yaw, gain, path = view
        theta = abs(float(wrap(np.arctan2(xy[1] - robot[1], xy[0] - robot[0]) - heading)))
        path = max(path, float(self.conf.planner.min_distance_m))
        weighted = gain * path / (path + self.vm * self.time_per_rad * theta)
        return FrontierObservation(np.array([xy[0], xy[1], z]), np.array([np.cos(yaw), np.sin(yaw), 0.0]),
                                   weighted, len(cells), np.full(2, np.nan), np.array(T, np.float64))


def make_seer(context) -> Method:
    """The ``seer`` method (:data:`~frontiernet.exploration.methods.METHODS`): SEER's views around the
    map's frontier clusters, goal rule ``rate``; its predictor is ``--model`` or ``seer.predictor``."""
    predictor = open_predictor(context.conf, "seer", context.model)
    source = SeerSource(predictor, context.map, context.conf, context.sim_conf.camera)
    return Method("seer", source, "rate", fresh_frontiers=True, uses_model=True)


make_seer.uses_model = True  # --model names its predictor file (methods.uses_model)
make_seer.model_kind = "seer predictor"  # not a FrontierNet model: bench --model is not for it
make_seer.check = check_predictor("seer")  # before the scene loads (methods.check_method)
make_seer.needs_map = "predicts the map around the map's frontier clusters"  # no --map-free (check_method)

__all__ = ["Crop", "SeerSource", "make_seer"]
