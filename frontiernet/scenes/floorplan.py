"""Floor plans: 2D occupancy images extruded into 3D buildings.

A plan is an (H, W) image: occupied pixels become walls of ``wall_height``, the inside
of the building gets a floor (and optionally a ceiling), and door gaps stay open with a
lintel above ``door_height`` where doors are known (KTH/MapEx ``valid_space`` marks
wall and door-frame pixels between spaces with 0).

Plan frame to world frame (right-handed, Z-up): pixel (row r, col c) of an (H, W) plan
at resolution ``s`` m/px covers ``x in [c*s, (c+1)*s)``, ``y in [(H-1-r)*s, (H-r)*s)``;
the floor top is at z = 0. :func:`plan_pixel_to_world` applies it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from ..errors import InputError, positive_number
from ..array_files import read_image, read_npy
from ..io import input_file, present
from .builder import MeshBuilder, make_texture, mask_rectangles, rect_boxes
from .explorable import enclosed_free as building_inside  # shared with 3D voxelisation
from .scene import Material, Scene, SceneMetadata

MIN_PLAN_EXTENT_M = 1.0  # a plan narrower than this holds no room a robot fits in: its resolution is wrong
IMAGE_SUFFIXES = (".png", ".pgm", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass
class FloorPlan:
    """A plan read from disk.

    Attributes:
        occupied: (H, W) bool, walls and obstacles.
        inside: (H, W) bool, pixels that belong to the building (get a floor).
        doors: (H, W) bool, door gaps (free pixels that get a lintel), may be all False.
        resolution: metres per pixel.
        spaces: (H, W) bool, the pixels of a labelled space (a KTH/MapEx ``valid_space`` > 0: a room or a
            corridor), or None for a plan without one.
    """

    occupied: np.ndarray
    inside: np.ndarray
    doors: np.ndarray
    resolution: float
    spaces: np.ndarray | None = None


def plan_pixel_to_world(rows, cols, shape: tuple[int, int], resolution: float) -> np.ndarray:
    """(N, 2) world x, y metres of the centres of plan pixels (rows, cols) of a plan of `shape`."""
    rows, cols = np.asarray(rows, np.float64), np.asarray(cols, np.float64)
    return np.stack([(cols + 0.5) * resolution, (shape[0] - rows - 0.5) * resolution], axis=-1)


def plan_start_positions(path: Path, plan: FloorPlan) -> list[list[float]]:
    """World (x, y) metres of the start poses a plan folder ships (``start_poses.json``, MapEx's
    starts as ``raw_pixel_row_col`` into ``occ_map.npy``; shared/data/floorplans/README.md).

    Raises:
        InputError: a file that is not such a list or not a regular file (a pipe, a folder, a link loop), or a
            start off the plan, on a wall, or outside every space of the plan's ``valid_space`` (0 there: outside
            the building, or a wall or door frame between spaces; MapEx's starts all lie in a room or corridor).
    """
    import json

    path = input_file(path, "KTH plan start-pose file")
    try:
        starts = [entry["raw_pixel_row_col"] for entry in json.loads(Path(path).read_text())["start_poses"]]
        rows, cols = (np.asarray([start[i] for start in starts], np.int64).reshape(-1) for i in (0, 1))
    except (ValueError, KeyError, TypeError, IndexError) as error:
        raise InputError(f"{path}: not a start_poses.json with raw_pixel_row_col entries ({error})") from None
    shape = plan.occupied.shape
    bad = (rows < 0) | (rows >= shape[0]) | (cols < 0) | (cols >= shape[1])
    if bad.any() or plan.occupied[rows, cols].any():
        raise InputError(f"{path}: start pose(s) off the plan or on a wall: "
                         f"{[starts[i] for i in np.flatnonzero(bad | plan.occupied[np.clip(rows, 0, shape[0] - 1), np.clip(cols, 0, shape[1] - 1)])]}")
    outside = np.flatnonzero(~plan.spaces[rows, cols]) if plan.spaces is not None else []
    if len(outside):
        listed = ", ".join(f"{i} (row {rows[i]}, col {cols[i]})" for i in outside[:4]) + \
            (f" and {len(outside) - 4} more" if len(outside) > 4 else "")
        raise InputError(f"{path}: start{'s' if len(outside) > 1 else ''} {listed} lie{'' if len(outside) > 1 else 's'}"
                         " outside every space of valid_space.npy (0 there: outside the building, or a wall or door "
                         "frame between spaces); a start must be a pixel of a room or corridor")
    return np.round(plan_pixel_to_world(rows, cols, shape, plan.resolution), 4).tolist()


def read_floorplan(path: str | Path, *, resolution: float | None, occupied_below: int, free_above: int,
                   gap_closing_m: float, kth_resolution: float, spec_text: str) -> FloorPlan:
    """Read a plan image, ``.npy`` array, or KTH/MapEx folder (``occ_map.npy`` + ``valid_space.npy``)."""
    path = Path(path)
    valid = None
    if resolution is not None:
        positive_number(resolution, f"{spec_text}: resolution", "metres/pixel")
    if not occupied_below <= free_above:  # a pixel value between them would be occupied and free at once
        raise InputError(f"{spec_text}: occupied_below ({occupied_below}) must be at most free_above ({free_above}): "
                         "pixels below the first are walls, above the second free space")
    if path.is_dir():  # (a pipe, a folder or a link loop with a file's name is named so: input_file, read_npy)
        if not present(path / "occ_map.npy"):
            raise InputError(f"{path}: floor-plan folder has no occ_map.npy")
        input_file(path / "occ_map.npy", "KTH plan occupancy grid")
        if present(path / "valid_space.npy"):
            valid = _load_array(path / "valid_space.npy")
        resolution = kth_resolution if resolution is None else resolution
        path = path / "occ_map.npy"
    input_file(path, "floor-plan file")
    if resolution is None:
        raise InputError(f"{spec_text}: a floor plan needs its resolution in metres/pixel "
                         "(add '?resolution=0.05')")
    positive_number(resolution, f"{spec_text}: resolution", "metres/pixel")
    image = _load_array(path) if path.suffix.lower() == ".npy" else _load_image(path)
    if image.ndim != 2 or min(image.shape) < 3:
        raise InputError(f"{path}: a floor plan must be a 2D image of at least 3x3 pixels, got shape {image.shape}")
    if min(image.shape) * resolution < MIN_PLAN_EXTENT_M:  # a wrong ?resolution= (mm for m), not a building
        raise InputError(f"{spec_text}: {image.shape[1]} x {image.shape[0]} pixels at {resolution:g} m/pixel span "
                         f"{image.shape[1] * resolution:.3g} x {image.shape[0] * resolution:.3g} m, less than "
                         f"{MIN_PLAN_EXTENT_M:g} m a side: check its resolution (metres per pixel)")
    occupied = image < occupied_below
    free = image > free_above
    if valid is not None:
        if valid.shape != image.shape:
            raise InputError(f"{path.parent / 'valid_space.npy'}: shape {valid.shape} differs from "
                             f"occ_map.npy {image.shape}")
        spaces = valid > 0
        margin = max(1, int(round(0.4 / resolution)))  # walls and door frames around the spaces
        inside = ndimage.binary_dilation(spaces, iterations=margin) | spaces
        doors = _door_gaps(free & ~spaces & inside, valid, free)
    else:
        inside = building_inside(free, float(resolution), gap_closing_m)
        inside = inside | (occupied & ndimage.binary_dilation(inside, iterations=2))
        doors = np.zeros_like(free)
    if not (free & inside).any():
        raise InputError(f"{path}: the floor plan has no free space inside a building"
                         f"{_grey_levels(image, occupied_below, free_above)}")
    return FloorPlan(occupied=occupied, inside=inside | (occupied & ndimage.binary_dilation(inside)),
                     doors=doors, resolution=float(resolution), spaces=None if valid is None else valid > 0)


def _grey_levels(image: np.ndarray, occupied_below: float, free_above: float) -> str:
    """What a plan (float64 pixels) without free space holds against the grey levels it is read by: ``: its
    values lie in [lo, hi]; free space is above free_above (250), walls below occupied_below (50)`` (and, with
    no free pixel at all, how to give it: a plan of fractions in [0, 1] is all walls)."""
    finite = image[np.isfinite(image)]
    if not finite.size:
        return ": its values are all NaN or infinite"
    low, high = float(finite.min()), float(finite.max())
    text = (f": its values lie in [{low:g}, {high:g}]; free space is above free_above ({free_above:g}), "
            f"walls below occupied_below ({occupied_below:g})")
    if high <= free_above:
        text += (" and no pixel is free: scale it to the grey levels (0 wall, 255 free), or give ?free_above= and "
                 "?occupied_below= for its values")
    return text


def _door_gaps(candidates: np.ndarray, space_labels: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Door gaps: free pixels outside every labelled space that join two different spaces.

    Connected groups of `candidates` (free, unlabelled, inside pixels) are kept when they
    border free pixels of at least two distinct spaces; unlabelled strips along a single
    room's walls are not doors. (KTH plans draw some thick walls as outlines; their
    hollow insides stay free, enclosed and unreachable.)
    """
    groups, count = ndimage.label(candidates)
    if count == 0:
        return candidates
    free_labels = np.where(free, space_labels, 0)
    pairs = []
    for axis in (0, 1):
        for shift in (1, -1):
            neighbour = np.roll(free_labels, shift, axis=axis)
            touching = (groups > 0) & (neighbour > 0)
            pairs.append(np.stack([groups[touching], neighbour[touching]], axis=1))
    pairs = np.unique(np.concatenate(pairs).astype(np.int64), axis=0)
    spaces_touched = np.bincount(pairs[:, 0], minlength=count + 1)
    return np.isin(groups, np.flatnonzero(spaces_touched >= 2))


def _load_array(path: Path) -> np.ndarray:
    array = read_npy(path)
    real = np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    if not real and array.dtype != bool:  # (complex numbers lost their imaginary part in silence)
        raise InputError(f"{path}: floor-plan array must hold real numbers or booleans, got {array.dtype}")
    return array.astype(np.float64) if array.dtype != bool else np.where(array, 254.0, 0.0)


def _load_image(path: Path) -> np.ndarray:
    import cv2

    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise InputError(f"{path}: unsupported floor-plan format '{path.suffix}' "
                         f"(use .npy or one of {', '.join(IMAGE_SUFFIXES)})")
    return read_image(path, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH, "floor-plan image").astype(np.float64)


def plan_materials(builder: MeshBuilder, rng: np.random.Generator) -> dict[str, int]:
    """Default floor-plan materials (plaster walls, wood floor, white ceiling, door frames)."""
    return {
        "wall": builder.material(Material("plan-wall", (225, 220, 210), make_texture("plaster", rng, (225, 220, 210)))),
        "floor": builder.material(Material("plan-floor", (160, 120, 80), make_texture("wood", rng, (160, 120, 80)))),
        "ceiling": builder.material(Material("plan-ceiling", (240, 240, 240),
                                             make_texture("plaster", rng, (240, 240, 238)))),
        "lintel": builder.material(Material("plan-lintel", (200, 195, 185),
                                            make_texture("plaster", rng, (200, 195, 185)))),
    }


def extrude_plan(builder: MeshBuilder, plan: FloorPlan, materials: dict[str, int], *, wall_height: float,
                 door_height: float, ceiling: bool, texture_size_m: float, z0: float = 0.0) -> None:
    """Add the plan's walls, floor, door lintels and optional ceiling to `builder`.

    The floor's top face lies at ``z0``; walls span ``[z0, z0 + wall_height]``.
    Only faces that can be seen from inside are emitted (floor top, ceiling bottom).
    """
    shape, s = plan.occupied.shape, plan.resolution
    walls = mask_rectangles(plan.occupied)
    builder.add_boxes(*rect_boxes(walls, shape, s, z0, z0 + wall_height), materials["wall"],
                      texture_size_m, faces=("+x", "-x", "+y", "-y", "+z"))
    floor = mask_rectangles(plan.inside)
    builder.add_boxes(*rect_boxes(floor, shape, s, z0 - 0.05, z0), materials["floor"], texture_size_m,
                      faces=("+z",))
    if plan.doors.any() and door_height < wall_height:
        lintels = mask_rectangles(plan.doors)
        builder.add_boxes(*rect_boxes(lintels, shape, s, z0 + door_height, z0 + wall_height),
                          materials["lintel"], texture_size_m, faces=("+x", "-x", "+y", "-y", "-z"))
    if ceiling:
        builder.add_boxes(*rect_boxes(floor, shape, s, z0 + wall_height, z0 + wall_height + 0.05),
                          materials["ceiling"], texture_size_m, faces=("-z",))


def load_floorplan(path: str | Path, spec_text: str, conf) -> Scene:
    """Read a floor plan and extrude it into a :class:`Scene` (see module docstring).

    `conf` is the ``floorplan`` section of ``configs/scenes.yaml`` merged with spec options.
    """
    for key in ("wall_height", "door_height"):
        positive_number(conf[key], f"{spec_text}: {key}", "metres")
    plan = read_floorplan(path, resolution=conf.resolution, occupied_below=conf.occupied_below,
                          free_above=conf.free_above, gap_closing_m=conf.gap_closing_m,
                          kth_resolution=conf.kth_resolution, spec_text=spec_text)
    builder = MeshBuilder()
    materials = plan_materials(builder, np.random.default_rng(int(conf.texture_seed)))
    extrude_plan(builder, plan, materials, wall_height=float(conf.wall_height),
                 door_height=float(conf.door_height), ceiling=bool(conf.ceiling),
                 texture_size_m=float(conf.texture_size_m))
    path = Path(path)
    extra = {"resolution": plan.resolution, "plan_shape": list(plan.occupied.shape),
             "wall_height": float(conf.wall_height), "ceiling": bool(conf.ceiling),
             "door_pixels": int(plan.doors.sum())}
    if path.is_dir() and present(path / "start_poses.json"):  # (a pipe there: named, not taken for none)
        extra["start_xy"] = plan_start_positions(path / "start_poses.json", plan)
    metadata = SceneMetadata(name=path.name if path.is_dir() else path.stem, source="floorplan", spec=spec_text,
                             extra=extra)
    return builder.build(metadata)
