"""Contact sheets of generated training samples, to eyeball the labels.

One sheet per sample: a title line (scene, view index, largest gain), one row of seven
labelled tiles and a legend of the gain classes:

======  ==============================================================================
RGB     the rendered image
depth   turbo colour map up to ``max_depth`` metres, invalid black
F_p     projected frontier voxels (cyan) on the dimmed image
F_d     depth discontinuities (yellow) on the dimmed image
F       the frontier mask (magenta, :data:`FRONTIER_COLOUR`) on the dimmed image
D       the distance field, inferno colour map, bright at 0 and black at ``truncation_px``
gain    gain classes in :data:`GAIN_PALETTE` on the dimmed image (class 0 left dimmed)
======  ==============================================================================
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from frontiernet.errors import InputError
from frontiernet.io import check_not_dangling, colorize_depth, ensure_dir, remove_if_empty, write_image
from frontiernet.simulator.preview import contact_sheet

FRONTIER_COLOUR = (255, 0, 255)  # F tile
PROJECTED_COLOUR = (0, 255, 255)  # F_p tile
DISCONTINUITY_COLOUR = (255, 255, 0)  # F_d tile
DIM = 0.4  # RGB brightness under overlays
# One RGB colour per gain class (K = 11, datagen.yaml ground_truth.gain.bin_edges): 0 = no gain
# black, then blue to red with growing gain; magenta and white for the two largest classes.
GAIN_PALETTE = np.array([
    (0, 0, 0), (70, 107, 227), (41, 187, 236), (49, 241, 153), (163, 253, 61), (237, 208, 58),
    (254, 154, 45), (240, 90, 26), (200, 41, 4), (230, 30, 140), (255, 255, 255),
], np.uint8)

_BOOL_KEYS = ("frontier_projected", "discontinuity", "frontier_mask")
_IMAGE_KEYS = ("depth", *_BOOL_KEYS, "distance_field", "gain", "gain_class")


def _text(image: np.ndarray, text: str, origin: tuple[int, int], scale: float = 0.5) -> None:
    import cv2

    cv2.putText(image, text, origin, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)


def _checked(sample: dict) -> dict:
    """The sample's arrays as numpy, with shapes checked against rgb (H, W, 3)."""
    missing = [k for k in ("rgb", *_IMAGE_KEYS) if k not in sample]
    if missing:
        raise InputError(f"preview sample lacks {', '.join(missing)} (has {', '.join(map(str, sample))})")
    out = {k: np.asarray(sample[k]) for k in ("rgb", *_IMAGE_KEYS)}
    rgb = out["rgb"]
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"preview sample rgb must be (H, W, 3), got shape {rgb.shape}")
    out["rgb"] = rgb.astype(np.uint8)
    for key in _IMAGE_KEYS:
        if out[key].shape != rgb.shape[:2]:
            raise InputError(f"preview sample {key} must be {rgb.shape[:2]} like rgb, got shape {out[key].shape}")
    return out


def _overlay(dimmed: np.ndarray, mask: np.ndarray, colour) -> np.ndarray:
    tile = dimmed.copy()
    tile[mask.astype(bool)] = colour
    return tile


def distance_tile(distance_px: np.ndarray, truncation_px: float) -> np.ndarray:
    """(H, W) float pixels -> (H, W, 3) uint8 inferno colours, bright at 0, black at `truncation_px`."""
    import cv2

    d = np.nan_to_num(np.asarray(distance_px, np.float64), nan=truncation_px)
    scaled = ((1.0 - np.clip(d / truncation_px, 0.0, 1.0)) * 255).astype(np.uint8)
    return cv2.applyColorMap(scaled, cv2.COLORMAP_INFERNO)[..., ::-1].copy()


def gain_tile(dimmed: np.ndarray, gain_class: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 dimmed image with classes > 0 painted in :data:`GAIN_PALETTE` (larger clipped)."""
    classes = np.clip(np.asarray(gain_class, np.int64), 0, len(GAIN_PALETTE) - 1)
    tile = dimmed.copy()
    tile[classes > 0] = GAIN_PALETTE[classes[classes > 0]]
    return tile


def _legend(width: int) -> np.ndarray:
    """(24, width, 3) uint8 white strip: 'gain class' and a numbered swatch per class."""
    strip = np.full((24, width, 3), 255, np.uint8)
    _text(strip, "gain class", (6, 17), 0.45)
    x = 100
    for k, colour in enumerate(GAIN_PALETTE):
        if x + 40 > width:
            break
        strip[5:19, x:x + 14] = colour
        strip[5:19, x:x + 14][[0, -1]] = 0  # outline, so white and black show
        strip[5:19, x:x + 14][:, [0, -1]] = 0
        _text(strip, str(k), (x + 17, 17), 0.4)
        x += 40
    return strip


def sample_contact_sheet(sample: dict, max_depth: float = 3.5, truncation_px: float = 10.0) -> np.ndarray:
    """One labelled contact sheet of a generated sample (see module docstring).

    Args:
        sample: dict with ``rgb`` (H, W, 3) uint8; ``depth`` (H, W) float32 metres, NaN
            invalid; ``frontier_projected``, ``discontinuity``, ``frontier_mask`` (H, W)
            bool; ``distance_field`` (H, W) float32 pixels; ``gain`` (H, W) float32 m^3;
            ``gain_class`` (H, W) int64; optional ``scene`` str and ``index`` int.
        max_depth: metres at the far end of the depth colour map.
        truncation_px: distance field value drawn black (the truncation r).
    Returns:
        (H', W', 3) uint8 RGB image, W' = 7 * (W + 10).
    Raises:
        InputError: a missing key or an array whose shape does not match ``rgb``.
    """
    s = _checked(sample)
    dimmed = (s["rgb"].astype(np.float32) * DIM).astype(np.uint8)
    gain = np.asarray(s["gain"], np.float64)
    max_gain = float(np.nanmax(gain)) if np.isfinite(gain).any() else 0.0
    tiles = [
        s["rgb"],
        colorize_depth(np.asarray(s["depth"], np.float32), max_depth),
        _overlay(dimmed, s["frontier_projected"], PROJECTED_COLOUR),
        _overlay(dimmed, s["discontinuity"], DISCONTINUITY_COLOUR),
        _overlay(dimmed, s["frontier_mask"], FRONTIER_COLOUR),
        distance_tile(s["distance_field"], truncation_px),
        gain_tile(dimmed, s["gain_class"]),
    ]
    labels = ["RGB", "depth", "F_p", "F_d", "F", "D", f"gain (max {max_gain:.2f} m^3)"]
    row = contact_sheet(tiles, columns=len(tiles), labels=labels)
    title = np.full((26, row.shape[1], 3), 255, np.uint8)
    _text(title, f"{sample.get('scene', '?')}  view {sample.get('index', '?')}  "
                 f"F {int(np.count_nonzero(s['frontier_mask']))} px  max gain {max_gain:.2f} m^3", (6, 18), 0.5)
    return np.concatenate([title, row, _legend(row.shape[1])], axis=0)


def preview_indices(length: int, n: int, seed: int = 0) -> np.ndarray:
    """(min(n, length),) int64 sorted distinct indices spread evenly over ``range(length)``.

    One index per equal stretch of the dataset, all at the same seeded offset within
    their stretch (deterministic per `seed`).
    """
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 0:
        raise InputError(f"number of previews must be an integer >= 0, got {n!r}")
    if n >= length:
        return np.arange(length, dtype=np.int64)
    phase = np.random.default_rng(seed).random()
    return np.floor((np.arange(n) + phase) * (length / n)).astype(np.int64)


def write_previews(dataset, out_dir: str | Path, n: int = 16, seed: int = 0, *, max_depth: float = 3.5,
                   truncation_px: float = 10.0) -> list[Path]:
    """Write contact sheets of `n` samples spread evenly over `dataset`.

    Args:
        dataset: anything with ``len()`` and ``[i]`` giving sample dicts (see
            :func:`sample_contact_sheet`).
        out_dir: folder, created if needed (once the first sample is read); sheet of dataset item ``i`` goes
            to ``preview_<i>.png`` (``i`` zero-padded to the width of the largest index). A run that fails (a
            corrupt shard) removes the sheets it added and the folders it made: no empty or partial preview.
        n: number of sheets (all samples when the dataset is smaller).
        seed: picks the offset of the evenly spaced indices.
        max_depth, truncation_px: as in :func:`sample_contact_sheet`.
    Returns:
        The written paths, in dataset order.
    """
    out_dir = Path(out_dir)
    check_not_dangling(out_dir)  # (was "cannot create output folder (File exists)", after a sample was read)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir}: output path exists and is not a folder")
    length = len(dataset)
    width = len(str(max(length - 1, 0)))
    made = next((folder for folder in reversed((out_dir, *out_dir.parents)) if not folder.exists()), None)
    paths, written = [], []
    try:
        for i in preview_indices(length, n, seed):
            sheet = sample_contact_sheet(dataset[int(i)], max_depth, truncation_px)  # (read before the folder is made)
            path = ensure_dir(out_dir) / f"preview_{int(i):0{width}d}.png"
            new = not path.exists()
            paths.append(write_image(path, sheet))
            if new:
                written.append(path)
    except BaseException:  # a sample that cannot be read (a corrupt shard), Ctrl-C: no partial preview is left
        for path in written:
            path.unlink(missing_ok=True)
        if made is not None:
            remove_if_empty(made)
        raise
    return paths
