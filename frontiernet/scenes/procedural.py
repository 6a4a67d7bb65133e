"""``procedural:<seed>`` scenes: seeded multi-room buildings, the library's built-in scenes.

Pipeline (all randomness from ``np.random.default_rng([seed, stream])``, no global state):

1. :mod:`.procedural_layout`: a footprint (rectangle, L or U), a corridor spine, regions
   cut into rooms by recursive splitting, room kinds by size; optionally a stair room.
2. :mod:`.procedural_doors`: walls along the room borders, doors and open-plan openings on
   a random spanning tree of the room adjacency (plus loops), windows, the stair flight.
3. :mod:`.furniture_placement`: door leaves, windows, furniture per room kind, lights,
   never in front of doors and never cutting the room's free space apart.
4. This module: extrude the plan per room with per-room floor/wall textures
   (:func:`frontiernet.scenes.builder.mask_rectangles`), add stairs, slab, ceiling.

World frame: Z-up, metres; the ground floor's top is z = 0; a second floor's top is at
``wall_height + slab_thickness``. Plan pixels map to world x, y as in
:mod:`frontiernet.scenes.floorplan`. Options: the ``procedural`` section of
``configs/scenes.yaml``.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy import ndimage

from ..config import check_ranges
from ..errors import InputError
from .builder import MeshBuilder, make_texture, mask_rectangles, rect_boxes
from .furniture import furniture_materials
from .furniture_placement import Boxes, FloorFurnisher, Placed
from .procedural_doors import FloorLayout, Stair, make_floor, make_stair, wall_split
from .procedural_layout import Room, Skeleton, assign_kinds, make_skeleton, split_rooms
from .scene import Material, Scene, SceneMetadata


@dataclass
class ProceduralLayout:
    """Everything drawn for one seed before meshing (plan pixels unless stated).

    Attributes:
        params: validated options (attributes, metres).
        skeleton: footprint, corridors, regions (:class:`~.procedural_layout.Skeleton`).
        floors: one :class:`~.procedural_doors.FloorLayout` per storey, ground first.
        stair: the flight between floors 0 and 1, or None.
        wall_height, door_height: metres.
        furniture: (N, 3) lower / (N, 3) upper world corners (metres) and N material keys.
        placed: list of :class:`~.furniture_placement.Placed` (item footprints).
    """

    params: SimpleNamespace
    skeleton: Skeleton
    floors: list
    stair: Stair | None
    wall_height: float
    door_height: float
    furniture: tuple
    placed: list


def validate_options(conf, spec_text: str = "procedural") -> SimpleNamespace:
    """Check the ``procedural`` options against their declared ranges and relations
    (``configs/ranges/scenes.yaml``: a min at most its max, a lintel above every door, ...); returns them as
    attributes. Raises InputError naming the option (`spec_text` first)."""
    values = {str(k): conf[k] for k in conf.keys()}
    try:
        check_ranges(values, {"": "scenes.procedural"})
    except InputError as error:
        raise InputError(f"{spec_text}: option {error}") from None
    for key in ("texture_pixels", "rooms_min", "rooms_max", "max_attempts"):
        values[key] = int(values[key])
    if values["texture_pixels"] % 4:  # the brick and tile patterns divide it in quarters
        raise InputError(f"{spec_text}: option texture_pixels must be a multiple of 4, got {values['texture_pixels']}")
    return SimpleNamespace(**values)


def generate_layout(seed: int, conf, spec_text: str = "procedural") -> ProceduralLayout:
    """Draw the building of `seed` (deterministic). Raises InputError if no layout can be made."""
    p = validate_options(conf, spec_text)
    rng = np.random.default_rng([seed, 0])
    for _ in range(p.max_attempts):
        layout = _attempt(rng, p, seed)
        if layout is not None:
            return layout
    changed = _changed_options(p)
    if changed:  # (the option given is what leaves no building, more often than the footprint)
        them = "it" if len(changed) == 1 else "them"
        raise InputError(f"{spec_text}: no valid building after {p.max_attempts} attempts with "
                         f"{' and '.join(changed)}: no plan fits with {them}; bring {them} nearer the shipped "
                         "value (configs/scenes.yaml), or widen the footprint or room size options")
    raise InputError(f"{spec_text}: no valid building after {p.max_attempts} attempts; "
                     "widen the footprint or room size options")


def _changed_options(p: SimpleNamespace) -> list[str]:
    """``key=value (shipped: default)`` for each option of `p` (validated options) that differs from the
    shipped ``procedural`` section of ``configs/scenes.yaml`` (max_attempts aside)."""
    from ..config import load_config

    shipped = load_config("scenes").procedural
    return [f"{key}={value!r} (shipped: {shipped[key]!r})" for key, value in vars(p).items()
            if key in shipped and key != "max_attempts" and value != shipped[key]]


def _attempt(rng, p, seed: int) -> ProceduralLayout | None:
    two = p.floors == 2 or (p.floors is None and rng.random() < p.second_floor_probability)
    target = int(rng.integers(p.rooms_min, p.rooms_max + 1))
    skeleton = make_skeleton(rng, p, two, target)
    if skeleton is None:
        return None
    wall_height = float(rng.uniform(p.wall_height_min, p.wall_height_max))
    door_height = float(rng.uniform(p.door_height_min, p.door_height_max))
    storey = wall_height + p.slab_thickness
    floors, stair = [], None
    for index in range(2 if two else 1):
        rects = [np.asarray(c) for c in skeleton.corridors]
        kinds = ["corridor"] * len(rects)
        cells = split_rooms(rng, p, skeleton.regions, max(1, target - len(rects) - (skeleton.stair_rect is not None)))
        rects += cells
        kinds += assign_kinds(rng, cells, skeleton.building_kind, index, p.resolution)
        if skeleton.stair_rect is not None:
            rects.append(np.asarray(skeleton.stair_rect))
            kinds.append("stairs")
        if len(rects) < 4:
            return None
        if index == 0 and two:
            _, w_lo, w_hi = wall_split(p)
            r = np.asarray(skeleton.stair_rect)
            room = Room(rect=r, kind="stairs", interior=r + np.array([w_lo, w_lo, -w_hi, -w_hi]))
            stair = make_stair(rng, p, room, storey)
        floor = make_floor(rng, p, skeleton, rects, kinds, z0=index * storey, wall_height=wall_height,
                           door_height=door_height, stair=stair, upper=index == 1)
        if floor is None:
            return None
        floors.append(floor)
    furniture_rng = np.random.default_rng([seed, 1])
    boxes, placed = Boxes(), []
    for index, floor in enumerate(floors):
        furnisher = FloorFurnisher(furniture_rng, p, floor, index, boxes)
        if not all(furnisher.passable(i) for i in range(len(floor.rooms))):
            return None
        furnisher.door_leaves(door_height)
        furnisher.windows(wall_height)
        furnisher.furnish(p.furniture_density)
        if p.ceiling or index + 1 < len(floors):
            furnisher.lights(wall_height)
        placed += furnisher.placed
    return ProceduralLayout(p, skeleton, floors, stair, wall_height, door_height, boxes.arrays(), placed)


_FLOORS = {  # room kind -> (texture kind, base colours)
    "wood": [(176, 132, 88), (150, 105, 70), (200, 165, 120), (120, 85, 60)],
    "carpet": [(150, 140, 125), (110, 115, 130), (170, 160, 150), (120, 100, 95), (90, 95, 105)],
    "tiles": [(225, 225, 220), (190, 185, 175), (170, 120, 90), (150, 160, 170), (90, 90, 95)],
    "concrete": [(150, 150, 148), (125, 125, 120)],
    "marble": [(230, 228, 222), (200, 195, 185)],
    "parquet": [(180, 135, 90), (150, 110, 75)],
}
_FLOOR_KINDS = {"living": ["wood", "parquet", "carpet"], "kitchen": ["tiles", "tiles", "wood"],
                "dining": ["wood", "parquet"], "bedroom": ["wood", "carpet", "parquet"], "bathroom": ["tiles"],
                "closet": ["wood", "concrete"], "office": ["carpet", "carpet", "concrete", "wood"],
                "meeting": ["carpet", "wood"], "hall": ["marble", "tiles", "wood"],
                "corridor": ["wood", "tiles", "marble", "carpet"], "stairs": ["wood", "concrete", "tiles"]}
_WALL_COLOURS = [(235, 232, 222), (240, 240, 236), (220, 212, 195), (200, 210, 215), (215, 200, 185),
                 (190, 205, 185), (225, 215, 170), (205, 190, 200), (180, 185, 190), (238, 228, 210)]


def _room_materials(builder: MeshBuilder, rng, p, floor_index: int, room_index: int, kind: str) -> tuple[int, int]:
    """(floor id, wall id) of a fresh per-room pair of textured materials."""
    texture_kind = _FLOOR_KINDS.get(kind, ["wood"])[int(rng.integers(len(_FLOOR_KINDS.get(kind, ["wood"]))))]
    options = _FLOORS[texture_kind]
    colour = np.clip(np.asarray(options[int(rng.integers(len(options)))]) * rng.uniform(0.9, 1.1, 3), 0, 255)
    name = f"f{floor_index}-r{room_index}-{kind}"
    floor_id = builder.material(Material(f"{name}-floor", colour, make_texture(texture_kind, rng, colour, p.texture_pixels)))
    wall_colour = np.clip(np.asarray(_WALL_COLOURS[int(rng.integers(len(_WALL_COLOURS)))]) * rng.uniform(0.95, 1.05, 3), 0, 255)
    u = rng.random()
    wall_kind = "tiles" if kind == "bathroom" or (kind == "kitchen" and u < 0.3) else \
        "wallpaper" if kind in ("bedroom", "living", "dining") and u < 0.25 else \
        "brick" if kind in ("living", "hall", "corridor") and u > 0.93 else \
        "concrete" if kind in ("closet", "stairs") and u < 0.4 else "plaster" if u > 0.8 else "paint"
    if wall_kind == "brick":
        wall_colour = np.array([165, 85, 60]) * rng.uniform(0.85, 1.1)
    wall_id = builder.material(Material(f"{name}-wall", wall_colour,
                                        make_texture(wall_kind, rng, wall_colour, p.texture_pixels)))
    return floor_id, wall_id


def _add_rects(builder, mask, origin, shape, s, z0, z1, material, texture_size, faces) -> None:
    """Boxes over `mask`, the crop at plan pixel `origin` (row, col) of a plan of `shape`."""
    if mask.any():
        builder.add_boxes(*rect_boxes(mask_rectangles(mask, origin), shape, s, z0, z1), material, texture_size, faces)


def _extrude_floor(builder, rng, layout: ProceduralLayout, index: int, floor: FloorLayout, ceiling_id: int) -> None:
    """Walls, floor, lintels and ceiling of one storey, with per-room materials."""
    p, s = layout.params, layout.params.resolution
    shape = floor.walls.shape
    top_floor = index == len(layout.floors) - 1
    wall_top = layout.wall_height if top_floor else layout.wall_height + p.slab_thickness
    hole = np.zeros(shape, bool)
    if layout.stair is not None:
        f = layout.stair.flight
        hole[f[0]:f[2], f[1]:f[3]] = True
    walkable = floor.interior | floor.openings_mask
    sides = ("+x", "-x", "+y", "-y")
    # each room's masks within the box of the pixels it owns: the whole plan once per room took minutes
    # for a building of hundreds of rooms (a 200 m footprint)
    windows = ndimage.find_objects(floor.owner + 1, max_label=len(floor.rooms))
    for r, room in enumerate(floor.rooms):
        floor_id, wall_id = _room_materials(builder, rng, p, index, r, room.kind)
        if windows[r] is None:  # every pixel of its cell taken by a later one
            continue
        window = windows[r]
        origin = (window[0].start, window[1].start)
        own = floor.owner[window] == r
        _add_rects(builder, floor.walls[window] & own, origin, shape, s, floor.z0, floor.z0 + wall_top, wall_id,
                   p.texture_size_m, sides + ("+z",))
        ground = walkable[window] & own & ~(hole[window] if index == 1 else False)
        stairwell = index == 1 and room.kind == "stairs"
        _add_rects(builder, ground, origin, shape, s, floor.z0 - (p.slab_thickness if stairwell else 0.05),
                   floor.z0, floor_id, p.texture_size_m, sides + ("+z", "-z") if stairwell else ("+z",))
        if p.ceiling or not top_floor:
            _add_rects(builder, walkable[window] & own & ~(hole[window] if index == 0 else False), origin, shape, s,
                       floor.z0 + layout.wall_height, floor.z0 + layout.wall_height + 0.05, ceiling_id,
                       p.texture_size_m, ("-z",))
        for o in floor.openings:
            if o.lintel_height is None or r not in (o.a, o.b):
                continue
            cut = np.zeros(own.shape, bool)
            cut[max(o.rect[0] - origin[0], 0):max(o.rect[2] - origin[0], 0),
                max(o.rect[1] - origin[1], 0):max(o.rect[3] - origin[1], 0)] = True
            _add_rects(builder, cut & own, origin, shape, s, floor.z0 + o.lintel_height, floor.z0 + wall_top,
                       wall_id, p.texture_size_m, sides + ("-z",))


def _add_stair(builder, layout: ProceduralLayout, material: int, rail: int) -> None:
    """Solid steps on floor 0 and railings around the hole on floor 1."""
    st, s, H = layout.stair, layout.params.resolution, layout.floors[0].walls.shape[0]
    f = st.flight.astype(np.float64)
    a = st.axis
    lower, upper = [], []
    for k in range(st.risers - 1):
        r = f.copy()
        if st.direction == 1:
            r[a], r[2 + a] = f[a] + k * st.tread_px, min(f[a] + (k + 1) * st.tread_px, f[2 + a])
        else:
            r[a], r[2 + a] = max(f[2 + a] - (k + 1) * st.tread_px, f[a]), f[2 + a] - k * st.tread_px
        lo, hi = rect_boxes(r[None], (H, 0), s, 0.0, (k + 1) * st.rise)
        lower.append(lo[0])
        upper.append(hi[0])
    builder.add_boxes(np.array(lower), np.array(upper), material, layout.params.texture_size_m,
                      ("+x", "-x", "+y", "-y", "+z"))
    z0 = layout.floors[1].z0
    for r in (st.open_side, st.bottom_rail):
        lo, hi = rect_boxes(np.asarray(r)[None], (H, 0), s, z0, z0 + 1.0)
        builder.add_boxes(lo, hi, rail, layout.params.texture_size_m)


def generate_procedural_scene(seed: int, spec_text: str, conf) -> Scene:
    """Build the scene of ``procedural:<seed>`` (see module docstring).

    Args:
        seed: non-negative integer; the same seed and options give identical arrays.
        spec_text: the spec string, recorded in the metadata and named in errors.
        conf: the ``procedural`` section of ``configs/scenes.yaml`` merged with spec options.
    Returns:
        A validated :class:`Scene` (Z-up, metres), metadata ``extra`` with the seed, room
        count and kinds, floors, footprint size and shape, heights.
    """
    layout = generate_layout(seed, conf, spec_text)
    p = layout.params
    rng = np.random.default_rng([seed, 2])
    builder = MeshBuilder()
    ceiling_colour = np.array([242, 242, 238]) * rng.uniform(0.95, 1.0)
    ceiling_id = builder.material(Material("ceiling", ceiling_colour,
                                           make_texture("paint", rng, ceiling_colour, p.texture_pixels)))
    for index, floor in enumerate(layout.floors):
        _extrude_floor(builder, rng, layout, index, floor, ceiling_id)
    ids = furniture_materials(builder, rng, p.texture_pixels)
    if layout.stair is not None:
        _add_stair(builder, layout, ids["wood"], ids["metal"])
    lower, upper, keys = layout.furniture
    if len(lower):
        builder.add_boxes(lower, upper, np.array([ids[k] for k in keys], np.int32), p.texture_size_m)
    sk = layout.skeleton
    rows, cols = np.nonzero(sk.footprint)
    metadata = SceneMetadata(
        name=f"procedural-{seed}", source="procedural", spec=spec_text,
        extra={"seed": int(seed), "floors": len(layout.floors),
               "rooms": int(sum(len(f.rooms) for f in layout.floors)),
               "rooms_per_floor": [len(f.rooms) for f in layout.floors],
               "room_kinds": [[r.kind for r in f.rooms] for f in layout.floors],
               "doors": int(sum(o.door for f in layout.floors for o in f.openings)),
               "open_plan_openings": int(sum(not o.door for f in layout.floors for o in f.openings)),
               "furniture_items": int(sum(pl.blocking and pl.name != "door" for pl in layout.placed)),
               "building": sk.building_kind, "footprint_shape": sk.shape_kind,
               "footprint_m": [float((cols.max() - cols.min() + 1) * p.resolution),
                               float((rows.max() - rows.min() + 1) * p.resolution)],
               "footprint_area_m2": float(sk.footprint.sum() * p.resolution ** 2),
               "wall_height": layout.wall_height, "door_height": layout.door_height,
               "storey_height": layout.wall_height + p.slab_thickness, "ceiling": bool(p.ceiling)},
    )
    return builder.build(metadata)


__all__ = ["generate_procedural_scene", "generate_layout", "validate_options", "ProceduralLayout", "Placed"]
