"""Per-view ground truth: frontier pixels, the distance field and info-gain classes.

The method of docs/design.md section 3 and the paper's section III-D, for one camera pose in
a scene voxelised at 0.1 m:

1. **V_in**: voxels the camera observes, i.e. every voxel a pixel's ray passes through
   up to its hit (or up to the sensor's max range when it hits nothing in range),
   the hit surface included. V_out is the rest of the explorable volume.
2. **V_ft**: observed explorable voxels with an unobserved explorable neighbour
   (6- or 26-connected) in view: frontiers made only by the edge of the field of view
   (the unobserved neighbour projects outside the image or behind the near plane) are
   left out by default (``ignore_fov_frontiers``). No image cue marks them, F_d would
   drop them anyway, and near the camera they would lie close to every pixel's ray.
3. **Gain** of a frontier voxel: the unobserved (V_out) volume a camera of the same
   model and range sees from the voxel at its best viewpoint looking from V_in towards
   V_out: the best of headings within +-90 degrees of the direction from the observed to
   the unobserved free voxels around it (and tilted like it).
   Measured at ~10 % of V_ft, blended to the rest. Two choices change the definition
   (:func:`gain_definition`, ``ground_truth.gain.volume`` / ``.spread``): ``volume:
   occluded`` counts only V_out inside this view's frustum (the space the frontier's
   occluder hides from this camera, not the space beside or behind it), and ``spread:
   region`` gives every voxel of a connected frontier region the largest gain measured in
   it (one gain per region) instead of the blend of the nearest samples.
4. **F_p**: pixels whose ray (from the near clipping plane to its hit) passes within
   ``r_ray_m`` of a frontier voxel's centre; the pixel's *ray gain* is the largest gain
   among those voxels.
5. **F_d**: depth discontinuities; **F** = F_p AND F_d; **D**: distance to F in
   pixels, truncated at r; **gain_class**: the gain binned into K = 11 classes.

Everything runs inside a box of the voxel grid around the camera that holds all it can
reach, so the cost does not grow with the building.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from frontiernet.errors import InputError, positive_number
from frontiernet.geometry import atan2, rotation_from_yaw_pitch
from frontiernet.mapping.traversal import frustum_volume, mark_traversed
from frontiernet.simulator.camera import Frame, PinholeCamera, Renderer
from frontiernet.simulator.voxels import VoxelGrid

from .labels import discontinuity_mask, distance_field, gain_classes, gain_definition
from .traversal import max_gain_near_rays


@dataclass
class GroundTruth:
    """Ground truth of one view. Images are (H, W); depth and gain are metric.

    Attributes:
        rgb: (H, W, 3) uint8 rendered colour.
        depth: (H, W) float32 z-depth in metres, NaN where invalid (no hit, beyond range).
        frontier_projected: (H, W) bool, F_p.
        discontinuity: (H, W) bool, F_d.
        frontier_mask: (H, W) bool, F = F_p AND F_d.
        distance_field: (H, W) float32 pixels, distance to F truncated at r.
        gain: (H, W) float32 cubic metres (see ``ground_truth.gain.label_region``).
        gain_class: (H, W) int64 in [0, K - 1]; 0 = no gain.
        T_world_cam: (4, 4) float64; K: (3, 3) float64.
        frontier_voxels: (M, 3) float64 world centres of V_ft, metres.
        frontier_voxel_gain: (M,) float32 cubic metres, gain of each frontier voxel.
        gain_sampled: (M,) bool, voxels whose gain was measured (the rest are blended).
        observed_voxels: number of voxels in V_in.
        far_depth: (H, W) float32 metres, the z-depth of surfaces hit beyond the depth sensor's
            range (``Frame.hit_depth`` there; NaN where the sensor's ``depth`` is valid or nothing
            is hit), or None when the frame has no ``hit_depth``. What a monocular network sees
            that the sensor does not: training emulates monocular depth from it as the explorer
            does (docs/exploration.md, "Monocular depth").
        timings: seconds per stage.
    """

    rgb: np.ndarray
    depth: np.ndarray
    frontier_projected: np.ndarray
    discontinuity: np.ndarray
    frontier_mask: np.ndarray
    distance_field: np.ndarray
    gain: np.ndarray
    gain_class: np.ndarray
    T_world_cam: np.ndarray
    K: np.ndarray
    frontier_voxels: np.ndarray
    frontier_voxel_gain: np.ndarray
    gain_sampled: np.ndarray
    observed_voxels: int
    far_depth: np.ndarray | None = None
    timings: dict = field(default_factory=dict)

    def arrays(self) -> dict:
        """The per-pixel arrays the dataset stores (see :mod:`datagen.shards`)."""
        arrays = {"rgb": self.rgb, "depth": self.depth, "frontier_mask": self.frontier_mask,
                  "frontier_projected": self.frontier_projected, "discontinuity": self.discontinuity,
                  "gain": self.gain, "gain_class": self.gain_class}
        if self.far_depth is not None:
            arrays["far_depth"] = self.far_depth
        return arrays


def far_depth(frame: Frame) -> np.ndarray | None:
    """(H, W) float32 metres: ``frame.hit_depth`` where the sensor's depth is invalid and a surface
    is hit (beyond the range), NaN elsewhere; None when the frame was rendered without it."""
    if frame.hit_depth is None:
        return None
    hit = np.asarray(frame.hit_depth, np.float32)
    return np.where(np.isnan(frame.depth) & np.isfinite(hit), hit, np.float32(np.nan)).astype(np.float32)


def _bounding_slices(mask: np.ndarray, margin: int) -> tuple[slice, ...]:
    """Slices of the bounding box of `mask`'s True voxels grown by `margin` (empty mask: empty box)."""
    slices = []
    for axis in range(mask.ndim):
        hits = np.flatnonzero(mask.any(axis=tuple(a for a in range(mask.ndim) if a != axis)))
        if len(hits) == 0:
            return tuple(slice(0, 0) for _ in range(mask.ndim))
        slices.append(slice(max(hits[0] - margin, 0), min(hits[-1] + margin + 1, mask.shape[axis])))
    return tuple(slices)


def _unit_offsets(radius: int) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) int64 offsets of a cube of `radius` (centre excluded) and (M, 3) unit vectors."""
    r = np.arange(-radius, radius + 1)
    offsets = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
    offsets = offsets[np.any(offsets != 0, axis=1)]
    return offsets, offsets / np.linalg.norm(offsets, axis=1, keepdims=True)


class GroundTruthGenerator:
    """Computes :class:`GroundTruth` for camera poses in one scene.

    Args:
        scene: the scene (world Z-up, metres).
        voxels: its :func:`~frontiernet.simulator.voxels.voxelize_scene` grid.
        conf: the merged datagen config (``camera``, ``ground_truth`` sections; see
            :func:`datagen.config.load_datagen_config`).
        renderer: a :class:`Renderer` to reuse (built from ``conf.camera`` otherwise).
    """

    def __init__(self, scene, voxels: VoxelGrid, conf, renderer: Renderer | None = None) -> None:
        self.scene, self.voxels = scene, voxels
        self.camera = renderer.camera if renderer is not None else PinholeCamera.from_config(conf.camera)
        self.renderer = renderer or Renderer(scene, self.camera, background=conf.camera.background)
        gt = conf.ground_truth
        self.conf = gt
        self.stride = int(gt.observe_stride_px)
        if self.stride < 1:
            raise InputError(f"ground_truth.observe_stride_px must be >= 1, got {gt.observe_stride_px!r}")
        if gt.frontier_connectivity not in (6, 26):
            raise InputError(f"ground_truth.frontier_connectivity must be 6 or 26, got {gt.frontier_connectivity!r}")
        self.structure = ndimage.generate_binary_structure(3, 1 if gt.frontier_connectivity == 6 else 3)
        for key in ("r_ray_m", "near_clip_m"):
            positive_number(gt[key], f"ground_truth.{key}", "metres", allow_zero=True)
        self.camera_directions = self.camera.ray_directions().reshape(-1, 3)  # (H*W, 3) unit z
        gain = gt.gain
        self.direction_offsets, self.direction_units = _unit_offsets(int(gain.direction_radius_voxels))
        scale = int(gain.camera_px) / self.camera.width
        width, height = int(gain.camera_px), max(int(round(self.camera.height * scale)), 1)
        gain_camera = PinholeCamera(width, height, self.camera.fx * scale, self.camera.fy * scale,
                                    (width - 1) / 2.0, (height - 1) / 2.0, self.camera.max_depth)
        self.gain_directions = gain_camera.ray_directions().reshape(-1, 3).astype(np.float64)
        self.gain_focal_px = float(np.sqrt(gain_camera.fx * gain_camera.fy))
        self.yaw_offsets = np.deg2rad(np.asarray(list(gain.yaw_offsets_deg), np.float64))
        if len(self.yaw_offsets) == 0:
            raise InputError("ground_truth.gain.yaw_offsets_deg must list at least one heading")
        self.gain_volume, self.gain_spread = gain_definition(gain).split("/")
        max_dir = float(np.linalg.norm(self.camera_directions, axis=1).max())
        self.reach_m = self.camera.max_depth * max_dir  # farthest point any pixel ray reaches

    # -- the pipeline ---------------------------------------------------------------------------

    def __call__(self, T_world_cam: np.ndarray, rng: np.random.Generator) -> GroundTruth:
        """Render the view at `T_world_cam` (4, 4) and compute its ground truth."""
        start = time.perf_counter()
        frame = self.renderer.render(T_world_cam)
        result = self.from_frame(frame, rng)
        result.timings = {"render": time.perf_counter() - start - sum(result.timings.values()), **result.timings}
        return result

    def from_frame(self, frame: Frame, rng: np.random.Generator) -> GroundTruth:
        """Ground truth for an already rendered :class:`Frame` of this scene and camera."""
        timings: dict[str, float] = {}
        clock = time.perf_counter()

        def lap(name: str) -> None:
            nonlocal clock
            now = time.perf_counter()
            timings[name] = now - clock
            clock = now

        H, W = frame.depth.shape
        T = np.asarray(frame.T_world_cam, np.float64)
        origin = T[:3, 3].copy()
        directions = (self.camera_directions @ T[:3, :3].T.astype(np.float32)).astype(np.float32)
        t_end = np.where(np.isfinite(frame.depth), frame.depth, np.float32(self.camera.max_depth))
        t_end = np.ascontiguousarray(t_end.reshape(-1), np.float32)

        lo, hi, box_origin = self._box(origin)
        box = tuple(slice(a, b) for a, b in zip(lo, hi))
        free = np.ascontiguousarray(self.voxels.explorable[box])
        size = self.voxels.voxel_size

        # 1. V_in: voxels along every stride-th pixel ray
        observed = np.zeros(free.shape, bool)
        rows = np.arange(0, H, self.stride)
        cols = np.arange(0, W, self.stride)
        pick = (rows[:, None] * W + cols[None, :]).reshape(-1)
        mark_traversed(origin, np.ascontiguousarray(directions[pick]), np.ascontiguousarray(t_end[pick]),
                       box_origin, size, observed)
        lap("observe")

        # 2. V_ft: observed free voxels touching unobserved free space (within V_in's bounding box)
        seen = _bounding_slices(observed, margin=1)
        unobserved_free = free[seen] & ~observed[seen]
        if self.conf.ignore_fov_frontiers:
            unobserved_free &= self._in_view(seen, box_origin, T)
        frontier = free[seen] & observed[seen] & ndimage.binary_dilation(unobserved_free, self.structure)
        frontier_index = np.argwhere(frontier) + [s.start for s in seen]  # (M, 3) box indices
        frontier_world = box_origin + (frontier_index + 0.5) * size
        region = None
        if self.gain_spread == "region":  # (M,) int connected region (26-connected) of each frontier voxel
            labelled, _ = ndimage.label(frontier, ndimage.generate_binary_structure(3, 3))
            region = labelled[frontier] - 1  # np.argwhere and boolean indexing share C order
        lap("frontier_voxels")

        # 3. gain of the frontier voxels
        counted = ~observed
        if self.gain_volume == "occluded":  # only V_out this camera's frustum holds (behind its occluders)
            counted &= self._in_view(tuple(slice(0, n) for n in free.shape), box_origin, T)
        voxel_gain, sampled = self._frontier_gains(frontier_index, frontier_world, origin, box_origin,
                                                   free, observed, counted, rng, region)
        lap("gain_views")

        # 4. F_p and the ray gain: the best frontier voxel within r_ray of each pixel's ray
        best = np.full((H, W), -1.0, np.float32)
        centres_cam = (frontier_world - origin) @ T[:3, :3]  # (M, 3) camera frame
        cam = self.camera
        max_gain_near_rays(centres_cam, voxel_gain.astype(np.float64), t_end.reshape(H, W), cam.fx,
                           cam.fy, cam.cx, cam.cy, float(self.conf.near_clip_m), float(self.conf.r_ray_m), best)
        frontier_projected = best >= 0.0
        ray_gain = np.maximum(best, 0.0)
        lap("project")

        # 5. image-space labels
        disc = self.conf.discontinuity
        discontinuity = discontinuity_mask(frame.depth, int(disc.window_px), float(disc.relative_jump),
                                           float(disc.min_jump_m), bool(disc.invalid_is_far))
        frontier_mask = frontier_projected & discontinuity
        truncation = float(self.conf.truncation_px)
        field_px, nearest = distance_field(frontier_mask, truncation, return_nearest=True)
        gain_conf = self.conf.gain
        if gain_conf.label_region == "band":
            gain = np.where(field_px < truncation, ray_gain[nearest[0], nearest[1]], 0.0).astype(np.float32)
        elif gain_conf.label_region == "rays":
            gain = ray_gain.astype(np.float32)
        else:
            raise InputError(f"ground_truth.gain.label_region must be 'band' or 'rays', got "
                             f"{gain_conf.label_region!r}")
        gain_class = gain_classes(gain, list(gain_conf.bin_edges), float(gain_conf.bin_unit_m3))
        lap("labels")
        return GroundTruth(rgb=frame.rgb, depth=frame.depth, frontier_projected=frontier_projected,
                           discontinuity=discontinuity, frontier_mask=frontier_mask, distance_field=field_px,
                           gain=gain, gain_class=gain_class, T_world_cam=T, K=np.asarray(frame.K, np.float64),
                           frontier_voxels=frontier_world, frontier_voxel_gain=voxel_gain.astype(np.float32),
                           gain_sampled=sampled, observed_voxels=int(observed.sum()),
                           far_depth=far_depth(frame), timings=timings)

    # -- pieces ----------------------------------------------------------------------------------

    def _in_view(self, region: tuple[slice, ...], box_origin: np.ndarray, T_world_cam: np.ndarray) -> np.ndarray:
        """Bool array over `region` (box slices): voxel centres that project into the image in
        front of the near clipping plane (at any depth: space beyond the range is in view)."""
        axes = [box_origin[a] + (np.arange(region[a].start, region[a].stop) + 0.5) * self.voxels.voxel_size
                for a in range(3)]
        R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
        # camera coordinates of every centre, separably: p_cam = R^T (p - t)
        cam = (R[0][:, None, None, None] * (axes[0] - t[0])[None, :, None, None]
               + R[1][:, None, None, None] * (axes[1] - t[1])[None, None, :, None]
               + R[2][:, None, None, None] * (axes[2] - t[2])[None, None, None, :])
        z = cam[2]
        cam_ = self.camera
        with np.errstate(divide="ignore", invalid="ignore"):
            u = cam_.fx * cam[0] / z + cam_.cx
            v = cam_.fy * cam[1] / z + cam_.cy
        return (z > float(self.conf.near_clip_m)) & (u >= -0.5) & (u <= cam_.width - 0.5) \
            & (v >= -0.5) & (v <= cam_.height - 0.5)

    def _box(self, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Voxel index range [lo, hi) of everything a view from `origin` and its gain views reach.

        Gain views start at frontier voxels (within `reach` of the camera) and reach as far
        again; one voxel of margin keeps the unobserved neighbours of every frontier voxel.
        """
        voxels = self.voxels
        reach = 2.0 * self.reach_m + 2 * voxels.voxel_size
        lo = np.floor((origin - reach - voxels.origin) / voxels.voxel_size).astype(np.int64)
        hi = np.ceil((origin + reach - voxels.origin) / voxels.voxel_size).astype(np.int64)
        lo = np.clip(lo, 0, voxels.shape)
        hi = np.clip(hi, 0, voxels.shape)
        return lo, hi, voxels.origin + lo * voxels.voxel_size

    def _frontier_gains(self, frontier_index, frontier_world, camera_origin, box_origin, free, observed, counted,
                        rng: np.random.Generator, region: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Gain (m^3) of every frontier voxel: measured at a subsample, spread to the rest.

        Args:
            counted: (X, Y, Z) bool box array, the voxels whose volume counts (V_out, or the part
                of it in view).
            region: (M,) int connected region of each voxel (``spread: region``) or None (blend).
        Returns (M,) float64 gains and (M,) bool "measured here".
        """
        conf = self.conf.gain
        m = len(frontier_index)
        sampled = np.zeros(m, bool)
        if m == 0:
            return np.zeros(0), sampled
        count = int(np.clip(round(float(conf.sample_fraction) * m), int(conf.min_samples), int(conf.max_samples)))
        count = min(count, m)
        if region is None:
            pick = rng.choice(m, size=count, replace=False)
        else:
            pick = self._region_samples(region, count, rng)
        pick = np.sort(pick)
        sampled[pick] = True
        directions = self._view_directions(frontier_index[pick], frontier_world[pick], camera_origin,
                                           free, observed)
        yaw = atan2(directions[:, 1], directions[:, 0])
        limit = np.deg2rad(float(conf.max_pitch_deg))
        pitch = np.clip(atan2(directions[:, 2], np.hypot(directions[:, 0], directions[:, 1])), -limit, limit)
        yaws = (yaw[:, None] + self.yaw_offsets[None, :]).reshape(-1)
        pitches = np.repeat(pitch, len(self.yaw_offsets))
        rotations = np.ascontiguousarray(rotation_from_yaw_pitch(yaws, pitches))
        origins = np.ascontiguousarray(np.repeat(frontier_world[pick], len(self.yaw_offsets), axis=0))
        volumes = np.empty(len(origins), np.float64)
        frustum_volume(origins, rotations, self.gain_directions, float(self.camera.max_depth), self.gain_focal_px,
                       box_origin, self.voxels.voxel_size, free, counted, volumes)  # V_out seen through free space
        sample_gain = volumes.reshape(len(pick), -1).max(axis=1)
        gain = self._blend(frontier_world, pick, sample_gain)
        if region is not None:  # one gain per region: the largest measured in it
            best = np.full(int(region.max()) + 1, -1.0)
            np.maximum.at(best, region[pick], sample_gain)
            gain = np.where(best[region] >= 0.0, best[region], gain)
        return gain, sampled

    @staticmethod
    def _region_samples(region: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
        """`count` distinct voxel indices: one random voxel of each connected region, the largest
        regions first, then random others (regions beyond `count` take the blend of the nearest
        samples)."""
        sizes = np.bincount(region)
        order = np.argsort(-sizes, kind="stable")[:count]
        first = np.array([rng.choice(np.flatnonzero(region == r)) for r in order], np.int64)
        rest = np.setdiff1d(np.arange(len(region)), first)
        more = rng.choice(rest, size=min(count - len(first), len(rest)), replace=False)
        return np.concatenate([first, more.astype(np.int64)])

    def _view_directions(self, index, world, camera_origin, free, observed) -> np.ndarray:
        """(S, 3) unit directions from observed towards unobserved free space around each voxel.

        The sum of unit offsets to unobserved free neighbours minus those to observed free
        ones (within ``direction_radius_voxels``); where that cancels, the camera's own
        viewing direction to the voxel.
        """
        neighbours = index[:, None, :] + self.direction_offsets[None]  # (S, M, 3)
        inside = np.all((neighbours >= 0) & (neighbours < np.asarray(free.shape)), axis=-1)
        clipped = np.clip(neighbours, 0, np.asarray(free.shape) - 1)
        flat = (clipped[..., 0], clipped[..., 1], clipped[..., 2])
        is_free = free[flat] & inside
        weight = np.where(observed[flat], -1.0, 1.0) * is_free  # +1 unobserved free, -1 observed free
        direction = np.einsum("sm,mc->sc", weight, self.direction_units)
        norm = np.linalg.norm(direction, axis=1)
        fallback = world - camera_origin
        fallback /= np.maximum(np.linalg.norm(fallback, axis=1, keepdims=True), 1e-9)
        ok = norm > 1e-6
        direction[ok] /= norm[ok, None]
        direction[~ok] = fallback[~ok]
        return direction

    def _blend(self, world: np.ndarray, pick: np.ndarray, sample_gain: np.ndarray) -> np.ndarray:
        """Inverse-distance blend of the measured gains to every frontier voxel (exact at samples)."""
        k = min(int(self.conf.gain.interpolation_neighbours), len(pick))
        if k <= 1:
            nearest = cKDTree(world[pick]).query(world, k=1)[1]
            return sample_gain[nearest]
        distance, neighbour = cKDTree(world[pick]).query(world, k=k)
        weight = 1.0 / np.maximum(distance, 1e-9)
        gain = (weight * sample_gain[neighbour]).sum(axis=1) / weight.sum(axis=1)
        gain[pick] = sample_gain
        return gain
