"""Where a scene is explorable: the inside of a building on a grid, and the explorable space of a
voxelised scene under the ``reachable`` rule (``sim.voxels.explorable``).

The space an exploration run is scored on (Vox@k in docs/design.md item 7) follows what the
robot can reach and see, not what the outside cannot flood into:

1. **The building's envelope.** A free voxel at layer ``k`` is inside the building when its
   column lies inside the plan outline of the structure *at or above* that height (every
   occupied voxel of layers ``>= k`` projected onto the plan; openings in that outline narrower
   than ``wall_gap_m`` closed, :func:`enclosed_free`) and inside the
   building's footprint (every occupied voxel projected, openings narrower than
   ``gap_closing_m`` closed: a recess in a facade with no floor is not the building's). Seen from
   above, a window has its lintel, a door its lintel or the ceiling: glassless windows, wide
   entrances and open fronts under a roof or a lintel do not open the envelope, and over a
   roofless room it ends at the walls' height, over a roofed one at the ceiling. Covered voxels
   (structure above them) within ``gap_closing_m / 2`` of the open air outside the envelope are
   the outside's (:func:`near_open_air`: eaves, a ledge outside a
   wall, the mouth of a wide door; as the ``enclosed`` rule has it at doors). A ``?bounds=`` box
   of the scene spec cuts the envelope and drops the structure outside it (surroundings).
2. **Navigable floor.** A free envelope voxel right above an occupied one (a surface the robot
   stands on: the grid's bottom layer is no floor) where a robot fits: ``floor_headroom_m`` of
   free envelope voxels above it, and ``floor_clearance_m`` in-plane to the nearest voxel
   without that headroom.
3. **Explorable** = the face-connected component of free envelope voxels that holds the seed:
   the navigable floor voxel nearest the spec's ``?seed=x,y[,z]`` (within ``seed_search_m``; with
   a z, the highest floor at or below it, without one the lowest), else, automatically, the
   component with the most navigable floor (the building's interior, not a cabinet or a wall's
   hollow), seeded on its lowest storey's walkable floor (step 4; :func:`walkable_floors`:
   navigable voxels joined through steps of one voxel, a ramp or a threshold; a stair's treads
   or a table top are floors of their own). With no navigable floor at all: the largest
   component, no seed, and step 4 is skipped.
4. **One storey** (:func:`storey_ceiling`). The robot keeps its camera height over the seed's
   floor and never takes a stair, so of the component only the seed's storey counts: the layers
   from the surface under the seed's walkable floor (its lowest voxel's) up to below the storey's
   ceiling, the first layer above that floor whose occupied voxels cover at least
   ``storey_slab_share`` of the floor's columns (a ceiling, or the next storey's floor slab;
   with none, up to the grid's top). The void under a thin floor over nothing, a stairwell going
   down, the storeys below and, above the ceiling, the space over structure (the storeys above)
   are neither explorable nor enclosed; the air over a courtyard or up an opening in the slab,
   and a room's patch without a floor mesh level with the floor (KTH plans), stay. The
   automatic seed is on the lowest storey: the lowest walkable floor holding at least
   ``storey_floor_share`` of the largest one's voxels (not a stair's tread or the bottom of a shaft).

Everything else free inside the envelope (wall interiors, closed cabinets, rooms with no way in)
is *enclosed*, not explorable: it tells "inside an obstacle" from "outside the building".

**The inside of a building** (:func:`enclosed_free`): free cells that a flood from the grid's
lateral border cannot reach through openings narrower than a gap (doors and windows to the
outside). One rule for a 2D floor plan (:mod:`.floorplan`, the building's inside) and for the
stack of horizontal voxel slices of a 3D scene (:mod:`frontiernet.simulator.voxels`, the
``enclosed`` rule, and the envelope above), so both agree on what is inside.
:func:`near_open_air` is the same half-gap margin around the open air outside a building given
as a mask.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import InputError, fraction_or_null, positive_number


_TIE = 1e-4  # cells; float32 distances equal to the radius count as within it


def _inplane_edt(mask: np.ndarray) -> np.ndarray:
    """float32 distance (cells) from each True cell of `mask` to the nearest False cell of its slice.

    `mask` is (H, W) or (H, W, Z) with horizontal slices along the last axis; a slice
    without any False cell gets a huge distance. Exact Euclidean distance transform
    (OpenCV, DIST_MASK_PRECISE), one slice at a time: 20x faster than a 3D scipy EDT.
    """
    import cv2

    if mask.ndim == 2:
        return cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    out = np.empty(mask.shape, np.float32)
    for k in range(mask.shape[2]):
        out[:, :, k] = cv2.distanceTransform(mask[:, :, k].astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return out


def enclosed_free(free: np.ndarray, resolution: float, gap_closing_m: float) -> np.ndarray:
    """Free cells enclosed by the building: not reachable from the lateral border.

    Works on one 2D plan (H, W) or on a stack of horizontal slices (X, Y, Z) at once
    (the in-plane axes are the first two). Openings narrower than `gap_closing_m`
    (doors and windows to the outside) are treated as closed: the flood from the border
    only passes cells farther than half that from any non-free cell (in-plane), and is
    then grown back by the same radius.

    Args:
        free: (H, W) or (X, Y, Z) bool, free cells.
        resolution: metres per cell; gap_closing_m: metres.
    Returns:
        bool array like `free`: free cells inside the building.
    """
    free = np.asarray(free, bool)
    radius = gap_closing_m / 2.0 / resolution
    pad = int(np.ceil(radius)) + 2
    width = ((pad, pad), (pad, pad)) + ((0, 0),) * (free.ndim - 2)
    padded = np.pad(free, width, constant_values=True)
    clearance = _inplane_edt(padded)
    structure = ndimage.generate_binary_structure(2, 1)  # 4-connected in-plane
    if free.ndim == 3:
        structure = np.stack([np.zeros_like(structure), structure, np.zeros_like(structure)], axis=-1)
    labels, _ = ndimage.label(clearance > radius + _TIE, structure=structure)
    border = np.unique(np.concatenate([labels[0].ravel(), labels[-1].ravel(),
                                       labels[:, 0].ravel(), labels[:, -1].ravel()]))
    flood = np.isin(labels, border[border > 0])
    del labels, clearance
    outside = _inplane_edt(~flood) <= radius + _TIE
    inside = padded & ~outside
    return inside[pad:-pad, pad:-pad]


def near_open_air(free: np.ndarray, outside: np.ndarray, resolution: float, gap_closing_m: float) -> np.ndarray:
    """Free cells within ``gap_closing_m / 2`` (in-plane) of open air outside the building.

    Open air: cells of `outside` that are free and farther than half the gap from every
    non-free cell of their slice, so openings narrower than the gap (the doors and windows
    :func:`enclosed_free` seals) let none of it in; unlike there, the air does not flow
    on into the building through wider openings: it only reaches the half gap beyond them.
    The grid's lateral border counts as free outside.

    Args:
        free: (H, W) or (X, Y, Z) bool, free cells; outside: bool like `free` (cells not in
            the building); resolution: metres per cell; gap_closing_m: metres.
    Returns:
        bool array like `free`: free cells within reach of the open air (the air included).
    """
    free = np.asarray(free, bool)
    radius = gap_closing_m / 2.0 / resolution
    pad = int(np.ceil(radius)) + 2
    width = ((pad, pad), (pad, pad)) + ((0, 0),) * (free.ndim - 2)
    padded = np.pad(free, width, constant_values=True)
    air = np.pad(np.asarray(outside, bool), width, constant_values=True) & padded
    air &= _inplane_edt(padded) > radius + _TIE
    near = padded & (_inplane_edt(~air) <= radius + _TIE)
    return near[pad:-pad, pad:-pad]


@dataclass
class ReachableSpace:
    """What :func:`reachable_space` found (arrays (X, Y, Z) bool on the voxel grid).

    Attributes:
        explorable: the chosen component of free envelope voxels.
        enclosed: every free voxel inside the envelope (a superset of `explorable`).
        navigable: navigable floor voxels (free, on a support, with the robot's headroom and clearance).
        seed: (3,) int64 voxel index the component was chosen by, or None (no navigable floor).
        floor_layer: layer index of the surface under the seed's walkable floor (step 4), or None
            (no seed): the robot's camera height is taken over it.
    """

    explorable: np.ndarray
    enclosed: np.ndarray
    navigable: np.ndarray
    seed: np.ndarray | None
    floor_layer: int | None = None


def box_mask(origin: np.ndarray, voxel_size: float, shape: tuple[int, int, int], box) -> np.ndarray:
    """(X, Y, Z) bool (a broadcast view): voxels whose centre lies in `box` ((2, 3) world [min, max],
    metres); all True when `box` is None."""
    if box is None:
        return np.ones((1, 1, 1), bool)
    box = np.asarray(box, np.float64).reshape(2, 3)
    masks = []
    for axis in range(3):
        centres = origin[axis] + (np.arange(shape[axis]) + 0.5) * voxel_size
        masks.append((centres >= box[0, axis]) & (centres <= box[1, axis]))
    return masks[0][:, None, None] & masks[1][None, :, None] & masks[2][None, None, :]


def envelope(occupied: np.ndarray, voxel_size: float, wall_gap_m: float,
             footprint_gap_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(X, Y, Z) bool voxels inside the building's envelope (step 1 of the module docstring), and
    (X, Y, Z) bool voxels covered (structure at or above them).

    Args:
        occupied: (X, Y, Z) bool structure (already cut to a bounds box).
        voxel_size: metres.
        wall_gap_m: openings in the outline of the structure at or above a layer narrower than
            this are closed (full-height openings of roofless rooms).
        footprint_gap_m: the same for the footprint, the outline of all the structure (floors
            included: a recess in a facade without floor is not the building's).
    """
    above = np.logical_or.accumulate(occupied[:, :, ::-1], axis=2)[:, :, ::-1]  # structure at or above k
    inside = above | enclosed_free(~above, voxel_size, wall_gap_m)
    plan = above[:, :, 0]  # every occupied voxel projected
    footprint = plan | enclosed_free(~plan, voxel_size, footprint_gap_m)
    return inside & footprint[:, :, None], above


def navigable_floor(free: np.ndarray, occupied: np.ndarray, voxel_size: float, headroom_m: float,
                    clearance_m: float) -> np.ndarray:
    """(X, Y, Z) bool: free voxels on a support (an occupied voxel right below; none on the grid's
    bottom layer) with `headroom_m` of `free` voxels above them (the voxel included) and
    `clearance_m` (in-plane) to the nearest voxel of their layer without that headroom."""
    import cv2

    need = max(int(math.ceil(headroom_m / voxel_size - 1e-9)), 1)
    run = np.zeros(free.shape[:2], np.int32)
    room = np.zeros(free.shape, bool)
    for k in range(free.shape[2] - 1, -1, -1):  # free voxels from k upwards
        run = np.where(free[:, :, k], run + 1, 0)
        room[:, :, k] = run >= need
    support = np.zeros(free.shape, bool)
    support[:, :, 1:] = occupied[:, :, :-1]
    floor = room & support
    radius = clearance_m / voxel_size
    for k in np.flatnonzero(floor.any(axis=(0, 1))):
        layer = np.pad(room[:, :, k], 1).astype(np.uint8)  # off the grid counts as blocked
        distance = cv2.distanceTransform(layer, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
        floor[:, :, k] &= distance > radius  # distance to the nearest blocked cell centre
    return floor


def _seed_voxel(navigable: np.ndarray, origin: np.ndarray, voxel_size: float, seed: np.ndarray,
                search_m: float, where: str) -> np.ndarray:
    """(3,) int64 index of the navigable floor voxel a ``?seed=`` point picks (module docstring)."""
    index = np.argwhere(navigable)
    centres = origin + (index + 0.5) * voxel_size
    horizontal = np.hypot(*(centres[:, :2] - seed[:2]).T)
    ok = horizontal <= search_m
    if len(seed) == 3:
        ok &= centres[:, 2] - 0.5 * voxel_size <= seed[2]
    if not ok.any():
        text = ",".join(f"{v:g}" for v in seed)
        raise InputError(f"{where}: seed={text} has no navigable floor within {search_m:g} m "
                         f"(free floor with the robot's headroom and clearance, inside the building"
                         f"{' at or below z' if len(seed) == 3 else ''}); give a point on a room's floor")
    candidates = np.flatnonzero(ok)
    # nearest column first, then the highest floor at or below z (or the lowest without z)
    height = centres[candidates, 2] * (-1.0 if len(seed) == 3 else 1.0)
    best = candidates[np.lexsort((height, np.round(horizontal[candidates], 6)))[0]]
    return index[best]


def walkable_floors(navigable: np.ndarray) -> tuple[np.ndarray, int]:
    """The walkable floors: navigable floor voxels joined through steps of one voxel (26-connected:
    a ramp or a threshold; a stair's treads, a riser and the robot's clearance apart, stay apart).

    Args:
        navigable: (X, Y, Z) bool navigable floor voxels (:func:`navigable_floor`).
    Returns:
        (labels, low): (X, Y, n) int32 floor labels (0: no floor) of the n grid layers from
        layer `low` on that hold navigable voxels (n = 0 when there are none).
    """
    layers = np.flatnonzero(navigable.any(axis=(0, 1)))
    if len(layers) == 0:
        return np.zeros(navigable.shape[:2] + (0,), np.int32), 0
    low, high = int(layers[0]), int(layers[-1]) + 1
    labels, _ = ndimage.label(navigable[:, :, low:high], structure=np.ones((3, 3, 3), bool))
    return labels, low


def _floor_seed(floors: np.ndarray, low: int, share: float) -> np.ndarray:
    """(3,) int64 voxel index of the automatic seed: the voxel nearest its centroid of the lowest
    walkable floor (by its lowest layer; the larger of two at one layer) with at least `share` of
    the largest floor's voxels: the ground storey of a building of several, not a stair's tread
    or the bottom of a shaft (`floors`, `low`: :func:`walkable_floors`)."""
    sizes = np.bincount(floors.ravel())
    sizes[0] = 0
    large = np.flatnonzero(sizes >= share * sizes.max())
    lowest = ndimage.minimum(np.broadcast_to(np.arange(floors.shape[2]), floors.shape), floors, large)
    label = int(large[np.lexsort((-sizes[large], np.asarray(lowest)))[0]])
    cells = np.argwhere(floors == label)
    best = cells[np.argmin(((cells - cells.mean(axis=0)) ** 2).sum(axis=1))]
    return best + np.array([0, 0, low])


def floor_layer(floors: np.ndarray, low: int, seed_index: np.ndarray) -> int:
    """Layer index of the surface under the lowest voxel of the seed's walkable floor (`floors`,
    `low`: :func:`walkable_floors`; `seed_index`: (3,) int index of a navigable voxel)."""
    region = floors == floors[seed_index[0], seed_index[1], seed_index[2] - low]
    return low + int(np.flatnonzero(region.any(axis=(0, 1)))[0]) - 1


def storey_ceiling(occupied: np.ndarray, floor_columns: np.ndarray, floor: int, share: float) -> int:
    """Layer index of the storey's ceiling (step 4): the first layer above `floor` whose occupied
    voxels cover at least `share` of `floor_columns` ((X, Y) bool: the columns of the seed's
    walkable floor), or Z (the grid's height) when none does. `occupied`: (X, Y, Z) bool."""
    counts = np.count_nonzero(occupied[floor_columns], axis=0)  # (Z,) occupied voxels per layer
    above = np.flatnonzero(counts[floor + 1:] >= share * max(int(np.count_nonzero(floor_columns)), 1))
    return floor + 1 + int(above[0]) if len(above) else occupied.shape[2]


def under_floor(occupied: np.ndarray, floor: int) -> np.ndarray:
    """(X, Y, floor) bool over the layers below `floor`: voxels with no occupied voxel at or below
    them in their column (the void under a building, where no pose can stand; all that step 4
    cut below the storey before ``storey_slab_share``, and still does with it null).
    `occupied`: (X, Y, Z) bool; `floor`: a layer index (0: no layer below)."""
    return ~np.logical_or.accumulate(occupied[:, :, :max(floor, 0)], axis=2)


def _seed_and_storey(occupied: np.ndarray, navigable: np.ndarray, explorable: np.ndarray,
                     seed_index: np.ndarray | None, shares: tuple[float, float]) -> tuple[np.ndarray, int, np.ndarray]:
    """Steps 3 and 4 of the module docstring on the chosen component.

    Args:
        occupied, navigable, explorable: (X, Y, Z) bool; `navigable` within the component
            `explorable` and not empty.
        seed_index: (3,) int index of the spec's seed voxel, or None (automatic).
        shares: (``storey_floor_share``, ``storey_slab_share``); None for either is the rule
            before them (benchmark plans made before the keys): the largest floor's seed, and
            only the void under the building cut (nothing above).
    Returns:
        (seed_index, floor, cut): the seed's (3,) index, the layer F of its floor's surface, and
        (X, Y, Z) bool: the component's voxels off the seed's storey (below F, or at or above its
        ceiling), which do not count.
    """
    floors, low = walkable_floors(navigable)
    if seed_index is None:
        seed_index = _floor_seed(floors, low, 1.0 if shares[0] is None else shares[0])
    floor = floor_layer(floors, low, seed_index)
    cut = np.zeros(explorable.shape, bool)
    if shares[1] is None:  # the rule before the storey: the void under the building only
        cut[:, :, :floor] = explorable[:, :, :floor] & under_floor(occupied, floor)
        return seed_index, floor, cut
    columns = (floors == floors[seed_index[0], seed_index[1], seed_index[2] - low]).any(axis=2)
    top = storey_ceiling(occupied, columns, floor, shares[1])
    cut[:, :, :floor] = explorable[:, :, :floor]  # below the storey: the void under it, shafts down, storeys below
    # at and above its ceiling, over structure there: the storeys above (not the air over a
    # courtyard or up an opening in the slab, which the robot sees from below)
    cut[:, :, top:] = explorable[:, :, top:] & np.logical_or.accumulate(occupied[:, :, top:], axis=2)
    return seed_index, floor, cut


def reachable_space(occupied: np.ndarray, origin: np.ndarray, voxel_size: float, conf, *,
                    seed: np.ndarray | None = None, box=None, where: str = "scene") -> ReachableSpace:
    """The explorable space of a voxel grid under the ``reachable`` rule (module docstring).

    Args:
        occupied: (X, Y, Z) bool surface voxels.
        origin: (3,) world corner of voxel (0, 0, 0), metres; voxel_size: metres.
        conf: the ``voxels`` section of configs/sim.yaml (``wall_gap_m``, ``gap_closing_m``, ``floor_headroom_m``,
            ``floor_clearance_m``, ``seed_search_m``, ``storey_floor_share``, ``storey_slab_share``).
        seed: None, or (2,) / (3,) world metres (a spec's ``?seed=``).
        box: None, or (2, 3) world [min, max] metres (a spec's ``?bounds=``).
        where: names the scene in error messages.
    Raises:
        InputError: a bad config value, or a seed with no navigable floor near it.
    """
    gap = positive_number(conf.wall_gap_m, "voxels.wall_gap_m", "metres", allow_zero=True)
    footprint_gap = positive_number(conf.gap_closing_m, "voxels.gap_closing_m", "metres", allow_zero=True)
    headroom = positive_number(conf.floor_headroom_m, "voxels.floor_headroom_m", "metres")
    clearance = positive_number(conf.floor_clearance_m, "voxels.floor_clearance_m", "metres", allow_zero=True)
    search = positive_number(conf.seed_search_m, "voxels.seed_search_m", "metres", allow_zero=True)
    shares = tuple(_share(conf, key) for key in ("storey_floor_share", "storey_slab_share"))
    origin = np.asarray(origin, np.float64)
    in_box = box_mask(origin, voxel_size, occupied.shape, box)
    structure = occupied & in_box
    inside, covered = envelope(structure, voxel_size, gap, footprint_gap)
    inside &= in_box
    free = ~occupied
    # covered space at the edge of the open air is the outside's (eaves, ledges, the mouth of a porch)
    enclosed = free & inside & ~(covered & near_open_air(free, ~inside, voxel_size, footprint_gap))
    navigable = navigable_floor(enclosed, occupied, voxel_size, headroom, clearance)
    labels, count = ndimage.label(enclosed)  # face-connected
    seed_index = None
    if seed is not None:
        seed_index = _seed_voxel(navigable, origin, voxel_size, np.asarray(seed, np.float64), search, where)
        chosen = labels[tuple(seed_index)]
    elif navigable.any():
        floor_counts = np.bincount(labels[navigable], minlength=count + 1)
        floor_counts[0] = 0
        chosen = int(np.argmax(floor_counts))
    else:
        sizes = np.bincount(labels.ravel(), minlength=count + 1)
        sizes[0] = 0
        chosen = int(np.argmax(sizes))
    explorable = labels == chosen if chosen > 0 else np.zeros(occupied.shape, bool)
    navigable &= explorable
    floor = None
    if navigable.any():  # the void under the building and the other storeys are neither explorable nor enclosed
        seed_index, floor, cut = _seed_and_storey(occupied, navigable, explorable, seed_index, shares)
        explorable &= ~cut
        enclosed &= ~cut
        navigable &= explorable
    return ReachableSpace(explorable=explorable, enclosed=enclosed, navigable=navigable, seed=seed_index,
                          floor_layer=floor)


def _share(conf, key: str) -> float | None:
    """The fraction ``voxels.<key>`` of configs/sim.yaml, in (0, 1], or None (null or absent: the
    rule before the key, :func:`_seed_and_storey`)."""
    return fraction_or_null(conf.get(key) if hasattr(conf, "get") else getattr(conf, key, None), f"voxels.{key}")


EXPLORABLE_RULES = ("reachable", "enclosed")
"""Values of ``sim.voxels.explorable``: the ``reachable`` rule (:func:`reachable_space`), or the
per-slice flood rule ``enclosed`` (:func:`enclosed_free`, the published benchmark's)."""


def largest_component(mask: np.ndarray) -> np.ndarray:
    """The largest 6-connected (face-connected) component of a 3D bool mask (all False if empty)."""
    labels, count = ndimage.label(mask)
    if count == 0:
        return np.zeros_like(mask, bool)
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return labels == int(np.argmax(sizes))


def explorable_space(occupied: np.ndarray, origin: np.ndarray, voxel_size: float, conf, *,
                     seed: np.ndarray | None = None, box=None, where: str = "scene") -> ReachableSpace:
    """The explorable space of a voxel grid under the rule ``conf.explorable`` (one of
    :data:`EXPLORABLE_RULES`, checked by the caller before the grid is built).

    Args: as :func:`reachable_space`; `conf` is the ``voxels`` section of configs/sim.yaml.
    Returns:
        ``reachable``: :func:`reachable_space`'s answer. ``enclosed``: every free voxel that a
        flood from the grid's border cannot reach through gaps narrower than ``gap_closing_m``,
        per horizontal slice (`enclosed`), its largest face-connected component when
        ``keep_largest_component`` (`explorable`), no navigable floor computed (`navigable` all
        False) and no seed.
    Raises:
        InputError: as :func:`reachable_space`; a seed or box under the ``enclosed`` rule.
    """
    if conf.explorable == "reachable":
        return reachable_space(occupied, origin, voxel_size, conf, seed=seed, box=box, where=where)
    if seed is not None or box is not None:
        raise InputError(f"{where}: the options seed= and bounds= need voxels.explorable: reachable "
                         "(this run uses enclosed)")
    gap = positive_number(conf.gap_closing_m, "voxels.gap_closing_m", "metres", allow_zero=True)
    enclosed = enclosed_free(~occupied, voxel_size, gap)
    explorable = largest_component(enclosed) if bool(conf.keep_largest_component) else enclosed
    return ReachableSpace(explorable=explorable, enclosed=enclosed, navigable=np.zeros(occupied.shape, bool),
                          seed=None)
