"""``frontiernet demo``: explore the built-in default scene with the shipped model (``make demo``).

The robot starts at a seeded random spot, perceives frontiers with FrontierNet on emulated
monocular depth, and explores until its step budget is spent. Prints the coverage reached
and writes ``exploration.mp4``, ``coverage.png`` and ``metrics.json`` to ``--out``
(``configs/demo.yaml`` over ``configs/explore.yaml``).
"""

from __future__ import annotations

from . import options


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("demo", help="explore the default scene with the shipped model",
                                   description=__doc__.splitlines()[0])
    parser.add_argument("--scene", help="scene spec (default: configs/demo.yaml `scene`)")
    options.output_folder(parser, default="outputs/demo")
    options.max_steps(parser, "configs/demo.yaml")
    options.model_option(parser)
    options.config_file(parser, "configs/demo.yaml (over configs/explore.yaml), and sim.yaml, depth.yaml and "
                                "scenes.yaml under sections sim:, depth: and scenes:")
    options.config_overrides(parser, "run.max_steps=100 sim.camera.max_depth=5 depth.emulated.fill_depth=20")
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..exploration.run import RUN_OUTPUTS, check_run, load_run_config, main
    from ..io import check_output_files, check_output_folder, claim_output_folder
    from .explore import summary_line

    check_output_folder(args.out, force=True)  # the demo writes over its own outputs (make demo)
    check_output_files(args.out, RUN_OUTPUTS, [(args.config, "the config file")])
    options.refuse_contradictions(args.overrides, {"run.max_steps": (f"--max-steps {args.max_steps}", args.max_steps),
                                                   "scene": (f"--scene {args.scene}", args.scene)})
    conf = load_run_config(args.config, args.overrides, names=("explore", "demo"))
    scene = conf.pop("scene") if args.scene is None else args.scene  # (an empty --scene is refused, not the default)
    if not isinstance(scene, str):  # (a list was read as the scene named "['procedural:3']")
        from omegaconf import OmegaConf

        from ..errors import InputError

        given = OmegaConf.to_container(scene) if OmegaConf.is_config(scene) else scene
        raise InputError(f"{args.config or 'configs/demo.yaml'}: config key 'scene' takes one scene spec (text, e.g. "
                         f"procedural:3), got {given!r}")
    check_run(conf, model=args.model, max_steps=args.max_steps)  # before the folder is made
    with claim_output_folder(args.out, force=True) as out:
        record = main(conf, scene, out, model=args.model, max_steps=args.max_steps)
    print(summary_line(record, args.out))
    return 0
