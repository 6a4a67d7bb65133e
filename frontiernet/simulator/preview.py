"""Quick looks at scenes: orthographic cut-away top views and contact sheets.

Used to eyeball generated and loaded scenes (``docs/images/procedural_contact_sheet.png``).
"""

from __future__ import annotations

import numpy as np

from ..scenes.scene import Scene


def material_colors(scene: Scene) -> np.ndarray:
    """(M, 3) float32 RGB 0-255 per material: the texture's mean colour, else `color`."""
    return np.array([m.texture.reshape(-1, 3).mean(0) if m.texture is not None else m.color
                     for m in scene.materials], np.float32).reshape(-1, 3)


MIN_TOPDOWN_PIXELS = 8
"""The fewest pixels a top view has across: fewer show nothing of the scene (and its outlines need 3)."""
MAX_TOPDOWN_PIXELS = 25_000_000
"""Largest top view drawn (5000 x 5000 px): its two casts of 24-byte rays per pixel hold 1.2 GB, more with their hits."""


def check_view_settings(pixel_size: float, cut_height: float) -> None:
    """InputError for a pixel size or cut height (of :func:`topdown_image`) that is not a positive number."""
    from ..errors import positive_number

    positive_number(pixel_size, "the pixel size (--pixel-size)", "metres")
    positive_number(cut_height, "the cut height (--cut-height)", "metres above the floor")


def check_view_size(scene: Scene, pixel_size: float) -> None:
    """InputError when a top view of `scene` at `pixel_size` metres per pixel (a positive number) would have more
    than :data:`MAX_TOPDOWN_PIXELS`, naming the size it would have (3 digits: a pixel size of 1e-300 gave a
    600-digit count; 1e-320, below the smallest normal float, overflowed to an infinite width) and the smallest
    pixel size the scene takes."""
    from ..errors import InputError

    extent = np.maximum(scene.bounds[1, :2] - scene.bounds[0, :2], 0.0).astype(np.float64)
    if not extent.min() > 0:  # (a flat mesh: no pixel size gives it MIN_TOPDOWN_PIXELS across)
        raise InputError(f"{scene.name} is {extent[0]:.3g} x {extent[1]:.3g} m across: a top view of it has no "
                         "width at any pixel size")
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        across = np.ceil(extent / pixel_size)  # (x, y) pixels, inf where they overflow
        digits = np.log10(extent) - np.log10(pixel_size)  # their decimal logarithms, finite where they overflow
        if np.isfinite(across).all() and across.prod() <= MAX_TOPDOWN_PIXELS:
            return
    smallest = float(np.sqrt(extent.prod() / MAX_TOPDOWN_PIXELS))
    while np.ceil(extent / smallest).prod() > MAX_TOPDOWN_PIXELS:  # (ceil: a few steps up at most)
        smallest *= 1.001
    size = " x ".join(f"{n:,.0f}" if n < 1e9 else _power_of_ten(d) for n, d in zip(across, digits))
    side = int(np.sqrt(MAX_TOPDOWN_PIXELS))
    raise InputError(f"a top view of {scene.name} ({extent[0]:.3g} x {extent[1]:.3g} m) at {pixel_size:.3g} m per "
                     f"pixel (--pixel-size) would be {size} px, more than the {MAX_TOPDOWN_PIXELS:,} drawn at most "
                     f"({side:,} x {side:,}); give a larger pixel size, at least {_round_up(smallest)} m")


def _power_of_ten(digits: float) -> str:
    """``10 ** digits`` to 3 significant digits, also past the largest float (``1.92e+321``)."""
    exponent = int(np.floor(digits))
    mantissa = 10.0 ** (digits - exponent)
    if round(mantissa, 2) >= 10.0:
        mantissa, exponent = mantissa / 10.0, exponent + 1
    return f"{mantissa:.3g}e+{exponent}"


def _round_up(value: float) -> str:
    """`value` > 0 to 3 significant digits, rounded up (a smallest pixel size that is no smaller)."""
    digits = 2 - int(np.floor(np.log10(value)))
    return f"{np.ceil(value * 10.0 ** digits) / 10.0 ** digits:.{max(digits, 0)}f}"


def topdown_image(scene: Scene, pixel_size: float = 0.05, cut_height: float = 1.8) -> np.ndarray:
    """Orthographic top view of `scene` cut at ``bounds_min_z + cut_height`` metres.

    One ray per pixel is cast straight down from the cut plane (so ceilings and upper
    floors are not in the way); hits are coloured by material colour, brighter the
    higher the hit and the more the surface faces up. Pixels whose downward ray starts
    inside a solid (a wall cut by the plane, seen by an upward ray hitting its top from
    inside) are drawn dark grey, as walls in a plan drawing; nothing hit is black.

    Args:
        scene: any :class:`Scene` (Z-up, metres).
        pixel_size: metres per image pixel.
        cut_height: metres above the scene's lowest point.
    Returns:
        (H, W, 3) uint8 image; row 0 is the scene's largest y (north up), column 0 its smallest x.
    Raises:
        InputError: a pixel size or cut height that is not a positive number, a cut height at or
            above the scene's top, or an image of more
            than :data:`MAX_TOPDOWN_PIXELS` or fewer than :data:`MIN_TOPDOWN_PIXELS` across.
    """
    from ..errors import InputError
    from .raycast import INVALID_ID, cast_rays

    check_view_settings(pixel_size, cut_height)
    lo, hi = scene.bounds
    check_view_size(scene, pixel_size)
    width, height = (int(np.ceil((hi[axis] - lo[axis]) / pixel_size)) for axis in (0, 1))
    if min(width, height) < MIN_TOPDOWN_PIXELS:
        raise InputError(f"a top view of {scene.name} at {pixel_size:g} m per pixel would be {width} x {height} px, "
                         f"fewer than {MIN_TOPDOWN_PIXELS} across; give a smaller pixel size (--pixel-size, at most "
                         f"{min(hi[:2] - lo[:2]) / MIN_TOPDOWN_PIXELS:.3g} m here)")
    if cut_height >= hi[2] - lo[2]:  # the plane above everything: a view of the roof, nothing cut
        raise InputError(f"the cut height (--cut-height) {cut_height:g} m lies above {scene.name}, which is "
                         f"{hi[2] - lo[2]:.2f} m high; give a height inside it (1.8 m cuts a storey's walls)")
    cut = lo[2] + cut_height
    xs = np.arange(lo[0] + pixel_size / 2, hi[0], pixel_size)
    ys = np.arange(hi[1] - pixel_size / 2, lo[1], -pixel_size)
    X, Y = np.meshgrid(xs, ys)
    origins = np.stack([X, Y, np.full_like(X, cut)], -1)
    down = np.concatenate([origins, np.broadcast_to([0.0, 0.0, -1.0], origins.shape)], -1).astype(np.float32)
    hit = cast_rays(scene, down)
    up = cast_rays(scene, np.concatenate([origins, np.broadcast_to([0.0, 0.0, 1.0], origins.shape)], -1)
                   .astype(np.float32))
    colors = material_colors(scene)
    prim = hit["primitive_ids"]
    found = prim != INVALID_ID
    image = np.zeros(X.shape + (3,), np.float32)
    material = scene.triangle_material[np.where(found, prim, 0)]
    z = cut - hit["t_hit"]
    height = np.clip((z - lo[2]) / max(cut_height, 1e-6), 0.0, 1.0)
    facing = np.abs(hit["primitive_normals"][..., 2])
    shade = (0.75 + 0.35 * height) * (0.8 + 0.2 * facing)
    image[found] = colors[material[found]] * shade[found, None]
    # a wall cut by the plane: the ray down starts inside it, the ray up meets its top from below
    up_prim = up["primitive_ids"]
    inside = (up_prim != INVALID_ID) & (up["t_hit"] < max(hi[2] - cut, 0) + 1) & \
        (np.abs(up["primitive_normals"][..., 2]) > 0.5)
    up_material = scene.triangle_material[np.where(inside, up_prim, 0)]
    wall = inside & (~found | (hit["t_hit"] > 0.0)) & _solid_above(scene, up, inside, up_material)
    image[wall] = 0.2 * colors[up_material[wall]] + 10.0
    return np.clip(image, 0, 255).astype(np.uint8)


def overlay_columns(image: np.ndarray, scene: Scene, pixel_size: float, columns: np.ndarray, origin: np.ndarray,
                    cell_size: float, color=(40, 220, 90), seed: np.ndarray | None = None) -> np.ndarray:
    """Tint the pixels of a :func:`topdown_image` over the marked cells of a plan grid, outline them.

    Args:
        image: (H, W, 3) uint8 top view of `scene` at `pixel_size` metres per pixel.
        columns: (X, Y) bool cells (e.g. voxel columns holding explorable voxels); cell ``(i, j)``
            spans ``origin + [i, i+1) * cell_size`` on x (likewise y), origin (2,) world metres.
        color: RGB of the tint (35 %) and of the outline.
        seed: None, or (2,) world x, y metres marked with a red cross.
    Returns:
        A new (H, W, 3) uint8 image.
    """
    import cv2

    lo, hi = scene.bounds
    xs = np.arange(lo[0] + pixel_size / 2, hi[0], pixel_size)[:image.shape[1]]
    ys = np.arange(hi[1] - pixel_size / 2, lo[1], -pixel_size)[:image.shape[0]]
    i = np.floor((xs - origin[0]) / cell_size).astype(np.int64)
    j = np.floor((ys - origin[1]) / cell_size).astype(np.int64)
    ok_i, ok_j = (i >= 0) & (i < columns.shape[0]), (j >= 0) & (j < columns.shape[1])
    mask = np.zeros(image.shape[:2], bool)
    mask[np.ix_(ok_j, ok_i)] = columns[np.ix_(i[ok_i], j[ok_j])].T
    out = image.astype(np.float32)
    out[mask] = 0.65 * out[mask] + 0.35 * np.asarray(color, np.float32)
    out = np.clip(out, 0, 255).astype(np.uint8)
    edge = mask & ~cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    out[edge] = color
    if seed is not None:
        c, r = int((seed[0] - lo[0]) / pixel_size), int((hi[1] - seed[1]) / pixel_size)
        size = max(3, min(image.shape[:2]) // 60)
        cv2.line(out, (c - size, r - size), (c + size, r + size), (230, 30, 30), 2)
        cv2.line(out, (c - size, r + size), (c + size, r - size), (230, 30, 30), 2)
    return out


def _solid_above(scene: Scene, up: dict, inside: np.ndarray, up_material: np.ndarray) -> np.ndarray:
    """True where the upward hit is the top face of a solid (its normal points up, i.e. we are inside)."""
    v = scene.vertices[scene.triangles[np.where(inside, up["primitive_ids"], 0)]]
    normal_z = np.cross(v[..., 1, :] - v[..., 0, :], v[..., 2, :] - v[..., 0, :])[..., 2]
    return inside & (normal_z > 0)


def contact_sheet(images: list[np.ndarray], columns: int, labels: list[str] | None = None,
                  background: int = 255) -> np.ndarray:
    """Tile (H_i, W_i, 3) uint8 images into a grid with `columns` columns, each labelled.

    Every cell is as large as the largest image (images are centred, not scaled); a label
    is written in the cell's top-left corner. Returns one (H, W, 3) uint8 image.
    """
    import cv2

    if not images:
        raise ValueError("contact_sheet needs at least one image")
    h = max(im.shape[0] for im in images) + 30
    w = max(im.shape[1] for im in images) + 10
    rows = (len(images) + columns - 1) // columns
    sheet = np.full((rows * h, columns * w, 3), background, np.uint8)
    for index, im in enumerate(images):
        r, c = divmod(index, columns)
        y0 = r * h + 25 + (h - 30 - im.shape[0]) // 2
        x0 = c * w + 5 + (w - 10 - im.shape[1]) // 2
        sheet[y0:y0 + im.shape[0], x0:x0 + im.shape[1]] = im
        if labels is not None and index < len(labels):
            cv2.putText(sheet, str(labels[index]), (c * w + 6, r * h + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.55,
                        (0, 0, 0), 1, cv2.LINE_AA)
    return sheet
