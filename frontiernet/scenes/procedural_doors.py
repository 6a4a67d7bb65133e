"""Walls, doors, open-plan openings, windows and stairs of one procedural floor (plan pixels).

Conventions (see :mod:`frontiernet.scenes.procedural_layout`): rectangles are (4,) int
``[r0, c0, r1, c1)`` plan pixels. Each room cell owns ``ceil(w/2)`` pixels of wall on its
low sides and ``floor(w/2)`` on its high sides (``w`` = interior wall thickness in pixels),
so two neighbouring cells are separated by exactly ``w`` pixels; a band outside the
footprint adds the exterior wall. Openings are rectangles cut through a shared wall,
chosen on a random spanning tree of the room adjacency (every room reachable) plus a
few extra loops. In front of every opening a clearance zone is kept free of furniture.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from .procedural_layout import PUBLIC_KINDS, Room, px

OPEN_PLAN_KINDS = ("corridor", "hall", "living", "kitchen", "dining")
PRIVATE_KINDS = ("bathroom", "closet", "bedroom")


@dataclass
class Opening:
    """A door or a wide open-plan opening through the wall between rooms `a` and `b`.

    Attributes:
        a, b: room indices; `a` is on the low side (smaller row/col) of the wall.
        axis: 0 when the wall runs along columns (a horizontal line of the plan), 1 along rows.
        rect: (4,) int64 plan pixels of the gap through the wall.
        lintel_height: metres above the floor where the wall resumes, or None (full height).
        door: True for a door (gets a door leaf), False for an open-plan opening.
        clearance: (2, 4) int64 keep-out rects in front of the gap in room a and in room b.
    """

    a: int
    b: int
    axis: int
    rect: np.ndarray
    lintel_height: float | None
    door: bool
    clearance: np.ndarray


@dataclass
class Stair:
    """A straight flight from floor 0 up to floor 1 (plan pixels and metres).

    Attributes:
        flight: (4,) int64 plan rect covered by the treads (the hole in the upper slab).
        axis: 1 when the flight climbs along columns, 0 along rows.
        direction: +1 when it climbs towards larger row/col, else -1.
        risers: number of risers; rise: metres per riser; tread_px: tread depth in pixels.
        bottom_landing, top_landing: (4,) rects kept free at the foot and the head.
        open_side: (4,) one-pixel rect along the flight's free long side (railing on floor 1).
        bottom_rail: (4,) one-pixel rect across the hole's lower end (railing on floor 1).
    """

    flight: np.ndarray
    axis: int
    direction: int
    risers: int
    rise: float
    tread_px: float
    bottom_landing: np.ndarray
    top_landing: np.ndarray
    open_side: np.ndarray
    bottom_rail: np.ndarray


@dataclass
class FloorLayout:
    """One floor: rooms, openings and the (H, W) bool / int masks of its plan.

    Attributes:
        rooms: list of :class:`Room` (cells tile the footprint; `interior` set).
        openings: list of :class:`Opening`.
        walls, interior, openings_mask, clearance, reserved: (H, W) bool; `reserved`
            covers stairs, landings and the stairwell hole (no furniture, no doors).
        owner: (H, W) int32 index of the room each pixel belongs to (walls included).
        windows: list of (room, axis, side, along0, along1): a window on the exterior wall
            at the room's low (side -1) or high (side +1) edge across `axis`, pixels.
        furniture: (H, W) bool, filled by the furniture placement.
        z0: metres, top of this floor's slab.
    """

    rooms: list
    openings: list
    walls: np.ndarray
    interior: np.ndarray
    openings_mask: np.ndarray
    clearance: np.ndarray
    reserved: np.ndarray
    solid: np.ndarray
    owner: np.ndarray
    z0: float
    windows: list = field(default_factory=list)
    furniture: np.ndarray | None = None


def wall_split(p) -> tuple[int, int, int]:
    """(w, w_lo, w_hi): interior wall pixels, and the part owned by the cell above/left of it."""
    w = px(p.wall_thickness, p.resolution)
    return w, (w + 1) // 2, w // 2


def _rect(axis: int, across0, across1, along0, along1) -> np.ndarray:
    """A plan rect from ranges across a wall line and along it."""
    if axis == 0:
        return np.array([across0, along0, across1, along1], np.int64)
    return np.array([along0, across0, along1, across1], np.int64)


def _fill(mask: np.ndarray, r, value=True) -> None:
    mask[max(r[0], 0):max(r[2], 0), max(r[1], 0):max(r[3], 0)] = value


def make_stair(rng, p, stair_room: Room, storey: float) -> Stair:
    """Lay a straight flight against one long wall of the stair room's interior."""
    s = p.resolution
    I = stair_room.interior
    axis = 1 if I[3] - I[1] >= I[2] - I[0] else 0
    other = 1 - axis
    risers = int(np.ceil(storey / p.stair_riser_max))
    tread_px = p.stair_tread / s
    run = int(np.ceil((risers - 1) * tread_px))
    landing = px(p.stair_landing, s)
    fw = px(p.stair_width, s)
    direction = 1 if rng.random() < 0.5 else -1
    if direction == 1:
        a0 = I[axis] + landing
        bottom, top = (I[axis], a0), (a0 + run, a0 + run + landing)
    else:
        a0 = I[2 + axis] - landing - run
        bottom, top = (a0 + run, I[2 + axis]), (a0 - landing, a0)
    if rng.random() < 0.5:
        side, open_line = (I[other], I[other] + fw), (I[other] + fw, I[other] + fw + 1)
    else:
        side, open_line = (I[2 + other] - fw, I[2 + other]), (I[2 + other] - fw - 1, I[2 + other] - fw)
    # _rect's `axis` is the wall-line axis: along = the flight's climbing axis
    line_axis = 0 if axis == 1 else 1
    return Stair(flight=_rect(line_axis, *side, a0, a0 + run), axis=axis, direction=direction,
                 risers=risers, rise=storey / risers, tread_px=tread_px,
                 bottom_landing=_rect(line_axis, *side, *bottom), top_landing=_rect(line_axis, *side, *top),
                 open_side=_rect(line_axis, *open_line, a0, a0 + run),
                 bottom_rail=_rect(line_axis, *side, *((a0 - 1, a0) if direction == 1 else (a0 + run, a0 + run + 1))))


def _shared_walls(rooms, p):
    """Candidate openings: (i, j, axis, line, lo, hi) for rooms sharing a wall segment long enough."""
    s = p.resolution
    margin = px(p.door_corner_margin, s)
    need = px(p.door_width_min, s)
    out = []
    for i, A in enumerate(rooms):
        for j, B in enumerate(rooms):
            if i == j:
                continue
            for axis in (0, 1):  # axis 0: A above B (A.r1 == B.r0); axis 1: A left of B
                if A.rect[2 + axis] != B.rect[axis]:
                    continue
                o = 1 - axis
                lo = max(A.interior[o], B.interior[o]) + margin
                hi = min(A.interior[2 + o], B.interior[2 + o]) - margin
                if hi - lo >= need:
                    out.append((i, j, axis, int(A.rect[2 + axis]), int(lo), int(hi)))
    return out


def _spanning_edges(rng, rooms, candidates, p):
    """Indices of candidate walls that get an opening: a random spanning tree plus loops, or None."""
    parent = list(range(len(rooms)))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    weights = []
    for i, j, *_ in candidates:
        kinds = (rooms[i].kind, rooms[j].kind)
        w = rng.random()
        w -= 0.6 * sum(k in PUBLIC_KINDS for k in kinds)
        w += 0.8 * (kinds[0] in PRIVATE_KINDS and kinds[1] in PRIVATE_KINDS)
        w += 0.5 * ("stairs" in kinds and not any(k in PUBLIC_KINDS[:2] for k in kinds))
        weights.append(w)
    chosen, rest = [], []
    for index in np.argsort(weights):
        i, j = candidates[index][:2]
        if find(i) != find(j):
            parent[find(i)] = find(j)
            chosen.append(int(index))
        else:
            rest.append(int(index))
    if len({find(i) for i in range(len(rooms))}) > 1:
        return None
    for index in rest:
        kinds = {rooms[candidates[index][0]].kind, rooms[candidates[index][1]].kind}
        if not kinds & {"closet", "bathroom", "stairs"} and rng.random() < p.extra_door_probability:
            chosen.append(index)
    return chosen


def _make_opening(rng, p, rooms, candidate, reserved, door_height, wall_height) -> Opening | None:
    i, j, axis, line, lo, hi = candidate
    s = p.resolution
    w, w_lo, w_hi = wall_split(p)
    kinds = (rooms[i].kind, rooms[j].kind)
    both_corridor = kinds == ("corridor", "corridor")
    open_plan = both_corridor or (all(k in OPEN_PLAN_KINDS for k in kinds) and "corridor" not in kinds
                                  and rng.random() < p.open_plan_probability)
    span = hi - lo
    if open_plan:
        width = span if both_corridor else int(span * rng.uniform(0.5, 1.0))
        width = max(width, min(span, px(p.door_width_max, s)))
        lintel = None if both_corridor or rng.random() < 0.4 else wall_height - rng.uniform(0.2, 0.45)
    else:
        width = min(span, px(rng.uniform(p.door_width_min, p.door_width_max), s))
        lintel = door_height
    cl = px(p.door_clearance, s)
    for _ in range(12):
        start = int(rng.integers(lo, hi - width + 1))
        gap = _rect(axis, line - w_hi, line + w_lo, start, start + width)
        zones = np.stack([_rect(axis, line - w_hi - cl, line - w_hi, start, start + width),
                          _rect(axis, line + w_lo, line + w_lo + cl, start, start + width)])
        if not any(reserved[z[0]:z[2], z[1]:z[3]].any() for z in zones):
            return Opening(a=i, b=j, axis=axis, rect=gap, lintel_height=lintel, door=not open_plan,
                           clearance=zones)
    return None


def _windows(p, rooms, footprint) -> list:
    """Window spans on exterior walls: (room, axis, side, along0, along1) in pixels."""
    s = p.resolution
    out = []
    for index, room in enumerate(rooms):
        if room.kind in ("closet", "stairs"):
            continue
        for axis in (0, 1):
            o = 1 - axis
            lo, hi = int(room.interior[o]), int(room.interior[2 + o])
            for side in (-1, 1):
                probe = room.rect[axis] - 1 if side < 0 else room.rect[2 + axis]
                if not 0 <= probe < footprint.shape[axis]:
                    continue
                line = footprint[probe, lo:hi] if axis == 0 else footprint[lo:hi, probe]
                outside = ~line
                if outside.mean() < 0.95 or (hi - lo) * s < 1.4:
                    continue
                width = px(min(p.window_width_max, (hi - lo) * s - 0.6), s)
                count = max(1, int((hi - lo) * s // 4.0))
                for k in range(count):
                    centre = lo + (hi - lo) * (2 * k + 1) // (2 * count)
                    out.append((index, axis, side, centre - width // 2, centre + width // 2))
    return out


def make_floor(rng, p, skeleton, rects, kinds, *, z0: float, wall_height: float, door_height: float,
               stair: Stair | None, upper: bool) -> FloorLayout | None:
    """Walls, openings and masks of one floor from its room cells; None if rooms cannot all connect."""
    shape = skeleton.shape
    w, w_lo, w_hi = wall_split(p)
    rooms = []
    for rect, kind in zip(rects, kinds):
        interior = np.array([rect[0] + w_lo, rect[1] + w_lo, rect[2] - w_hi, rect[3] - w_hi], np.int64)
        rooms.append(Room(rect=np.asarray(rect, np.int64), kind=kind, interior=interior))
    reserved = np.zeros(shape, bool)
    solid = np.zeros(shape, bool)
    if stair is not None:
        for r in ((stair.flight, stair.open_side, stair.bottom_rail) if upper else (stair.flight,)):
            _fill(solid, r)
        _fill(reserved, stair.top_landing if upper else stair.bottom_landing)
        reserved |= solid
    candidates = _shared_walls(rooms, p)
    chosen = _spanning_edges(rng, rooms, candidates, p)
    if chosen is None:
        return None
    openings = []
    for index in chosen:
        opening = _make_opening(rng, p, rooms, candidates[index], reserved, door_height, wall_height)
        if opening is None:
            return None
        openings.append(opening)
    interior = np.zeros(shape, bool)
    owner = np.zeros(shape, np.int32)
    for index, room in enumerate(rooms):
        _fill(interior, room.interior)
        _fill(owner, room.rect, index + 1)
    openings_mask = np.zeros(shape, bool)
    clearance = np.zeros(shape, bool)
    for o in openings:
        _fill(openings_mask, o.rect)
        for z in o.clearance:
            _fill(clearance, z)
    clearance &= interior
    band = px(p.exterior_wall_thickness, p.resolution) - w_hi
    outer = ndimage.maximum_filter(skeleton.footprint, size=2 * band + 1)
    walls = outer & ~interior & ~openings_mask
    _, (rows, cols) = ndimage.distance_transform_edt(owner == 0, return_indices=True)
    owner = owner[rows, cols] - 1
    return FloorLayout(rooms=rooms, openings=openings, walls=walls, interior=interior,
                       openings_mask=openings_mask, clearance=clearance, reserved=reserved, solid=solid, owner=owner,
                       z0=z0, windows=_windows(p, rooms, skeleton.footprint),
                       furniture=np.zeros(shape, bool))
