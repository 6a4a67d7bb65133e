"""Furniture catalogue for procedural scenes: items built from boxes, room programs, materials.

An :class:`Item` is described in its own frame, metres: ``u`` along the wall it stands
against (0..width), ``v`` away from that wall into the room (0..depth), ``z`` up from
the floor (every floor-standing item touches z = 0). Placement
(:mod:`frontiernet.scenes.furniture_placement`) maps ``(u, v)`` to world x, y.
Dimensions are typical catalogue sizes of home and office furniture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .builder import MeshBuilder, make_texture
from .scene import Material


@dataclass
class Item:
    """A piece of furniture: `parts` is (N, 6) float64 ``[u0, v0, z0, u1, v1, z1]`` metres
    with `materials` (N,) keys into the furniture palette; `blocking` False for rugs and
    wall-mounted things (pictures, whiteboards) that do not occupy floor space."""

    name: str
    parts: np.ndarray
    materials: list
    blocking: bool = True

    @property
    def width(self) -> float:
        return float(self.parts[:, 3].max())

    @property
    def depth(self) -> float:
        return float(self.parts[:, 4].max())


def make_item(name, boxes, blocking=True) -> Item:
    parts = np.array([b[:6] for b in boxes], np.float64)
    parts[:, [0, 3]] -= parts[:, 0].min()
    parts[:, [1, 4]] -= parts[:, 1].min()
    return Item(name, parts, [b[6] for b in boxes], blocking)


def _legs(u0, v0, u1, v1, z1, m, t=0.05):
    return [(u0, v0, 0, u0 + t, v0 + t, z1, m), (u1 - t, v0, 0, u1, v0 + t, z1, m),
            (u0, v1 - t, 0, u0 + t, v1, z1, m), (u1 - t, v1 - t, 0, u1, v1, z1, m)]


def _chair(cu, v0, facing_plus_v: bool, m="fabric"):
    """A chair 0.46 m wide centred at u=cu, occupying v in [v0, v0+0.48]; its back away from the table."""
    back = (v0 + 0.42, v0 + 0.48) if facing_plus_v is False else (v0, v0 + 0.06)
    return (_legs(cu - 0.22, v0, cu + 0.22, v0 + 0.46, 0.44, "metal", 0.03)
            + [(cu - 0.23, v0, 0.44, cu + 0.23, v0 + 0.48, 0.49, m),
               (cu - 0.23, back[0], 0.49, cu + 0.23, back[1], 0.92, m)])


def bed(rng, room_w):
    w = float(rng.choice([0.9, 1.4, 1.6, 1.8] if room_w > 2.6 else [0.9]))
    d = 2.05
    boxes = [(0, 0.06, 0, w, d, 0.32, "wood"), (0, 0, 0, w, 0.06, rng.uniform(0.9, 1.2), "wood"),
             (0.03, 0.08, 0.32, w - 0.03, d - 0.03, 0.52, "bedding"), (0, 0.75, 0.3, w, d, 0.55, "fabric")]
    for k in range(1 if w < 1.2 else 2):
        u0 = 0.1 + k * w / 2
        boxes.append((u0, 0.12, 0.52, u0 + (w - 0.2 if w < 1.2 else w / 2 - 0.2), 0.5, 0.64, "white"))
    if rng.random() < 0.7 and room_w > w + 1.2:  # nightstands either side
        boxes = [(b[0] + 0.5, *b[1:3], b[3] + 0.5, *b[4:]) for b in boxes]
        for u0 in (0.0, w + 0.55):
            boxes += [(u0, 0, 0, u0 + 0.45, 0.4, 0.55, "wood2"), (u0 + 0.15, 0.12, 0.55, u0 + 0.3, 0.27, 0.78, "white")]
    return make_item("bed", boxes)


def wardrobe(rng, room_w):
    w, h = rng.uniform(0.9, 2.0), rng.uniform(1.9, 2.2)
    boxes = [(0, 0, 0, w, 0.6, h, "cabinet")]
    for k in range(max(1, int(w / 0.5))):
        u = (k + 0.5) * w / max(1, int(w / 0.5))
        boxes.append((u - 0.01, 0.6, 0.9, u + 0.01, 0.62, 1.2, "metal"))
    return make_item("wardrobe", boxes)


def desk(rng, room_w, monitor=None):
    w, d = rng.uniform(1.1, 1.6), 0.7
    boxes = [(0, 0, 0.72, w, d, 0.75, "wood")] + _legs(0, 0, w, d, 0.72, "metal")
    if monitor or (monitor is None and rng.random() < 0.5):
        boxes += [(w / 2 - 0.3, 0.12, 0.85, w / 2 + 0.3, 0.16, 1.2, "screen"),
                  (w / 2 - 0.04, 0.14, 0.75, w / 2 + 0.04, 0.2, 0.85, "dark")]
    boxes += _chair(w / 2 + rng.uniform(-0.15, 0.15), d + 0.05, False)
    return make_item("desk", boxes)


def sofa(rng, room_w, w=None):
    w = w or rng.uniform(1.6, 2.4)
    m = "fabric"
    return make_item("sofa", [(0, 0, 0.05, w, 0.92, 0.42, m), (0, 0, 0.05, w, 0.22, 0.85, m),
                          (0, 0, 0.05, 0.18, 0.92, 0.62, m), (w - 0.18, 0, 0.05, w, 0.92, 0.62, m),
                          (0.18, 0.22, 0.42, w - 0.18, 0.9, 0.5, "fabric2")]
                 + _legs(0.02, 0.02, w - 0.02, 0.9, 0.05, "dark", 0.04))


def armchair(rng, room_w):
    item = sofa(rng, room_w, w=0.85)
    item.name = "armchair"
    return item


def coffee_table(rng, room_w):
    w, d, h = rng.uniform(0.9, 1.2), rng.uniform(0.5, 0.65), rng.uniform(0.38, 0.46)
    return make_item("coffee_table", [(0, 0, h - 0.04, w, d, h, "wood2")] + _legs(0, 0, w, d, h - 0.04, "wood2"))


def tv_unit(rng, room_w):
    w = rng.uniform(1.2, 1.8)
    tv = rng.uniform(0.9, min(1.4, w))
    return make_item("tv_unit", [(0, 0, 0, w, 0.42, 0.5, "cabinet"), (w / 2 - 0.12, 0.1, 0.5, w / 2 + 0.12, 0.26, 0.53, "dark"),
                             (w / 2 - tv / 2, 0.14, 0.53, w / 2 + tv / 2, 0.19, 0.53 + tv * 0.58, "screen")])


def bookshelf(rng, room_w):
    w, h, d = rng.uniform(0.8, 1.6), rng.uniform(1.7, 2.1), 0.35
    boxes = [(0, 0, 0, w, 0.02, h, "wood"), (0, 0, 0, 0.03, d, h, "wood"), (w - 0.03, 0, 0, w, d, h, "wood")]
    shelves = int(rng.integers(4, 7))
    for k in range(shelves + 1):
        z = k * (h - 0.03) / shelves
        boxes.append((0.03, 0.02, z, w - 0.03, d, z + 0.03, "wood"))
        if k < shelves and rng.random() < 0.8:
            u0 = rng.uniform(0.04, w / 3)
            u1 = rng.uniform(u0 + 0.15, w - 0.04)
            top = z + 0.03 + (h / shelves - 0.03) * rng.uniform(0.55, 0.85)
            boxes.append((u0, 0.05, z + 0.03, u1, d - 0.05, top, f"book{int(rng.integers(4))}"))
    return make_item("bookshelf", boxes)


def sideboard(rng, room_w):
    w, h = rng.uniform(1.0, 1.8), rng.uniform(0.75, 0.9)
    return make_item("sideboard", [(0, 0, 0.08, w, 0.45, h, "cabinet")] + _legs(0.03, 0.03, w - 0.03, 0.42, 0.08, "dark", 0.04)
                 + [(w * 0.2, 0.15, h, w * 0.2 + 0.2, 0.35, h + 0.3, "pot")])


def counter(rng, room_w):
    w = min(room_w - 0.75, rng.uniform(1.8, 4.2))
    sink = rng.uniform(0.2, max(0.3, w - 0.8))
    hob = (sink + 0.9) if sink + 1.6 < w else max(0.1, sink - 0.8)
    boxes = [(0, 0, 0.1, w, 0.6, 0.86, "cabinet"), (0, 0, 0, w, 0.52, 0.1, "dark"),
             (0, 0, 0.86, w, 0.63, 0.9, "counter"), (0, 0, 1.45, w, 0.35, 2.15, "cabinet"),
             (sink, 0.1, 0.9, sink + 0.55, 0.5, 0.905, "metal"), (sink + 0.25, 0.04, 0.9, sink + 0.3, 0.1, 1.2, "metal")]
    if 0 <= hob and hob + 0.6 <= w:
        boxes.append((hob, 0.08, 0.9, hob + 0.6, 0.56, 0.91, "dark"))
    return make_item("counter", boxes)


def fridge(rng, room_w):
    h = rng.uniform(1.75, 2.0)
    return make_item("fridge", [(0, 0, 0, 0.7, 0.68, h, "appliance"), (0.6, 0.68, 0.9, 0.63, 0.7, 1.5, "metal")])


def table_set(rng, room_w, name="dining", length=(1.2, 2.0), depth=(0.8, 1.0)):
    w = min(rng.uniform(*length), max(length[0], room_w - 1.6))
    d = rng.uniform(*depth)
    boxes = [(0.5, 0.55, 0.72, 0.5 + w, 0.55 + d, 0.76, "wood")] + _legs(0.52, 0.57, 0.48 + w, 0.53 + d, 0.72, "wood")
    per_side = max(1, int(w / 0.65))
    for k in range(per_side):
        cu = 0.5 + (k + 0.5) * w / per_side
        boxes += _chair(cu, 0.05, True) + _chair(cu, 0.57 + d, False)
    if w > 1.4 and rng.random() < 0.6:  # chairs at the ends, rotated by swapping u and v
        for end in (0.0, w + 0.52):
            c = _chair(0.55 + d / 2, end, end == 0.0)
            boxes += [(b[1], b[0], b[2], b[4], b[3], b[5], b[6]) for b in c]
    return make_item(name, boxes)


def meeting_table(rng, room_w):
    return table_set(rng, room_w, "meeting_table", (2.0, 3.6), (1.0, 1.3))


def bathtub(rng, room_w):
    w = rng.uniform(1.5, 1.75)
    return make_item("bathtub", [(0, 0, 0, w, 0.75, 0.56, "ceramic"), (0.08, 0.08, 0.5, w - 0.08, 0.67, 0.565, "water")])


def toilet(rng, room_w):
    return make_item("toilet", [(0.02, 0, 0, 0.38, 0.2, 0.8, "ceramic"), (0.04, 0.15, 0, 0.36, 0.68, 0.42, "ceramic"),
                            (0.03, 0.18, 0.42, 0.37, 0.68, 0.45, "white")])


def sink(rng, room_w):
    w = rng.uniform(0.6, 1.0)
    return make_item("sink", [(0, 0, 0, w, 0.48, 0.82, "cabinet"), (0, 0, 0.82, w, 0.5, 0.87, "ceramic"),
                          (w / 2 - 0.02, 0.03, 0.87, w / 2 + 0.02, 0.12, 1.05, "metal"),
                          (0.05, 0, 1.15, w - 0.05, 0.015, 1.85, "mirror")])


def shelving(rng, room_w):
    w, h, d = rng.uniform(0.9, 1.8), rng.uniform(1.8, 2.1), 0.45
    boxes = [(u, v, 0, u + 0.04, v + 0.04, h, "metal") for u in (0, w - 0.04) for v in (0, d - 0.04)]
    for k in range(5):
        z = 0.1 + k * (h - 0.15) / 4
        boxes.append((0, 0, z, w, d, z + 0.03, "metal"))
        if k < 4 and rng.random() < 0.7:
            u0 = rng.uniform(0.05, w / 2)
            boxes.append((u0, 0.05, z + 0.03, min(w - 0.05, u0 + rng.uniform(0.3, 0.6)), d - 0.05,
                          z + 0.03 + rng.uniform(0.15, 0.3), "cardboard"))
    return make_item("shelving", boxes)


def filing_cabinet(rng, room_w):
    return make_item("filing_cabinet", [(0, 0, 0, 0.45, 0.6, rng.uniform(0.7, 1.3), "metal")])


def plant(rng, room_w):
    top = rng.uniform(0.9, 1.6)
    return make_item("plant", [(0.08, 0.08, 0, 0.42, 0.42, 0.4, "pot"), (0, 0, 0.4, 0.5, 0.5, top, "leaf")])


def floor_lamp(rng, room_w):
    return make_item("floor_lamp", [(0, 0, 0, 0.3, 0.3, 0.03, "dark"), (0.13, 0.13, 0.03, 0.17, 0.17, 1.45, "metal"),
                                (0.02, 0.02, 1.4, 0.28, 0.28, 1.65, "shade")])


def bench(rng, room_w):
    w = rng.uniform(1.0, 1.5)
    return make_item("bench", [(0, 0, 0.4, w, 0.4, 0.45, "wood")] + _legs(0, 0, w, 0.4, 0.4, "dark"))


def dresser(rng, room_w):
    w, h = rng.uniform(0.9, 1.4), rng.uniform(0.8, 1.0)
    return make_item("dresser", [(0, 0, 0, w, 0.5, h, "wood2"), (0.1, 0, h + 0.3, w - 0.1, 0.015, h + 0.9, "mirror")])


def rug(rng, room_w):
    w, d = rng.uniform(1.4, 2.6), rng.uniform(1.0, 1.8)
    return make_item("rug", [(0, 0, 0, w, d, 0.012, "rug")], blocking=False)


def picture(rng, room_w):
    w, h = rng.uniform(0.4, 1.2), rng.uniform(0.4, 0.9)
    z = rng.uniform(1.2, 1.5)
    return make_item("picture", [(0, 0, z, w, 0.02, z + h, "frame"), (0.04, 0.02, z + 0.04, w - 0.04, 0.025, z + h - 0.04,
                                                                   f"art{int(rng.integers(3))}")], blocking=False)


def whiteboard(rng, room_w):
    w = rng.uniform(1.2, 2.4)
    return make_item("whiteboard", [(0, 0, 0.9, w, 0.02, 2.0, "metal"), (0.03, 0.02, 0.93, w - 0.03, 0.025, 1.97, "white")],
                 blocking=False)


# Room programs: (item factory, placement, probability). Placement "wall" stands the item
# against a wall, "corner" against a wall at a corner, "middle" away from the walls,
# "mount" hangs it on a wall. Probabilities are scaled by the furniture density.
PROGRAMS = {
    "living": [(sofa, "wall", 1.0), (rug, "middle", 0.6), (coffee_table, "middle", 0.8), (tv_unit, "wall", 0.8),
               (armchair, "wall", 0.6), (bookshelf, "wall", 0.6), (sideboard, "wall", 0.4), (plant, "corner", 0.7),
               (floor_lamp, "corner", 0.5), (plant, "corner", 0.4), (picture, "mount", 0.8), (picture, "mount", 0.5)],
    "kitchen": [(counter, "corner", 1.0), (fridge, "corner", 0.9), (counter, "wall", 0.4), (table_set, "middle", 0.6),
                (plant, "corner", 0.3)],
    "dining": [(table_set, "middle", 1.0), (sideboard, "wall", 0.7), (bookshelf, "wall", 0.3), (plant, "corner", 0.5),
               (picture, "mount", 0.7)],
    "bedroom": [(bed, "wall", 1.0), (wardrobe, "wall", 0.8), (desk, "wall", 0.4), (dresser, "wall", 0.4),
                (rug, "middle", 0.3), (plant, "corner", 0.3), (picture, "mount", 0.6)],
    "bathroom": [(bathtub, "corner", 0.8), (toilet, "wall", 1.0), (sink, "wall", 1.0), (shelving, "wall", 0.2)],
    "closet": [(shelving, "wall", 1.0), (shelving, "wall", 0.6), (wardrobe, "wall", 0.3)],
    "office": [(desk, "wall", 1.0), (desk, "wall", 0.6), (desk, "wall", 0.4), (bookshelf, "wall", 0.6),
               (filing_cabinet, "wall", 0.6), (filing_cabinet, "corner", 0.3), (plant, "corner", 0.4),
               (whiteboard, "mount", 0.3)],
    "meeting": [(meeting_table, "middle", 1.0), (sideboard, "wall", 0.4), (plant, "corner", 0.6),
                (whiteboard, "mount", 0.8), (plant, "corner", 0.3)],
    "hall": [(plant, "corner", 0.9), (sofa, "wall", 0.6), (coffee_table, "middle", 0.5), (bench, "wall", 0.5),
             (plant, "corner", 0.7), (bookshelf, "wall", 0.4), (sofa, "wall", 0.4), (picture, "mount", 0.7)],
    "corridor": [(plant, "corner", 0.4), (bench, "wall", 0.25), (picture, "mount", 0.6), (picture, "mount", 0.4)],
    "stairs": [(plant, "corner", 0.5), (picture, "mount", 0.4)],
}

_WOODS = [(176, 132, 88), (140, 98, 62), (205, 170, 125), (110, 75, 50), (190, 160, 120)]
_FABRICS = [(120, 130, 150), (150, 70, 60), (90, 110, 90), (200, 190, 170), (70, 80, 100), (160, 140, 110),
            (110, 90, 120), (60, 60, 65), (180, 120, 60)]
_PLAIN = {"white": (235, 235, 230), "metal": (160, 162, 168), "dark": (45, 45, 48), "ceramic": (240, 240, 238),
          "screen": (20, 22, 28), "mirror": (190, 205, 215), "water": (200, 220, 230), "leaf": (60, 120, 55),
          "pot": (170, 95, 60), "shade": (240, 230, 200), "frame": (60, 45, 35), "cardboard": (190, 150, 100),
          "glass": (175, 205, 230), "window_frame": (240, 240, 240), "light": (255, 255, 250),
          "appliance": (220, 222, 225)}


def furniture_materials(builder: MeshBuilder, rng: np.random.Generator, texture_px: int) -> dict[str, int]:
    """Register one building's furniture palette (woods, fabrics, plain colours); key -> material id."""
    def pick(options):
        base = np.asarray(options[int(rng.integers(len(options)))], np.float64)
        return np.clip(base * rng.uniform(0.85, 1.15), 0, 255).astype(np.uint8)

    ids = {}
    for key, kind, options in (("wood", "wood", _WOODS), ("wood2", "wood", _WOODS), ("fabric", "fabric", _FABRICS),
                               ("fabric2", "fabric", _FABRICS), ("bedding", "fabric", [(230, 228, 220), (200, 210, 225)]),
                               ("rug", "carpet", _FABRICS), ("counter", "marble", [(225, 222, 215), (80, 80, 85)]),
                               ("door", "wood", [(235, 230, 220), (176, 132, 88), (140, 98, 62)]),
                               ("cabinet", "plaster", [(240, 240, 235), (176, 132, 88), (120, 130, 125), (60, 62, 70)])):
        color = pick(options)
        ids[key] = builder.material(Material(f"furniture-{key}", color, make_texture(kind, rng, color, texture_px)))
    for k in range(4):
        ids[f"book{k}"] = builder.material(Material(f"furniture-book{k}", pick(_FABRICS)))
    for k in range(3):
        color = pick(_FABRICS)
        ids[f"art{k}"] = builder.material(Material(f"furniture-art{k}", color, make_texture("concrete", rng, color, 32)))
    for key, color in _PLAIN.items():
        ids[key] = builder.material(Material(f"furniture-{key}", color))
    return ids
