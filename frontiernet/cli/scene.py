"""``frontiernet scene``: inspect scenes (``info``) and save top-down previews (``topdown``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ..scenes import spec as spec_module
from . import options


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "scene", help="inspect a scene (info, topdown)",
        description="Inspect scenes. SPEC names a scene:\n" + spec_module.__doc__.split("\n", 2)[2],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True,
                                    parser_class=type(parser))
    info = actions.add_parser("info", help="JSON: bounds, triangles, explorable volume, voxel counts")
    options.scene_world(info, "voxel settings")
    info.set_defaults(func=run_info)
    topdown = actions.add_parser("topdown", help="save a cut-away top view PNG")
    options.scene_world(topdown, "voxel settings of the explorable region")
    options.output_file(topdown, "output PNG file")
    topdown.add_argument("--pixel-size", type=float, default=0.05, help="metres per pixel (default 0.05)")
    topdown.add_argument("--cut-height", type=float, default=1.8,
                         help="metres above the floor where the view is cut, > 0 (default 1.8)")
    topdown.add_argument("--no-explorable", action="store_true",
                         help="leave out the explorable region (drawn by default: columns of the space "
                              "exploration is scored on, green where it reaches the cut height, amber where "
                              "it lies only above or below it, outlined, its seed a red cross)")
    topdown.set_defaults(func=run_topdown)


def scene_info(spec: str, conf) -> dict:
    """Facts about a scene as a JSON-able dict (bounds, triangles, explorable volume...);
    `conf`: :func:`~frontiernet.simulator.world.load_world_config` (sim.yaml, scenes.yaml as ``scenes``)."""
    from ..simulator.world import build_world

    world = build_world(spec, conf, conf.scenes, renderer=False)
    scene, voxels = world.scene, world.voxels
    bounds = scene.bounds
    return {
        "spec": spec,
        "name": scene.name,
        "source": scene.metadata.source,
        "units": scene.metadata.units,
        "up_axis_conversion": scene.metadata.up_axis_conversion,
        "bounds_min": np.round(bounds[0], 4).tolist(),
        "bounds_max": np.round(bounds[1], 4).tolist(),
        "size_m": np.round(bounds[1] - bounds[0], 4).tolist(),
        "triangles": scene.num_triangles,
        "vertices": int(len(scene.vertices)),
        "materials": len(scene.materials),
        "textured_materials": sum(m.texture is not None for m in scene.materials),
        "surface_area_m2": round(float(scene.triangle_areas().sum()), 3),
        "voxel_size_m": voxels.voxel_size,
        "voxel_grid_shape": list(voxels.shape),
        "voxels_occupied": int(voxels.occupied.sum()),
        "voxels_explorable": int(voxels.explorable.sum()),
        "voxels_outside": int(voxels.occupied.size - voxels.occupied.sum() - voxels.explorable.sum()),
        "explorable_volume_m3": round(float(voxels.explorable_volume_m3), 3),
        "explorable_rule": str(conf.voxels.explorable),
        "explorable_seed": None if voxels.seed is None else np.round(voxels.index_to_world(voxels.seed), 3).tolist(),
        "load_seconds": round(world.seconds["load"], 3),
        "voxelize_seconds": round(world.seconds["voxelize"], 3),
        "metadata": scene.metadata.extra,
    }


def run_info(args) -> int:
    from ..simulator.world import load_world_config

    conf = load_world_config(args.config)
    print(json.dumps(scene_info(args.spec, conf), indent=2, default=str))
    return 0


GREEN, AMBER = (40, 220, 90), (240, 170, 30)
"""RGB of the explorable region in ``scene topdown``: columns explorable at the cut height, and
columns explorable only above or below it."""


def run_topdown(args) -> int:
    from ..io import check_image_name, check_not_an_input, check_output_file, check_output_folder, ensure_dir, write_image
    from ..scenes.spec import scene_file
    from ..simulator.preview import check_view_settings, topdown_image
    from ..simulator.world import build_world, load_world_config

    check_output_file(args.out, args.force)  # before the work: a bad --out or setting fails at once, no folder
    check_not_an_input(args.out, [(scene_file(args.spec), "the scene"), (args.config, "the config file")], "--out",
                       "another --out")  # (--force wrote a floor plan's top view over the plan)
    check_image_name(args.out)
    check_output_folder(Path(args.out).parent, force=True)
    check_view_settings(args.pixel_size, args.cut_height)
    sim = load_world_config(args.config)
    scene = build_world(args.spec, sim, sim.scenes, voxels=False, renderer=False).scene  # the config's ray-cast engine
    image = topdown_image(scene, pixel_size=args.pixel_size, cut_height=args.cut_height)
    note = ""
    if not args.no_explorable:
        from ..simulator.preview import overlay_columns

        voxels = build_world(scene, sim, renderer=False).voxels
        seed = None if voxels.seed is None else voxels.index_to_world(voxels.seed)[:2]
        at_cut = voxels.explorable[:, :, voxels.layer(scene.bounds[0, 2] + args.cut_height)]
        for columns, color, mark in ((voxels.explorable.any(axis=2) & ~at_cut, AMBER, None), (at_cut, GREEN, seed)):
            image = overlay_columns(image, scene, args.pixel_size, columns, voxels.origin[:2], voxels.voxel_size,
                                    color=color, seed=mark)
        note = (f"; explorable {voxels.explorable_volume_m3:.1f} m^3: green at the cut height, amber only "
                f"above or below it{'' if seed is None else ', red cross its seed'}")
    ensure_dir(Path(args.out).parent)
    write_image(args.out, image)
    print(f"wrote {args.out} ({image.shape[1]} x {image.shape[0]} px{note})")
    return 0
