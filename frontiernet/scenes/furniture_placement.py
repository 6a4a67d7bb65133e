"""Place furniture, door leaves, windows and ceiling lights on a procedural floor.

Items (:mod:`frontiernet.scenes.furniture`) stand against a wall, in a corner or in the
middle of a room, axis-aligned. An item is kept only if its footprint (plan pixels)
lies inside the room's free floor, leaves a small gap to other furniture, keeps out of
door clearance zones and stairs, and the room stays passable: after eroding the free
floor by the robot radius, every doorway (and stair landing) of the room is still in
one connected component, and at most ``max_cutoff_area`` m^2 of it is cut off from them. World frame: Z-up metres; plan frame as in
:mod:`frontiernet.scenes.floorplan`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .furniture import PROGRAMS, Item, make_item
from .procedural_layout import px

SINGLE_ITEMS = ("bed", "counter", "fridge", "table_set", "meeting_table", "bathtub", "toilet", "sink", "tv_unit", "rug")
_SIDES = {  # wall name -> (unit u along the wall, unit v into the room)
    "S": ((1.0, 0.0), (0.0, 1.0)), "N": ((-1.0, 0.0), (0.0, -1.0)),
    "W": ((0.0, -1.0), (1.0, 0.0)), "E": ((0.0, 1.0), (-1.0, 0.0)),
}


@dataclass
class Placed:
    """A placed item: `footprint` (4,) int64 plan rect ``[r0, c0, r1, c1)`` of its floor area."""

    name: str
    floor: int
    room: int
    footprint: np.ndarray
    blocking: bool


class Boxes:
    """Accumulates world boxes: lower/upper (3,) metres and a furniture material key each."""

    def __init__(self):
        self.lower, self.upper, self.material = [], [], []

    def add(self, item: Item, origin, eu, ev, z0: float) -> None:
        eu, ev = np.asarray(eu), np.asarray(ev)
        p0 = origin + item.parts[:, [0]] * eu + item.parts[:, [1]] * ev
        p1 = origin + item.parts[:, [3]] * eu + item.parts[:, [4]] * ev
        self.lower.append(np.column_stack([np.minimum(p0, p1), item.parts[:, 2] + z0]))
        self.upper.append(np.column_stack([np.maximum(p0, p1), item.parts[:, 5] + z0]))
        self.material += list(item.materials)

    def arrays(self):
        """(N, 3) lower and (N, 3) upper corners in metres, and (N,) material keys."""
        if not self.lower:
            return np.zeros((0, 3)), np.zeros((0, 3)), []
        return np.concatenate(self.lower), np.concatenate(self.upper), list(self.material)


def _px_rect(lo, hi, H: int, s: float) -> np.ndarray:
    """World xy box [lo, hi] metres -> plan rect covering it."""
    eps = 1e-6
    return np.array([H - int(np.ceil(hi[1] / s - eps)), int(np.floor(lo[0] / s + eps)),
                     H - int(np.floor(lo[1] / s + eps)), int(np.ceil(hi[0] / s - eps))], np.int64)


def _grow(r, k):
    return np.array([r[0] - k, r[1] - k, r[2] + k, r[3] + k])


def _window(r) -> tuple[slice, slice]:
    """The part of plan rect `r` (its negative starts clipped) as slices: a check looks at the
    pixels it covers, never at the whole plan (a 200 m building's plan has millions)."""
    return slice(max(r[0], 0), max(r[2], 0)), slice(max(r[1], 0), max(r[3], 0))


def _any(r, *masks) -> bool:
    """Whether any of `masks` is set in plan rect `r`."""
    window = _window(r)
    return any(bool(mask[window].any()) for mask in masks)


def _inside(r, box) -> bool:
    return r[0] >= box[0] and r[1] >= box[1] and r[2] <= box[2] and r[3] <= box[3]


class FloorFurnisher:
    """Places items on one :class:`~frontiernet.scenes.procedural_doors.FloorLayout`."""

    def __init__(self, rng, p, floor, floor_index: int, boxes: Boxes):
        self.rng, self.p, self.floor, self.index, self.boxes = rng, p, floor, floor_index, boxes
        self.s = p.resolution
        self.H = floor.walls.shape[0]
        self.decor = np.zeros_like(floor.walls)  # wall strips taken by windows and pictures
        self.placed: list[Placed] = []
        r = px(p.robot_radius, self.s)
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        self.disk = yy ** 2 + xx ** 2 <= r * r
        self.gap_px = px(p.furniture_gap, self.s)
        self._anchors: dict[int, list] = {}

    def world_interior(self, room):
        I, s, H = room.interior, self.s, self.H
        return I[1] * s, (H - I[2]) * s, I[3] * s, (H - I[0]) * s  # x0, y0, x1, y1

    def anchors(self, index: int) -> list:
        """Pixels (row, col) that must stay mutually reachable in room `index` (fixed once the
        floor's openings and stairs are: kept, as every item placed in the room asks again)."""
        if index in self._anchors:
            return self._anchors[index]
        out = self._anchors[index] = []
        for o in self.floor.openings:
            for side, room in enumerate((o.a, o.b)):
                if room == index:
                    z = o.clearance[side]
                    out.append(((z[0] + z[2]) // 2, (z[1] + z[3]) // 2))
        I = self.floor.rooms[index].interior
        window = _window(I)
        rows, cols = np.nonzero(self.floor.reserved[window] & ~self.floor.solid[window])
        if len(rows):
            out.append((I[0] + int(rows.mean()), I[1] + int(cols.mean())))
        return out

    def passable(self, index: int, extra=None) -> bool:
        I = self.floor.rooms[index].interior
        window = _window(I)
        blocked = self.floor.furniture[window] | self.floor.solid[window]
        if extra is not None:
            blocked[max(extra[0] - I[0], 0):max(extra[2] - I[0], 0), max(extra[1] - I[1], 0):max(extra[3] - I[1], 0)] = True
        free = ndimage.binary_erosion(~blocked, self.disk, border_value=0)
        labels, _ = ndimage.label(free)
        ids = {int(labels[r - I[0], c - I[1]]) for r, c in self.anchors(index)}
        if 0 in ids or len(ids) > 1:
            return False
        if not ids:
            return True
        cut_off = int(free.sum()) - int((labels == ids.pop()).sum())
        return cut_off * self.s ** 2 <= self.p.max_cutoff_area

    def try_place(self, index: int, item: Item, origin, eu, ev, mount=False) -> bool:
        eu_, ev_ = np.asarray(eu), np.asarray(ev)
        corners = [origin + u * eu_ + v * ev_ for u in (0, item.width) for v in (0, item.depth)]
        rect = _px_rect(np.min(corners, 0), np.max(corners, 0), self.H, self.s)
        room, f = self.floor.rooms[index], self.floor
        if not _inside(rect, room.interior):
            return False
        if mount:
            if _any(rect, f.furniture, f.clearance, self.decor):
                return False
        elif item.blocking:
            if _any(rect, f.clearance, f.reserved) or _any(_grow(rect, self.gap_px), f.furniture):
                return False
            if not self.passable(index, rect):
                return False
        if mount:
            self.decor[rect[0]:rect[2], rect[1]:rect[3]] = True
        elif item.blocking:
            f.furniture[rect[0]:rect[2], rect[1]:rect[3]] = True
        self.boxes.add(item, origin, eu, ev, f.z0)
        self.placed.append(Placed(item.name, self.index, index, rect, item.blocking and not mount))
        return True

    def wall_frame(self, room, side: str, t: float, gap: float):
        x0, y0, x1, y1 = self.world_interior(room)
        start = {"S": (x0 + t, y0 + gap), "N": (x1 - t, y1 - gap), "W": (x0 + gap, y1 - t), "E": (x1 - gap, y0 + t)}
        return np.array(start[side]), *_SIDES[side]

    def wall_length(self, room, side: str) -> float:
        x0, y0, x1, y1 = self.world_interior(room)
        return x1 - x0 if side in "SN" else y1 - y0

    def place(self, index: int, item: Item, mode: str, tries: int = 25) -> bool:
        room, rng = self.floor.rooms[index], self.rng
        if mode == "middle":
            x0, y0, x1, y1 = self.world_interior(room)
            along_x = (x1 - x0) >= (y1 - y0)
            eu, ev = ((1.0, 0.0), (0.0, 1.0)) if along_x else ((0.0, 1.0), (-1.0, 0.0))
            margin = 0.3 if not item.blocking else 0.55
            for _ in range(tries // 3):
                centre = np.array([(x0 + x1) / 2 + rng.uniform(-0.15, 0.15) * (x1 - x0),
                                   (y0 + y1) / 2 + rng.uniform(-0.15, 0.15) * (y1 - y0)])
                origin = centre - item.width / 2 * np.asarray(eu) - item.depth / 2 * np.asarray(ev)
                half = np.abs(np.asarray(eu)) * item.width / 2 + np.abs(np.asarray(ev)) * item.depth / 2
                if np.any(centre - half < np.array([x0, y0]) + margin) or np.any(centre + half > np.array([x1, y1]) - margin):
                    continue
                if self.try_place(index, item, origin, eu, ev):
                    return True
            return False
        sides = [k for k in "SNWE" if self.wall_length(room, k) >= item.width + 0.05]
        if not sides:
            return False
        weights = np.array([self.wall_length(room, k) for k in sides])
        gap = 0.0 if mode == "mount" else self.p.furniture_wall_gap
        for _ in range(tries):
            side = sides[int(rng.choice(len(sides), p=weights / weights.sum()))]
            free = self.wall_length(room, side) - item.width - 2 * gap
            if free < 0:
                continue
            t = gap + (float(rng.choice([0.0, free])) if mode == "corner" else rng.uniform(0, free))
            origin, eu, ev = self.wall_frame(room, side, t, gap)
            if mode == "mount" and not self.solid_wall_behind(room, side, t, item.width):
                continue
            if self.try_place(index, item, origin, eu, ev, mount=(mode == "mount")):
                return True
        return False

    def solid_wall_behind(self, room, side, t, width) -> bool:
        I, s = room.interior, self.s
        origin, eu, _ = self.wall_frame(room, side, t, 0.0)
        a, b = origin, origin + width * np.asarray(eu)
        rect = _px_rect(np.minimum(a, b), np.maximum(a, b), self.H, s)
        row_or_col = {"S": (I[2], I[2] + 1, rect[1], rect[3]), "N": (I[0] - 1, I[0], rect[1], rect[3]),
                      "W": (rect[0], rect[2], I[1] - 1, I[1]), "E": (rect[0], rect[2], I[3], I[3] + 1)}[side]
        r0, r1, c0, c1 = row_or_col
        return bool(self.floor.walls[r0:r1, c0:c1].all())

    def door_leaves(self, door_height: float) -> None:
        s, f = self.s, self.floor
        for o in f.openings:
            if not o.door or self.rng.random() > self.p.door_leaf_probability:
                continue
            width = o.rect[3] - o.rect[1] if o.axis == 0 else o.rect[2] - o.rect[0]
            for side, hinge in self.rng.permutation([(0, 0), (0, 1), (1, 0), (1, 1)]).tolist():
                z = o.clearance[side]
                room = (o.a, o.b)[side]
                I = f.rooms[room].interior
                across = (I[2] if side == 0 else I[0], width) if o.axis == 0 else (I[3] if side == 0 else I[1], width)
                a0 = across[0] - width if side == 0 else across[0]
                al = (z[1] if hinge == 0 else z[3] - 1) if o.axis == 0 else (z[0] if hinge == 0 else z[2] - 1)
                rect = np.array([a0, al, a0 + width, al + 1] if o.axis == 0 else [al, a0, al + 1, a0 + width])
                near = _grow(rect, 1)
                rows, cols = _window(near)
                others = f.clearance[rows, cols].copy()  # the other openings' zones: this one's is cleared
                others[max(z[0] - rows.start, 0):max(z[2] - rows.start, 0),
                       max(z[1] - cols.start, 0):max(z[3] - cols.start, 0)] = False
                if not _inside(rect, I) or _any(near, f.furniture, f.reserved) or others.any():
                    continue
                lo = np.array([rect[1] * s, (self.H - rect[2]) * s])
                hi = np.array([rect[3] * s, (self.H - rect[0]) * s])
                thin = 0 if o.axis == 0 else 1  # the 1-pixel dimension in world x (0) or y (1)
                lo[thin] += 0.005
                hi[thin] -= 0.005
                leaf = make_item("door", [(0, 0, 0, hi[0] - lo[0], hi[1] - lo[1], door_height - 0.01, "door")])
                if not self.passable(room, rect):
                    continue
                f.furniture[rect[0]:rect[2], rect[1]:rect[3]] = True
                self.boxes.add(leaf, lo, (1.0, 0.0), (0.0, 1.0), f.z0)
                self.placed.append(Placed("door", self.index, room, rect, True))
                break

    def windows(self, wall_height: float) -> None:
        s = self.s
        names = {(0, -1): "N", (0, 1): "S", (1, -1): "W", (1, 1): "E"}
        for room_index, axis, side, a0, a1 in self.floor.windows:
            room = self.floor.rooms[room_index]
            name = names[(axis, side)]
            x0, y0, x1, y1 = self.world_interior(room)
            t = {"S": a0 * s - x0, "N": x1 - a1 * s, "W": y1 - (self.H - a0) * s, "E": (self.H - a1) * s - y0}[name]
            w = (a1 - a0) * s
            sill, top = self.rng.uniform(0.8, 1.0), min(2.2, wall_height - 0.25)
            boxes = [(0, 0, sill, w, 0.015, sill + 0.05, "window_frame"), (0, 0, top - 0.05, w, 0.015, top, "window_frame"),
                     (0, 0, sill, 0.05, 0.015, top, "window_frame"), (w - 0.05, 0, sill, w, 0.015, top, "window_frame"),
                     (0.05, 0, sill + 0.05, w - 0.05, 0.008, top - 0.05, "glass")]
            if w > 1.1:
                boxes.append((w / 2 - 0.025, 0, sill, w / 2 + 0.025, 0.015, top, "window_frame"))
            origin, eu, ev = self.wall_frame(room, name, t, 0.0)
            self.try_place(room_index, make_item("window", boxes, blocking=False), origin, eu, ev, mount=True)

    def lights(self, wall_height: float) -> None:
        for index, room in enumerate(self.floor.rooms):
            x0, y0, x1, y1 = self.world_interior(room)
            count = 1 + int(max(x1 - x0, y1 - y0) > 5.0)
            for k in range(count):
                c = np.array([x0 + (x1 - x0) * ((k + 0.5) / count if x1 - x0 >= y1 - y0 else 0.5),
                              y0 + (y1 - y0) * ((k + 0.5) / count if x1 - x0 < y1 - y0 else 0.5)])
                size = 0.5 if room.kind != "corridor" else 0.3
                rect = _px_rect(c - size / 2, c + size / 2, self.H, self.s)
                if _any(_grow(rect, 4), self.floor.solid, self.floor.reserved):
                    continue
                light = make_item("light", [(0, 0, wall_height - 0.04, size, size, wall_height, "light")], blocking=False)
                self.boxes.add(light, c - size / 2, (1.0, 0.0), (0.0, 1.0), self.floor.z0)

    def furnish(self, density: float) -> None:
        """Run each room's program; large rooms get further passes of the repeatable items."""
        for index, room in enumerate(self.floor.rooms):
            x0, y0, x1, y1 = self.world_interior(room)
            passes = 1 if room.kind == "corridor" else 1 + min(2, int((x1 - x0) * (y1 - y0) / 25.0))
            for repeat in range(passes):
                for factory, mode, probability in PROGRAMS.get(room.kind, []):
                    if repeat and factory.__name__ in SINGLE_ITEMS:
                        continue
                    if self.rng.random() >= min(1.0, probability * density * (0.6 if repeat else 1.0)):
                        continue
                    self.place(index, factory(self.rng, max(x1 - x0, y1 - y0)), mode)
