"""``frontiernet explore``: closed-loop exploration of a scene (paper III-E, III-F).

Writes to ``--out``: ``metrics.json`` (coverage per step, Vox@25/50/100, path length,
collisions, time per stage), ``trajectory.json``, ``frontiers.json``, ``coverage.png`` and
``exploration.mp4`` (camera view with frontier pixels beside the robot's map from above, and with
``--show-prediction`` the map as a map predictor completes it); with
``--mcap`` ``exploration.mcap`` (ROS 2 messages, :mod:`frontiernet.sequences.ros_explore`).
"""

from __future__ import annotations

from . import options


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("explore", help="explore a scene with FrontierNet (or another method)",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", required=True, help=options.SCENE_HELP)
    parser.add_argument("--method", default="frontiernet",
                        help="exploration method: frontiernet (the model), oracle (ground-truth frontiers), its hybrids "
                             "oracle-uniform and frontiernet-oracle-gain, the Fig. 9 "
                             "ablations df-uniform, discontinuity-gain, discontinuity-uniform, the baselines classic, "
                             "gain-distance, random-frontier, nbvp, vacuum, the all-knowing bound omniscient, or a plugin "
                             "(docs/exploration.md)")
    options.model_option(parser)
    parser.add_argument("--depth", help="depth source: gt, emulated, depth_anything_v2, metric3d_v2 "
                                        "(default: configs/explore.yaml run.depth)")
    options.max_steps(parser, "configs/explore.yaml")
    parser.add_argument("--start", metavar="x,y,z,yaw[,pitch]",
                        help="start pose (metres; angles in degrees, or radians with a 'rad' suffix; default: sampled "
                             "with the seed); the robot keeps the start's camera height, and a pitch (> 0 looks up) "
                             "is its camera's tilt for the run (motion.pitch_deg)")
    parser.add_argument("--seed", type=int, help="seed (default: run.seed)")
    parser.add_argument("--map-free", action="store_true", help="plan on the frontier tree only (paper Table III)")
    parser.add_argument("--no-video", action="store_true", help="skip exploration.mp4 (faster)")
    parser.add_argument("--rerun", action="store_true", help="also write recording.rrd for the Rerun viewer "
                                                             "(needs rerun-sdk)")
    parser.add_argument("--mcap", action="store_true",
                        help="also write exploration.mcap: the frontiers, the camera overlay, the map and the "
                             "camera's tf as ROS 2 messages for Foxglove and RViz (as frontiernet sequence writes)")
    parser.add_argument("--show-prediction", nargs="?", const=True, metavar="PREDICTOR",
                        type=options.optional_input_path("predictor file", "--show-prediction"),
                        help="draw the map as a mapex predictor completes it beside the robot's own in "
                             "exploration.mp4 (alone: the method's own prediction for mapex and frontiernet-mapex, "
                             "else mapex.predictor, else the shipped one; docs/mapprediction.md)")
    options.config_file(parser, options.EXPLORE_CONFIG)
    options.output_folder(parser, force=True)
    options.config_overrides(parser, "planner.clearance_m=0.3 sim.camera.max_depth=5 depth.emulated.fill_depth=20 "
                                     "scenes.floorplan.wall_height=2.4")
    parser.set_defaults(func=run)


def summary_line(record: dict, out) -> str:
    """One line with the coverage reached and where the outputs are."""
    vox = record["vox_at"]
    timing = record["timing"]
    return (f"explore: {record['scene']} with {record['method']} ({record['depth']} depth): coverage "
            f"{record['coverage']:.1%} after {record['steps']} steps (Vox@25/50/100 {vox['25']:.1%} / {vox['50']:.1%} "
            f"/ {vox['100']:.1%}), path {record['path_length_m']:.1f} m, {record['collisions']} collisions, "
            f"{timing['step_ms_without_motion']:.0f} ms per step; stopped: {record['stop_reason']}. "
            f"Outputs in {out}/ (metrics.json, coverage.png{', exploration.mp4' if 'video' in record else ''}"
            f"{', recording.rrd' if 'rerun' in record else ''}{', exploration.mcap' if 'mcap' in record else ''})")


def model_contradictions(method: str, model, depth) -> dict:
    """The config keys that ``--model`` and ``--depth`` set in a `method` run, for
    :func:`~.options.refuse_contradictions`: ``run.depth``, and ``<method>.predictor`` where the method runs a map
    predictor (seer, mapex: ``--model`` names its file; a FrontierNet model has no key). An unknown method: no
    predictor key (the run refuses it, naming the valid ones)."""
    from ..errors import InputError
    from ..exploration.methods import runs_frontiernet_model, uses_model

    keys = {"run.depth": (f"--depth {depth}", depth)}
    try:
        if uses_model(method) and not runs_frontiernet_model(method):
            keys[f"{method}.predictor"] = (f"--model {model}", model)
    except InputError:
        pass
    return keys


def refuse_pitch_contradiction(start, overrides) -> None:
    """InputError where ``--start`` gives a pitch and a ``motion.pitch_deg=`` override another (one of the two
    would be ignored); the start's pitch wins over a ``--config`` file's, as ``--map-free`` does."""
    import yaml

    from ..errors import InputError
    from ..exploration.run import start_pitch_deg

    pitch = start_pitch_deg(start)
    for item in overrides or () if pitch is not None else ():
        key, _, text = str(item).partition("=")
        if key.strip() != "motion.pitch_deg":
            continue
        try:
            given = yaml.safe_load(text)
        except yaml.YAMLError:
            given = text
        if not isinstance(given, (int, float)) or isinstance(given, bool) or abs(float(given) - pitch) > 1e-9:
            raise InputError(f"--start {start} (pitch {pitch:g} degrees) contradicts {str(item).strip()}: give one "
                             "of them")


def run(args) -> int:
    from ..exploration.run import RUN_OUTPUTS, check_run, load_run_config, main
    from ..io import check_output_files, check_output_folder, claim_output_folder
    from ..scenes.spec import scene_file

    check_output_folder(args.out, args.force)
    check_output_files(args.out, RUN_OUTPUTS, [(scene_file(args.scene), "the scene"), (args.model, "the model file"),
                                                (args.config, "the config file")])
    options.refuse_contradictions(args.overrides, {
        "planner.mode": ("--map-free", "map_free" if args.map_free else None),
        "run.seed": (f"--seed {args.seed}", args.seed), "run.max_steps": (f"--max-steps {args.max_steps}", args.max_steps),
        **model_contradictions(args.method, args.model, args.depth)})
    refuse_pitch_contradiction(args.start, args.overrides)
    overrides = [*args.overrides, *(["planner.mode=map_free"] if args.map_free else [])]  # over a --config file's
    conf = load_run_config(args.config, overrides)
    settings = {"method": args.method, "model": args.model, "depth": args.depth, "max_steps": args.max_steps,
                "start": args.start, "seed": args.seed, "rerun": args.rerun, "show_prediction": args.show_prediction}
    check_run(conf, video=not args.no_video, **settings)  # before the folder is made
    with claim_output_folder(args.out, args.force) as out:  # one run at a time writes there
        mcap = []
        if args.mcap:  # the ROS messages of frontiernet sequence (a layer above the explorer)
            from ..sequences.ros_explore import ExplorationMcap

            mcap = [ExplorationMcap(out / "exploration.mcap")]
        record = main(conf, args.scene, out, video=not args.no_video, step_outputs=mcap, **settings)
    if mcap:
        record["mcap"] = str(mcap[0].path)
    print(summary_line(record, args.out))
    return 0
