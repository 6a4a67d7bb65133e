"""How consistent are the gain labels? (``frontiernet datagen consistency``)

No model can agree with a label better than the label agrees with itself. Two checks, on views
drawn the way ``frontiernet datagen`` draws them (same sampler, same frontier/no-frontier balance):

- **resampled**: the same view labelled twice with different random generators. The image, F and
  D are the same; the gain is not, because it is measured at a random ~10 % of the frontier voxels
  (``ground_truth.gain.sample_fraction``) and blended to the rest.
- **consensus**: the per-pixel majority class of ``consistency.resampled_labelings`` further
  labelings of the view against the original one. Two noisy labelings agree less often than the
  best possible predictor (the per-pixel most likely class) agrees with one of them, so
  ``resampled`` understates the ceiling; the majority of several labelings estimates that
  predictor, and approaches the ceiling as their number grows.
- **nearby**: the view and a second one a small step away (``consistency.translation_m`` in a
  random horizontal direction, ``consistency.rotation_deg`` of yaw), labelled independently; the
  second view's labels are carried into the first view's pixels through the first view's depth
  (nearest pixel), where the second view sees the same surface point.

Both compare the two labelings with the scores of ``frontiernet evaluate``
(:mod:`frontiernet.frontiers.gain`): confusion matrices over all compared pixels, the labelled
band D < r and the frontier pixels F of the first view; hard Dice per class, the
paper-comparable gain Dice (all pixels, K classes with class 0, macro mean over the classes
present), how often the class is one off, and (nearby only) the distance-field disagreement in
pixels. Figures are at the dataset's resolution (480 px by default).
"""

from __future__ import annotations

import math

import numpy as np

from frontiernet.errors import InputError, positive_number, whole_number
from frontiernet.frontiers.gain import class_confusion, class_offsets, dice_per_class, mean_dice

KINDS = ("resampled", "consensus", "nearby")
REGIONS = ("all", "band", "frontier")


def load_consistency_config(user_file=None, overrides=()):
    """sim.yaml + datagen.yaml + label_consistency.yaml, scenes.yaml as section ``scenes``, then a user
    file and ``key=value`` overrides (:func:`~datagen.config.load_datagen_config`)."""
    from .config import load_datagen_config

    return load_datagen_config(user_file, overrides, ("sim", "datagen", "label_consistency"))


def nearby_pose(T_world_cam: np.ndarray, translation_m: float, yaw_rad: float, direction_rad: float) -> np.ndarray:
    """(4, 4) float64: the camera moved `translation_m` horizontally along world heading
    `direction_rad` and turned by `yaw_rad` about the world z axis (Z-up) at its centre."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    T = np.array(T_world_cam, np.float64, copy=True)
    T[:3, :3] = turn @ T[:3, :3]
    T[:3, 3] += translation_m * np.array([math.cos(direction_rad), math.sin(direction_rad), 0.0])
    return T


def warp_to_view(depth_a: np.ndarray, K_a: np.ndarray, T_a: np.ndarray, depth_b: np.ndarray, K_b: np.ndarray,
                 T_b: np.ndarray, max_depth_m: float, tolerance: float = 0.05,
                 tolerance_m: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each pixel of view A lands in view B, and whether B sees the same point.

    Args:
        depth_a, depth_b: (H, W) float32 z-depth in metres, NaN invalid (no hit within range).
            A's invalid pixels are taken at `max_depth_m` along their ray and count as seen when
            B's pixel is invalid too or at least that deep.
        K_a, K_b: (3, 3) intrinsics; T_a, T_b: (4, 4) ``T_world_cam`` (OpenCV camera frames).
        tolerance, tolerance_m: B sees A's point when their depths in B agree within
            ``max(tolerance * depth, tolerance_m)``.
    Returns:
        rows, cols: (H, W) int64 pixel of B nearest to each A pixel's point (clipped into the image);
        seen: (H, W) bool, inside B's image, in front of it, and not hidden in B.
    """
    H, W = depth_a.shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    far = ~np.isfinite(depth_a)
    z = np.where(far, float(max_depth_m), depth_a).astype(np.float64)
    camera_a = np.stack([(u - K_a[0, 2]) / K_a[0, 0] * z, (v - K_a[1, 2]) / K_a[1, 1] * z, z], -1)
    world = camera_a @ np.asarray(T_a)[:3, :3].T + np.asarray(T_a)[:3, 3]
    camera_b = (world - np.asarray(T_b)[:3, 3]) @ np.asarray(T_b)[:3, :3]
    z_b = camera_b[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        col = np.rint(K_b[0, 0] * camera_b[..., 0] / z_b + K_b[0, 2])
        row = np.rint(K_b[1, 1] * camera_b[..., 1] / z_b + K_b[1, 2])
    Hb, Wb = depth_b.shape
    inside = (z_b > 1e-6) & (col >= 0) & (col < Wb) & (row >= 0) & (row < Hb)
    rows = np.clip(np.nan_to_num(row), 0, Hb - 1).astype(np.int64)
    cols = np.clip(np.nan_to_num(col), 0, Wb - 1).astype(np.int64)
    there = depth_b[rows, cols].astype(np.float64)
    valid_there = np.isfinite(there)
    slack = np.maximum(tolerance * z_b, tolerance_m)
    same_point = valid_there & (np.abs(there - z_b) <= slack)
    beyond = ~valid_there | (there >= z_b - slack)
    seen = inside & np.where(far, beyond, same_point)
    return rows, cols, seen


def majority_class(classes: np.ndarray, num_classes: int) -> np.ndarray:
    """(H, W) int64 per-pixel most frequent class of (N, H, W) integer class maps (ties: the lower class)."""
    counts = np.stack([(classes == k).sum(0) for k in range(int(num_classes))])
    return counts.argmax(0)


class Agreement:
    """Confusion matrices (rows: the first labeling, columns: the second) over all compared
    pixels, the first labeling's band D < r and its frontier pixels F, plus the distance-field
    disagreement and counts."""

    def __init__(self, num_classes: int):
        self.num_classes = int(num_classes)
        self.confusion = {region: np.zeros((num_classes, num_classes), np.int64) for region in REGIONS}
        self.distance_error_sum = 0.0
        self.pixels = 0
        self.pairs = 0

    def add(self, first, second_class: np.ndarray, second_distance: np.ndarray, compared: np.ndarray,
            truncation_px: float) -> None:
        """`first`: a GroundTruth; `second_*`: (H, W) maps in the first view's pixels; `compared`: bool."""
        K = self.num_classes
        masks = {"all": compared, "band": compared & (first.distance_field < truncation_px),
                 "frontier": compared & first.frontier_mask}
        for region, mask in masks.items():
            self.confusion[region] += class_confusion(second_class, first.gain_class, K, mask)
        self.distance_error_sum += float(np.abs(second_distance - first.distance_field)[compared].sum())
        self.pixels += int(compared.sum())
        self.pairs += 1

    def summary(self) -> dict:
        band, at_frontier = class_offsets(self.confusion["band"]), class_offsets(self.confusion["frontier"])
        return {"pairs": self.pairs, "pixels": self.pixels,
                "gain_dice_with_class_0": mean_dice(self.confusion["all"], include_class_0=True),
                "gain_dice": mean_dice(self.confusion["all"], include_class_0=False),
                "gain_dice_frontier": mean_dice(self.confusion["frontier"], include_class_0=True),
                "gain_dice_per_class": [float(v) for v in dice_per_class(self.confusion["all"])],
                "gain_band_exact": band["exact"], "gain_band_one_off": band["one_off"],
                "gain_band_further": band["further"], "gain_band_mean_abs_offset": band["mean_abs_offset"],
                "gain_frontier_exact": at_frontier["exact"], "gain_frontier_one_off": at_frontier["one_off"],
                "df_error_px": self.distance_error_sum / self.pixels if self.pixels else float("nan"),
                "gain_confusion": {region: matrix.tolist() for region, matrix in self.confusion.items()}}


def _settings(conf) -> dict:
    section = conf.consistency
    settings = {key: positive_number(section[key], f"consistency.{key}", allow_zero=True)
                for key in ("translation_m", "rotation_deg", "depth_tolerance", "depth_tolerance_m")}
    for key in ("max_tries", "resampled_labelings"):
        value = section[key]
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise InputError(f"consistency.{key} must be a positive integer, got {value!r}")
        settings[key] = value
    return settings


def _nearby_view(generator, T: np.ndarray, settings: dict, min_clearance_m: float, rng: np.random.Generator):
    """A pose near `T` that is explorable and clear of the mesh, or None after ``max_tries``."""
    from frontiernet.simulator.raycast import distance_to_surface

    for _ in range(settings["max_tries"]):
        yaw = math.radians(settings["rotation_deg"]) * rng.choice([-1.0, 1.0])
        candidate = nearby_pose(T, settings["translation_m"], yaw, rng.uniform(-math.pi, math.pi))
        centre = candidate[None, :3, 3]
        if generator.voxels.is_explorable(centre)[0] and distance_to_surface(generator.scene, centre)[0] >= min_clearance_m:
            return candidate
    return None


def scene_consistency(spec: str, views: int, conf, seed: int = 0, on_view=None) -> dict:
    """Both checks on `views` views of one scene; returns ``{kind: Agreement}`` and the skipped count.

    Args:
        spec: scene spec; views: views to draw (datagen's sampler and balance); conf: the merged
            config (:func:`load_consistency_config`); seed: run seed (same seed, same figures).
        on_view: optional callable(), called after each view's checks (progress).
    """
    from .backends import _scene_state
    from .generate import shard_seed
    from .views_balance import shard_views

    settings = _settings(conf)
    scene, voxels, generator = _scene_state(spec, conf)
    rng = np.random.default_rng(shard_seed(seed, spec, 0))
    drawn, _ = shard_views(generator, views, rng, conf)
    K = len(conf.ground_truth.gain.bin_edges)
    truncation = float(conf.ground_truth.truncation_px)
    max_depth = float(generator.camera.max_depth)
    agreement = {kind: Agreement(K) for kind in KINDS}
    skipped = 0
    for truth, _kind in drawn:
        # the same pose, the gain sampled afresh: one labeling, then the majority of all of them
        again = [generator(truth.T_world_cam, rng) for _ in range(settings["resampled_labelings"])]
        everywhere = np.ones(truth.gain_class.shape, bool)
        agreement["resampled"].add(truth, again[0].gain_class, again[0].distance_field, everywhere, truncation)
        majority = majority_class(np.stack([labels.gain_class for labels in again]), K)
        agreement["consensus"].add(truth, majority, again[0].distance_field, everywhere, truncation)
        T_near = _nearby_view(generator, truth.T_world_cam, settings, float(conf.poses.min_clearance_m), rng)
        if T_near is None:
            skipped += 1
        else:
            near = generator(T_near, rng)
            rows, cols, seen = warp_to_view(truth.depth, truth.K, truth.T_world_cam, near.depth, near.K, T_near,
                                            max_depth, settings["depth_tolerance"], settings["depth_tolerance_m"])
            agreement["nearby"].add(truth, near.gain_class[rows, cols], near.distance_field[rows, cols], seen,
                                    truncation)
        if on_view is not None:
            on_view()
    return {"agreement": agreement, "skipped_nearby": skipped}


def label_consistency(specs: list[str], views_per_scene: int, conf, seed: int = 0, progress=None) -> dict:
    """Both checks over several scenes: per scene and pooled (confusions summed over scenes).

    Returns ``{"scenes": {spec: {kind: summary}}, "total": {kind: summary}, "settings": ...}``;
    each summary as :meth:`Agreement.summary`. `progress(done, total)` is called after each view.
    """
    from frontiernet.scenes.spec import expand_specs
    from frontiernet.errors import check_seed

    from .generate import MAX_VIEWS

    whole_number(views_per_scene, "--views-per-scene", 1, MAX_VIEWS)
    check_seed(seed, "--seed")  # (-1 labelled with a seed of its own hash)
    settings = _settings(conf)
    specs = expand_specs(specs)
    if not specs:
        raise InputError("no scenes given (--scenes SPEC ...)")
    K = len(conf.ground_truth.gain.bin_edges)
    total = {kind: Agreement(K) for kind in KINDS}
    per_scene, done = {}, 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, views_per_scene * len(specs))

    for spec in specs:
        result = scene_consistency(spec, views_per_scene, conf, seed, on_view=tick)
        per_scene[spec] = {kind: result["agreement"][kind].summary() for kind in KINDS}
        per_scene[spec]["skipped_nearby"] = result["skipped_nearby"]
        for kind in KINDS:
            part = result["agreement"][kind]
            for region in REGIONS:
                total[kind].confusion[region] += part.confusion[region]
            total[kind].distance_error_sum += part.distance_error_sum
            total[kind].pixels += part.pixels
            total[kind].pairs += part.pairs
    return {"scenes": per_scene, "total": {kind: total[kind].summary() for kind in KINDS},
            "settings": {**settings, "views_per_scene": views_per_scene, "seed": seed,
                         "sample_fraction": float(conf.ground_truth.gain.sample_fraction)}}


def format_consistency(result: dict) -> str:
    """The figures as a short text table: one row per scene and check, then the pooled rows."""
    s = result["settings"]
    rows = [f"label consistency: {s['views_per_scene']} views per scene, nearby = {s['translation_m']:g} m and "
            f"{s['rotation_deg']:g} deg away, gain measured at {100 * s['sample_fraction']:g} % of frontier voxels",
            f"{'scene':<44} {'check':<10} {'pairs':>5} {'Dice':>6} {'fg':>6} {'at F':>6} {'exact':>6} "
            f"{'1 off':>6} {'DF px':>6}",
            "  (Dice: paper-comparable, all pixels, K classes with class 0; fg: classes 1-10; at F: at the first "
            "view's frontier pixels; exact / 1 off: gain class in the band D < r)"]

    def row(name: str, kind: str, summary: dict) -> str:
        if not summary["pairs"]:  # (its figures would be 0 / 0)
            return (f"{name[-44:]:<44} {kind:<10} {0:>5}  no pair: no {kind} view was found (a nearby one clear of the "
                    f"mesh within consistency.max_tries tries, {s['translation_m']:g} m away)")
        return (f"{name[-44:]:<44} {kind:<10} {summary['pairs']:>5} {summary['gain_dice_with_class_0']:>6.3f} "
                f"{summary['gain_dice']:>6.3f} {summary['gain_dice_frontier']:>6.3f} {summary['gain_band_exact']:>6.3f} "
                f"{summary['gain_band_one_off']:>6.3f} {summary['df_error_px']:>6.3f}")

    for spec, kinds in result["scenes"].items():
        rows += [row(spec, kind, kinds[kind]) for kind in KINDS]
    rows += [row("all scenes", kind, result["total"][kind]) for kind in KINDS]
    return "\n".join(rows)
