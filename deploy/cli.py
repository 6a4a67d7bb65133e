"""``frontiernet export`` and ``frontiernet predict`` (registered through the
``frontiernet.commands`` entry point), and ``frontiernet bench inference`` (through
``frontiernet.bench``).

  frontiernet export MODEL --format onnx|torchscript|safetensors --out FILE [--half] [--frontier-threshold PX]
  frontiernet predict --image RGB [--depth D|depth_anything_v2|metric3d_v2] [--model M] --out DIR [--force] [--size PX]
                     [--depth-scale S] [--depth-encoding scale|sun|nyu] [--intrinsics FX,FY,CX,CY]
                     [--config FILE] [KEY=VALUE ...]
"""

from __future__ import annotations

from frontiernet.cli import options


def add_parser(subparsers) -> None:
    export = subparsers.add_parser(
        "export", help="export a model to ONNX, TorchScript or a compact safetensors file",
        description="Export a FrontierNet model file or training checkpoint. ONNX and TorchScript take any "
                    "batch and image size; each file carries the model config for the runtime.")
    options.model_file(export)
    export.add_argument("--format", required=True, choices=("onnx", "torchscript", "safetensors"))
    options.output_file(export)
    export.add_argument("--half", action="store_true", help="safetensors: float16 weights (half the size)")
    export.add_argument("--frontier-threshold", type=float, metavar="PX",
                        help="threshold l (px) the exported file's runtimes use for D < l, e.g. the best-F1 l "
                             "of frontiernet evaluate (default: keep the model's)")
    export.set_defaults(func=run_export)

    predict = subparsers.add_parser(
        "predict", help="frontier pixels and gain of one image (overlay picture and arrays)",
        description="Run FrontierNet on one RGB image (and depth map) and write overlay.png, distance.png, "
                    "input.png and outputs.npz.")
    predict.add_argument("--image", metavar="RGB", type=options.input_path("image"),
                         help="RGB image (8-bit, 3 channels)")
    predict.add_argument("--depth", metavar="D", type=options.input_path("depth file"),
                         help="depth map: .npy metres, or an image (integer images are divided by --depth-scale); "
                              "or a monocular depth model that estimates it from --image: depth_anything_v2, "
                              "metric3d_v2 (local weights: depth.<model>.path=..., configs/depth.yaml; metric3d_v2 "
                              "needs --intrinsics)")
    predict.add_argument("--model", metavar="M", type=options.input_path("model file"),
                         help="model file, checkpoint, .onnx or TorchScript .pt (default: the shipped model for "
                              "the inputs given: RGB + depth, or RGB only for --image alone)")
    options.output_folder(predict, force=True)
    predict.add_argument("--size", type=int, metavar="PX", help="network input size: the short side is resized "
                                                                "to PX and centre-cropped (default: the model's, "
                                                                "320; 0 keeps the image as is)")
    predict.add_argument("--depth-scale", type=float,
                         help="integer depth units per metre (default 1000: millimetres; TUM: 5000); float depth "
                              "(.npy, float images) is metres and takes none")
    predict.add_argument("--depth-encoding", default="scale", choices=("scale", "sun", "nyu"),
                         help="depth file encoding: scale (integer units, see --depth-scale; float = metres), sun "
                              "(SUN3D/SUN RGB-D bit-rotated mm), nyu (NYU Depth V2 raw Kinect PGM)")
    predict.add_argument("--fill-invalid-depth", action="store_true",
                         help="fill the depth's holes (a real sensor's 0) from the nearest valid pixel before the "
                              "network, which reads missing depth as free space beyond range (use for real frames)")
    predict.add_argument("--intrinsics", metavar="FX,FY,CX,CY",
                         help="pinhole intrinsics of the image in pixels: also write 3D frontiers (frontiers.json, "
                              "in a level camera frame and the camera frame; needs --depth)")
    predict.add_argument("--threads", type=int, help="CPU threads for the network (1 to 4 per core; default: "
                                                     "torch's)")
    options.config_file(predict, "configs/depth.yaml under section depth: (the monocular models), and "
                                 "configs/explore.yaml's anchoring: (the 3D frontiers)")
    options.config_overrides(predict, "depth.depth_anything_v2.path=weights/da2 anchoring.hdbscan.min_cluster_size=30")
    predict.set_defaults(func=run_predict)


def run_export(args) -> int:
    from frontiernet.io import check_output_file

    from .export import export

    check_output_file(args.out, args.force)
    path = export(args.model, args.format, args.out, half=args.half,
                  frontier_threshold_px=args.frontier_threshold)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0


def _overrides_not_read(overrides, *, intrinsics: bool, depth_model: str | None) -> str | None:
    """What is wrong with ``key=value`` `overrides` that this ``predict`` would not read (None: each is read): an
    ``anchoring.*`` key without ``--intrinsics`` (only the 3D frontiers anchor), a ``depth.<model>.*`` key of a
    model that does not run (a depth file given, or another model). Both ran without a word, as if they had acted."""
    for item in overrides:
        key = item.split("=", 1)[0].strip()
        if key.startswith("anchoring.") and not intrinsics:
            return (f"{item}: anchoring makes the 3D frontiers of --intrinsics, and none is given: give --intrinsics, "
                    "or leave it out")
        model = key.split(".")[1] if key.startswith("depth.") and key.count(".") >= 2 else None
        if model is not None and model != depth_model:
            runs = f"--depth {depth_model} runs" if depth_model else "no depth model runs (--depth gives a file, or none)"
            return f"{item}: a setting of the depth model {model}, and {runs}: leave it out"
    return None


def run_predict(args) -> int:
    """``frontiernet predict``; refuses, before anything is written, a ``--depth-scale`` the depth is not
    read with (another ``--depth-encoding``, a depth model, no ``--depth``) and an encoding of no depth file."""
    from frontiernet.errors import InputError, cpu_count_option, positive_number
    from frontiernet.io import check_output_files, check_output_folder, claim_output_folder, input_file
    from frontiernet.model.predictor import input_size

    from .predict import OUTPUT_FILES, depth_model_name, load_predict_config, predict_files

    if args.size:  # (0 keeps the image as is)
        input_size(args.size, "--size (or 0: the image's own size)")
    if args.depth_scale is not None:
        positive_number(args.depth_scale, "--depth-scale")
    depth_model = depth_model_name(args.depth)
    if (args.depth is None or depth_model) and (args.depth_scale is not None or args.depth_encoding != "scale"):
        given = "--depth-scale" if args.depth_scale is not None else f"--depth-encoding {args.depth_encoding}"
        reading = "no --depth is given" if args.depth is None else \
            f"--depth {depth_model} estimates the depth from the image"
        raise InputError(f"{given} decodes a depth file, and {reading}: leave it out")
    if args.depth_scale is not None and args.depth_encoding != "scale":
        raise InputError(f"--depth-scale ({args.depth_scale:g}) applies to --depth-encoding scale only; the "
                         f"{args.depth_encoding} encoding sets its own unit: leave --depth-scale out")
    if args.threads is not None:
        cpu_count_option(args.threads, "--threads")
    check_output_folder(args.out, args.force)  # earlier outputs are replaced only with --force
    check_output_files(args.out, OUTPUT_FILES, [(args.image, "the image (--image)"), (args.model, "the model file"),
                                                (None if depth_model else args.depth, "the depth file (--depth)"),
                                                (args.config, "the config file")])
    for path, what in ((args.image, "image"), (args.model, "model file"),
                       (None if depth_model else args.depth, "depth file")):
        if path is not None:  # before the model loads
            input_file(path, what)
    unread = _overrides_not_read(args.overrides, intrinsics=bool(args.intrinsics), depth_model=depth_model)
    if unread:
        raise InputError(unread)
    conf = load_predict_config(args.config, args.overrides)
    intrinsics = None
    if args.intrinsics:
        from frontiernet.geometry import parse_intrinsics_text

        intrinsics = parse_intrinsics_text(args.intrinsics)
        from frontiernet.frontiers.settings import AnchoringSettings

        AnchoringSettings.from_config(conf)  # the anchoring keys, before any picture is written
    with claim_output_folder(args.out, args.force):
        result = predict_files(args.image, args.depth, args.model, args.out, size=args.size,
                               depth_scale=args.depth_scale, threads=args.threads, intrinsics=intrinsics,
                               depth_encoding=args.depth_encoding, fill_invalid=args.fill_invalid_depth, conf=conf)
    frontier = result["frontier_mask"]
    frontiers = result.get("frontiers")
    print(f"{int(frontier.sum())} frontier pixels ({100 * frontier.mean():.2f} % of the image)"
          + (f", {len(frontiers)} 3D frontiers" if frontiers is not None else "")
          + f"; wrote {args.out}/overlay.png, distance.png, outputs.npz" + (", frontiers.json" if frontiers is not None else ""))
    return 0
