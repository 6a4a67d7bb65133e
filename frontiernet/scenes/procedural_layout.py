"""Procedural building layouts on a 2D plan: footprint, corridors, rooms, stairs.

Everything here works on integer plan pixels of ``resolution`` metres (the
:mod:`frontiernet.scenes.floorplan` frame: pixel (row r, col c) covers
``x in [c*s, (c+1)*s)``, ``y in [(H-1-r)*s, (H-r)*s)``). Rectangles are (4,) int
``[row0, col0, row1, col1)`` (half-open).

The building's footprint is a union of rectangular blocks (a rectangle, an L or a U).
Corridors are carved first (a spine along the main block, plus one down each wide
wing); the rest of the footprint is split into rectangular regions, each of which is
cut into rooms by recursive binary space partitioning (BSP), separately per floor. A
building with two floors reserves a stair room, identical on both floors. The room
cells tile the footprint; walls are drawn along the cell borders afterwards (see
:mod:`frontiernet.scenes.procedural_doors`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .builder import mask_rectangles

PUBLIC_KINDS = ("corridor", "hall", "living", "kitchen", "dining", "stairs")  # rooms doors prefer


@dataclass
class Room:
    """One room cell of one floor.

    Attributes:
        rect: (4,) int64 plan pixels ``[r0, c0, r1, c1)``, the cell including its share of walls.
        interior: (4,) int64 plan pixels of the free floor inside the walls.
        kind: ``corridor``, ``stairs``, ``living``, ``kitchen``, ``bedroom``, ``bathroom``...
    """

    rect: np.ndarray
    kind: str
    interior: np.ndarray | None = None

    @property
    def size_px(self) -> tuple[int, int]:
        return int(self.rect[2] - self.rect[0]), int(self.rect[3] - self.rect[1])


@dataclass
class Skeleton:
    """Footprint and building-wide structure shared by all floors (plan pixels).

    Attributes:
        shape: (H, W) of the plan grid (footprint plus a margin for exterior walls).
        footprint: (H, W) bool, pixels inside the building's outer wall line.
        shape_kind: ``rectangle``, ``L`` or ``U``.
        building_kind: ``house`` or ``office`` (decides room kinds and furniture).
        corridors: list of (4,) rects.
        regions: list of (4,) rects that are split into rooms per floor.
        stair_rect: (4,) rect of the stair room (two floors), else None.
    """

    shape: tuple[int, int]
    footprint: np.ndarray
    shape_kind: str
    building_kind: str
    corridors: list = field(default_factory=list)
    regions: list = field(default_factory=list)
    stair_rect: np.ndarray | None = None


def px(metres: float, resolution: float) -> int:
    """Metres to a whole number of plan pixels (at least 1)."""
    return max(1, int(round(metres / resolution)))


def _footprint_blocks(rng, p, s: float, target_rooms: int):
    """Canonical-frame blocks (rects, pixels) of a rectangle / L / U footprint, and the main block.

    The main block's area is about `target_rooms` times a random mean room area; its long
    side is clipped to [footprint_min, footprint_max]. Canonical frame: the main block runs
    along columns at the top; wings hang below it.
    """
    aspect = rng.uniform(p.aspect_min, 1.0)
    area = target_rooms * rng.uniform(p.room_area_min, p.room_area_max)
    long_m = float(np.clip(np.sqrt(area / aspect), p.footprint_min, p.footprint_max))
    depth_m = min(max(long_m * aspect, p.footprint_short_min), long_m)
    W, D = px(long_m, s), px(depth_m, s)
    u = rng.random()
    kind = "U" if u < p.u_shape_probability else "L" if u < p.u_shape_probability + p.l_shape_probability else "rectangle"
    wing_min = px(2 * p.room_min + 0.3, s)
    if kind != "rectangle":
        main_d = max(wing_min, int(D * rng.uniform(0.55, 0.85)))  # wings make up the depth
        wing_w = max(wing_min, int(W * rng.uniform(p.wing_fraction_min, p.wing_fraction_max) / (2 if kind == "U" else 1)))
        wing_d = min(int(main_d * rng.uniform(0.5, 1.1)), px(p.footprint_max, s) - main_d)
        if wing_d < wing_min:
            kind = "rectangle"
        else:
            D = main_d
        if kind == "U" and 2 * wing_w + px(3.0, s) > W:
            kind = "L"
    main = np.array([0, 0, D, W])
    blocks = [main]
    if kind == "L":
        blocks.append(np.array([D, 0, D + wing_d, wing_w]))
    elif kind == "U":
        blocks += [np.array([D, 0, D + wing_d, wing_w]), np.array([D, W - wing_w, D + wing_d, W])]
    return kind, blocks


def _corridors(rng, p, s: float, blocks):
    """Corridor rects (canonical frame): a spine along the main block and one down each wide wing."""
    main = blocks[0]
    D, W = main[2] - main[0], main[3] - main[1]
    corridors = []
    if rng.random() >= p.corridor_probability or D * s < p.min_corridor_building_depth:
        return corridors
    cw = px(rng.uniform(p.corridor_width_min, p.corridor_width_max), s)
    margin = px(p.room_min + 0.3, s)
    offset = int(rng.integers(margin, max(margin + 1, D - cw - margin + 1)))
    spine = np.array([offset, 0, offset + cw, W])
    wings = []
    for wing in blocks[1:]:
        wing_w = wing[3] - wing[1]
        if wing_w * s < p.min_corridor_building_depth:
            continue
        wcw = px(rng.uniform(p.corridor_width_min, p.corridor_width_max), s)
        c0 = wing[1] + (wing_w - wcw) // 2
        stub = px(p.room_min + 0.5, s) if rng.random() < 0.5 else 0  # a room at the wing's end
        wings.append(np.array([offset + cw, c0, wing[2] - stub, c0 + wcw]))
    # a spine that stops short of one end leaves an end room (a hall, a big office...)
    if rng.random() < 0.5 and W * s > 14:
        end = px(rng.uniform(4.0, 7.0), s)
        shortened = spine.copy()
        if rng.random() < 0.5:
            shortened[1] = end
        else:
            shortened[3] = W - end
        if all(w[1] >= shortened[1] and w[3] <= shortened[3] for w in wings):
            spine = shortened
    return [spine] + wings


def _transform(rects, shape, flip_rows: bool, flip_cols: bool, transpose: bool):
    """Apply a flip / transpose of the canonical frame to (4,) rects; returns rects and new shape."""
    H, W = shape
    out = []
    for r in rects:
        r = np.array(r, np.int64)
        if flip_rows:
            r = np.array([H - r[2], r[1], H - r[0], r[3]])
        if flip_cols:
            r = np.array([r[0], W - r[3], r[2], W - r[1]])
        if transpose:
            r = r[[1, 0, 3, 2]]
        out.append(r)
    return out, ((W, H) if transpose else (H, W))


def _carve(region, cut, axis: int):
    """Split `region` at absolute coordinate `cut` along `axis` (0 rows, 1 cols)."""
    a, b = region.copy(), region.copy()
    a[2 + axis], b[axis] = cut, cut
    return a, b


def _place_stair_room(rng, p, s: float, regions, corridors):
    """Carve the stair room out of a region; returns (stair rect, remaining regions) or None."""
    storey = p.wall_height_max + p.slab_thickness
    risers = int(np.ceil(storey / p.stair_riser_max))
    length = px((risers - 1) * p.stair_tread + 2 * p.stair_landing + p.wall_thickness, s)
    width = px(p.stair_width + p.stair_walkway + p.wall_thickness, s)
    mn = px(p.room_min, s)
    order = rng.permutation(len(regions))
    for index in order:
        region = regions[index]
        h, w = region[2] - region[0], region[3] - region[1]
        axis = 1 if w >= h else 0  # along the region's long side
        along, across = (w, h) if axis == 1 else (h, w)
        if along < length or across < width:
            continue
        start = region[axis] + int(rng.integers(0, along - length + 1))
        if start - region[axis] < mn:
            start = region[axis]
        end = start + length
        if region[2 + axis] - end < mn:
            end = region[2 + axis]
        pieces = []
        before, rest = _carve(region, start, axis)
        middle, after = _carve(rest, end, axis)
        pieces += [r for r in (before, after) if r[2 + axis] > r[axis]]
        other = 1 - axis
        stair = middle
        if across - width >= mn:  # the stair room takes one side of the region
            if rng.random() < 0.5:
                stair, leftover = _carve(middle, middle[other] + width, other)
            else:
                leftover, stair = _carve(middle, middle[2 + other] - width, other)
            pieces.append(leftover)
        regions = [r for i, r in enumerate(regions) if i != index] + pieces
        return stair, regions
    return None


def make_skeleton(rng: np.random.Generator, p, two_floors: bool, target_rooms: int) -> Skeleton | None:
    """Draw a footprint, corridors, regions (and stair room); None when this draw is unusable."""
    s = p.resolution
    kind, blocks = _footprint_blocks(rng, p, s, target_rooms)
    Hc = max(int(b[2]) for b in blocks)
    Wc = max(int(b[3]) for b in blocks)
    corridors = _corridors(rng, p, s, blocks)
    canvas = np.zeros((Hc, Wc), bool)
    for b in blocks:
        canvas[b[0]:b[2], b[1]:b[3]] = True
    rest = canvas.copy()
    for c in corridors:
        rest[c[0]:c[2], c[1]:c[3]] = False
    regions = list(mask_rectangles(rest))
    mn = px(p.room_min, s)
    if any(min(r[2] - r[0], r[3] - r[1]) < mn for r in regions):
        return None
    stair = None
    if two_floors:
        placed = _place_stair_room(rng, p, s, regions, corridors)
        if placed is None:
            return None
        stair, regions = placed
    flips = rng.random(3) < 0.5
    named = corridors + regions + ([stair] if stair is not None else [])
    named, (Hc, Wc) = _transform(named, (Hc, Wc), *flips)
    blocks, _ = _transform(blocks, canvas.shape, *flips)
    margin = px(p.exterior_wall_thickness, s) + 2
    named = [r + margin for r in named]
    shape = (Hc + 2 * margin, Wc + 2 * margin)
    footprint = np.zeros(shape, bool)
    for b in blocks:
        footprint[b[0] + margin:b[2] + margin, b[1] + margin:b[3] + margin] = True
    area_m2 = footprint.sum() * s * s
    building = "office" if area_m2 > p.office_min_area and rng.random() < 0.6 else "house"
    return Skeleton(shape=shape, footprint=footprint, shape_kind=kind, building_kind=building,
                    corridors=named[:len(corridors)],
                    regions=named[len(corridors):len(corridors) + len(regions)],
                    stair_rect=named[-1] if stair is not None else None)


def split_rooms(rng: np.random.Generator, p, regions, target_rooms: int) -> list[np.ndarray]:
    """Binary space partitioning of the regions into room cells (list of (4,) rects).

    First every cell with a side longer than ``room_max`` is split; then the largest
    cells (area jittered) are split until there are `target_rooms` cells or none can be
    split without a side shorter than ``room_min``. Cuts fall near the middle (normal,
    sd 17 % of the side), or, with ``closet_probability``, a closet-sized slice comes off one end.
    """
    s = p.resolution
    mn, mx = px(p.room_min, s), px(p.room_max, s)

    def split(r):
        h, w = int(r[2] - r[0]), int(r[3] - r[1])
        can = [h >= 2 * mn, w >= 2 * mn]
        if all(can):
            axis = 0 if h * rng.uniform(0.75, 1.33) > w else 1
        else:
            axis = 0 if can[0] else 1
        length = h if axis == 0 else w
        closet = px(rng.uniform(p.room_min, p.room_min + 0.7), s)
        if rng.random() < p.closet_probability and length >= closet + 2 * mn and min(h, w) * s < 5.0:
            offset = closet if rng.random() < 0.5 else length - closet  # a closet / bathroom slice
        else:
            offset = int(np.clip(round(length * rng.normal(0.5, 0.17)), mn, length - mn))
        return list(_carve(r, r[axis] + offset, axis))

    def splittable(r):
        return max(r[2] - r[0], r[3] - r[1]) >= 2 * mn

    leaves = []
    stack = [np.array(r, np.int64) for r in regions]
    while stack:  # sides longer than room_max must go
        r = stack.pop()
        if max(r[2] - r[0], r[3] - r[1]) > mx and splittable(r):
            stack += split(r)
        else:
            leaves.append(r)
    while len(leaves) < target_rooms:
        candidates = [i for i, r in enumerate(leaves) if splittable(r)]
        if not candidates:
            break
        areas = np.array([(leaves[i][2] - leaves[i][0]) * (leaves[i][3] - leaves[i][1]) for i in candidates], float)
        i = candidates[int(np.argmax(areas * rng.uniform(0.6, 1.4, len(areas))))]
        leaves += split(leaves.pop(i))
    return leaves


def assign_kinds(rng, rects, building: str, floor: int, s: float) -> list[str]:
    """Room kinds by size: the largest public rooms first, small cells become baths/closets."""
    areas = np.array([(r[2] - r[0]) * (r[3] - r[1]) * s * s for r in rects])
    short = np.array([min(r[2] - r[0], r[3] - r[1]) * s for r in rects])
    order = np.argsort(-areas)
    kinds = [""] * len(rects)
    if building == "house":
        big = ["living", "kitchen", "dining"] if floor == 0 else ["living"]
        rest_kinds = ["bedroom", "bedroom", "office", "bedroom"]
    else:
        big = ["hall", "meeting", "kitchen"] if floor == 0 else ["meeting", "kitchen"]
        rest_kinds = ["office"]
    bathrooms = 0
    for rank, i in enumerate(order):
        if areas[i] < 4.5 or short[i] < 1.8:
            kinds[i] = "bathroom" if bathrooms < 1 + len(rects) // 7 and areas[i] >= 2.5 else "closet"
            bathrooms += kinds[i] == "bathroom"
        elif big and areas[i] >= 9.0:
            kinds[i] = big.pop(0)
        elif areas[i] < 8.0 and bathrooms < 1 + len(rects) // 6 and rng.random() < 0.6:
            kinds[i] = "bathroom"
            bathrooms += 1
        else:
            kinds[i] = rest_kinds[int(rng.integers(len(rest_kinds)))]
    return kinds
