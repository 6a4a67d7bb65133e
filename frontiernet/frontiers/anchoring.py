"""Anchoring: per-pixel network outputs -> 3D frontiers (docs/design.md item 4, paper III-E).

1. F = [D < l] and G = the decoded gain class (:func:`anchor_prediction`).
2. Per frontier pixel: the image direction towards the occluded side (down the depth
   gradient, onto the occluder: the hidden space lies behind it) and the frontier depth =
   mean of the foreground and background depths sampled across the edge (:mod:`.pixels`).
3. HDBSCAN over the features ``[w_pixel u/W, w_pixel v/H, w_dir cos, w_dir sin,
   w_depth depth, w_gain log1p(gain)]`` (zero-weight columns left out; public code:
   weights [10, 10, 1, 1, 0.3], no gain).
4. Each cluster becomes one :class:`FrontierObservation`: the member pixel nearest the
   cluster's mean pixel, back-projected at the members' robust median depth; a view
   direction from that pixel's ray and the mean occluded-side direction; the cluster's gain.

Conventions: world Z-up, metres; camera OpenCV (x right, y down, z forward);
``T_world_cam`` (4, 4) float64 maps camera to world coordinates.
"""

from __future__ import annotations

import types
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry import pinhole_intrinsics, rigid_pose
from .gain import decode_gain
from .pixels import FrontierPixels, frontier_pixel_cues
from .settings import AnchoringSettings

_DEPTH_PERCENTILES = (5.0, 90.0)   # cluster depth: median of the members in this band (public code)
_GAIN_PERCENTILES = (50.0, 90.0)   # "robust" cluster gain: median of this band (public code) ...
_ROBUST_GAIN_MIN_PIXELS = 10       # ... or the mean for smaller clusters (public code)


@dataclass
class FrontierObservation:
    """One 3D frontier seen in one frame (paper III-E).

    Attributes:
        position: (3,) float64 world metres, the frontier point (in the free space between
            the occluder and what it hides).
        direction: (3,) float64 unit world vector: where a camera placed at `position`
            should look to see the unexplored space.
        gain_m3: expected information gain, cubic metres.
        num_pixels: frontier pixels in the cluster (when only a subset was clustered,
            its member count scaled back to the whole image).
        pixel: (2,) float64 (u, v) pixel of the cluster's centre.
        T_world_cam: (4, 4) float64 pose of the camera that saw it.
    """

    position: np.ndarray
    direction: np.ndarray
    gain_m3: float
    num_pixels: int
    pixel: np.ndarray
    T_world_cam: np.ndarray


# -- input checks ---------------------------------------------------------------------------------

def _image(array, name: str, shape: tuple[int, int] | None = None) -> np.ndarray:
    array = np.asarray(array)
    if array.ndim != 2 or (shape is not None and array.shape != shape):
        wanted = f"{shape}" if shape is not None else "(H, W)"
        raise InputError(f"{name} must be a {wanted} image, got shape {array.shape}")
    return array


def _checked_inputs(frontier_mask, gain_m3, depth, K, T_world_cam):
    mask = _image(frontier_mask, "frontier_mask")
    if mask.dtype.kind not in "biu":
        raise InputError(f"frontier_mask must be a bool (or 0/1 integer) image, got dtype {mask.dtype}")
    mask = mask.astype(bool, copy=False)
    gain = _image(gain_m3, "gain_m3", mask.shape).astype(np.float32, copy=False)
    if not np.all(np.isfinite(gain)):
        raise InputError("gain_m3 must be finite everywhere (NaN or inf found)")
    depth = _image(depth, "depth", mask.shape).astype(np.float32, copy=False)
    return mask, gain, depth, pinhole_intrinsics(K, mask.shape), rigid_pose(T_world_cam)


# -- clustering -----------------------------------------------------------------------------------

def cluster_features(pixels: FrontierPixels, image_size: tuple[int, int], weights: dict) -> np.ndarray:
    """(N, F) float64 HDBSCAN features of the pixels; columns of zero weight are left out.

    Args:
        image_size: (H, W) pixels, normalising u and v to [0, 1].
        weights: weight per feature name: pixel, direction, depth, gain.
    """
    H, W = image_size
    side = pixels.occluded_side
    columns = {"pixel": (pixels.u / W, pixels.v / H), "direction": (side[:, 0], side[:, 1]),
               "depth": (pixels.depth,), "gain": (np.log1p(pixels.gain),)}
    used = [weights[name] * column for name, group in columns.items() if weights[name] > 0 for column in group]
    return np.stack(used, 1)


def cluster_labels(features: np.ndarray, settings: AnchoringSettings, fraction: float = 1.0) -> np.ndarray:
    """(N,) int HDBSCAN labels of the feature rows, -1 = noise.

    ``min_cluster_size`` and ``min_samples`` count frontier pixels of the whole image. When
    only a random `fraction` of them is clustered (``max_pixels``), both are scaled by it
    (at least 2 and 1): the k-th neighbour distance of the subset then matches that of all
    pixels and a cluster keeps its size in image pixels, so subsampling neither drops small
    frontiers nor changes what ``cluster_selection_epsilon`` merges.
    """
    min_cluster_size = max(2, round(settings.min_cluster_size * fraction))
    min_samples = max(1, round(settings.min_samples * fraction))
    if len(features) < max(min_cluster_size, min_samples):
        return np.full(len(features), -1, np.intp)
    clusterer = _hdbscan().HDBSCAN(min_cluster_size=min_cluster_size, min_samples=min_samples,
                                   cluster_selection_epsilon=settings.cluster_selection_epsilon,
                                   allow_single_cluster=settings.allow_single_cluster, metric="euclidean",
                                   core_dist_n_jobs=1)
    return clusterer.fit_predict(features)


class _NumpyWithStableArgsort(types.ModuleType):
    """numpy, but ``argsort`` is stable unless told otherwise (see :func:`_hdbscan`)."""

    def __getattr__(self, name):
        return getattr(np, name)

    @staticmethod
    def argsort(a, axis=-1, kind=None, order=None, **kwargs):
        return np.argsort(a, axis=axis, kind=kind or "stable", order=order, **kwargs)


def _hdbscan():
    """The hdbscan package, its minimum spanning tree's edges put in the same order on every CPU.

    hdbscan sorts the tree's edges by weight with numpy's default argsort, which is not stable,
    and mutual reachability makes equal weights common (an edge weighs the larger core distance
    of its two ends). numpy's sort kernels are chosen for the CPU (AVX-512 ones on some machines):
    they leave equal weights in different orders, the single-linkage tree is built in a different
    order, and some pixels change cluster (530 vs 528 of the first frame of procedural:2000 from
    its first development start). A run of an image method from the same start then drifted apart
    between machines (docs/benchmark.md, "Both depth regimes"). The module that sorts gets a numpy
    whose argsort is stable: equal weights keep the tree's own order, which does not depend on the
    CPU. Imported here, not at the top: training imports this package (gain classes) without hdbscan.
    """
    import hdbscan
    from hdbscan import hdbscan_

    if not isinstance(hdbscan_.np, _NumpyWithStableArgsort):
        hdbscan_.np = _NumpyWithStableArgsort("numpy")
    return hdbscan


# -- one cluster -> one frontier ------------------------------------------------------------------

def band_median(values: np.ndarray, lower_pct: float, upper_pct: float) -> float:
    """Median of the sorted values from the `lower_pct` to the `upper_pct` percentile (by rank)."""
    ordered = np.sort(np.asarray(values, np.float64))
    start = int(len(ordered) * lower_pct / 100.0)
    stop = max(int(np.ceil(len(ordered) * upper_pct / 100.0)), start + 1)
    return float(np.median(ordered[start:stop]))


def cluster_gain(gains: np.ndarray, mode: str) -> float:
    """Gain (m^3) of a cluster from its pixels' gains: robust (public code), mean or max."""
    if mode == "max":
        return float(np.max(gains))
    if mode == "robust" and len(gains) >= _ROBUST_GAIN_MIN_PIXELS:
        return band_median(gains, *_GAIN_PERCENTILES)
    return float(np.mean(gains))


def _unit(vector: np.ndarray) -> np.ndarray | None:
    norm = float(np.linalg.norm(vector))
    return vector / norm if norm > 1e-9 else None


def view_direction(ray_cam: np.ndarray, occluded_side: np.ndarray, R_world_cam: np.ndarray,
                   forward_weight: float, horizontal: bool) -> np.ndarray:
    """(3,) unit world view direction of a frontier.

    In the camera frame: normalise(forward_weight * unit pixel ray + (cos, sin, 0)), the
    lateral part being the unit mean occluded-side image direction (image u, v = camera
    x, y): a robot at the frontier looks past the occluding edge into the space behind the
    occluder. With `horizontal`, the world direction is levelled (z = 0); if that leaves
    nothing, the camera's levelled forward (or, looking straight down, its levelled up)
    axis is used.

    Args:
        ray_cam: (3,) camera-frame ray of the centre pixel; occluded_side: (2,) (du, dv).
        R_world_cam: (3, 3) camera-to-world rotation.
    """
    lateral = _unit(np.asarray(occluded_side, np.float64))
    lateral_cam = np.zeros(3) if lateral is None else np.array([lateral[0], lateral[1], 0.0])
    unit_ray = _unit(ray_cam)
    direction = _unit(forward_weight * unit_ray + lateral_cam)
    world = R_world_cam @ (unit_ray if direction is None else direction)
    if not horizontal:
        return world
    for candidate in (world, R_world_cam[:, 2], -R_world_cam[:, 1]):
        level = _unit(np.array([candidate[0], candidate[1], 0.0]))
        if level is not None:
            return level
    raise AssertionError("a rotation has no axis off the vertical")  # pragma: no cover


def frontier_from_cluster(pixels: FrontierPixels, K: np.ndarray, T_world_cam: np.ndarray,
                          settings: AnchoringSettings, fraction: float = 1.0) -> FrontierObservation:
    """One cluster's pixels -> a :class:`FrontierObservation` (paper III-E).

    Args:
        pixels: the cluster's members; K: (3, 3) intrinsics; T_world_cam: (4, 4) pose.
        fraction: the clustered fraction of all frontier pixels (scales ``num_pixels``).
    """
    centre_offset = (pixels.u - pixels.u.mean()) ** 2 + (pixels.v - pixels.v.mean()) ** 2
    centre = int(np.argmin(centre_offset))
    u, v = pixels.u[centre], pixels.v[centre]
    ray_cam = np.linalg.solve(K, np.array([u, v, 1.0]))  # z = 1: depth scales it to the point
    depth = band_median(pixels.depth, *_DEPTH_PERCENTILES)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    direction = view_direction(ray_cam, pixels.occluded_side.mean(0), R, settings.forward_weight,
                               settings.horizontal_directions)
    return FrontierObservation(position=R @ (depth * ray_cam) + t, direction=direction,
                               gain_m3=cluster_gain(pixels.gain, settings.cluster_gain),
                               num_pixels=round(len(pixels) / fraction), pixel=np.array([u, v]),
                               T_world_cam=T_world_cam.copy())


# -- public entry points ----------------------------------------------------------------------------

def anchor_frontiers(frontier_mask: np.ndarray, gain_m3: np.ndarray, depth: np.ndarray, K: np.ndarray,
                     T_world_cam: np.ndarray, conf, rng: np.random.Generator | None = None
                     ) -> list[FrontierObservation]:
    """Cluster frontier pixels into 3D frontiers (paper III-E).

    Args:
        frontier_mask: (H, W) bool, F.
        gain_m3: (H, W) float32 cubic metres per pixel, G.
        depth: (H, W) float32 z-depth in metres (NaN, inf or <= 0 where invalid).
        K: (3, 3) float64 intrinsics of this image size.
        T_world_cam: (4, 4) float64 camera-to-world pose.
        conf: the ``anchoring`` section of ``configs/explore.yaml`` (or :class:`AnchoringSettings`).
        rng: picks the clustered subset when there are more than ``max_pixels`` frontier
            pixels (None: a fixed seed, so results repeat).
    Returns:
        One :class:`FrontierObservation` per HDBSCAN cluster, largest cluster first; [] when
        there are too few usable frontier pixels.
    """
    settings = AnchoringSettings.from_config(conf)
    mask, gain, depth, K, T = _checked_inputs(frontier_mask, gain_m3, depth, K, T_world_cam)
    pixels = frontier_pixel_cues(mask, gain, depth, settings)
    total = len(pixels)
    if total < max(settings.min_cluster_size, settings.min_samples):
        return []
    if total > settings.max_pixels:
        rng = np.random.default_rng(0) if rng is None else rng
        pixels = pixels.subset(np.sort(rng.choice(total, settings.max_pixels, replace=False)))
    features = cluster_features(pixels, mask.shape, settings.feature_weights)
    fraction = len(pixels) / total
    labels = cluster_labels(features, settings, fraction)
    clusters = [np.flatnonzero(labels == label) for label in np.unique(labels[labels >= 0])]
    clusters.sort(key=len, reverse=True)
    return [frontier_from_cluster(pixels.subset(members), K, T, settings, fraction) for members in clusters]


def anchor_prediction(distance_field: np.ndarray, gain_class: np.ndarray, depth: np.ndarray, K: np.ndarray,
                      T_world_cam: np.ndarray, conf, labels: dict, rng: np.random.Generator | None = None,
                      gain_logits: np.ndarray | None = None) -> list[FrontierObservation]:
    """3D frontiers from the network's outputs, or from ground-truth labels (paper III-E).

    F = [D < l] with l = ``conf.frontier_threshold_px`` (or ``labels["frontier_threshold_px"]``
    when that is null); G = the gain classes decoded with the labels' bin edges and
    ``conf.gain_decoding`` (:func:`~.gain.decode_gain`; ``expected`` reads `gain_logits` on F);
    then :func:`anchor_frontiers`.

    Args:
        distance_field: (H, W) float32 pixels, distance to the nearest frontier pixel.
        gain_class: (H, W) integer gain classes in [0, K - 1].
        gain_logits: (K, H, W) float32 gain-class logits of the network (None for labels).
        depth, K, T_world_cam, conf, rng: as for :func:`anchor_frontiers`.
        labels: the model's label encoding (``bin_edges``, ``bin_unit_m3``,
            ``frontier_threshold_px``; ``configs/model.yaml`` ``labels:``).
    """
    settings = AnchoringSettings.from_config(conf)
    distance = _image(distance_field, "distance_field").astype(np.float32, copy=False)
    classes = _image(gain_class, "gain_class", distance.shape)
    threshold = settings.frontier_threshold_px
    if threshold is None:
        threshold = labels.get("frontier_threshold_px") if hasattr(labels, "get") else None
        if threshold is None:
            raise InputError("anchoring.frontier_threshold_px is null and the model labels have no "
                             "frontier_threshold_px")
    try:
        edges, unit = labels["bin_edges"], float(labels["bin_unit_m3"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"labels must give bin_edges and bin_unit_m3, got {labels!r}") from None
    frontier_mask = distance < float(threshold)
    gain = decode_gain(classes, list(edges), unit, settings.gain_decoding, gain_logits, frontier_mask)
    return anchor_frontiers(frontier_mask, gain, depth, K, T_world_cam, settings, rng)
