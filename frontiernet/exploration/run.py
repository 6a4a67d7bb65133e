"""One exploration run from a config: ``main(conf, scene, ...)``, and ``explore(scene, out, user_file,
overrides, ...)`` (the config resolved, then ``main``) behind ``frontiernet explore``.

Loads the scene, samples (or checks) the start pose, builds the depth source and the
method (:func:`~frontiernet.exploration.methods.make_method`), runs the :class:`~frontiernet.exploration.explorer.Explorer` and writes the
outputs of :mod:`frontiernet.exploration.outputs` (and the video) to `out`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from ..errors import InputError, check_seed, whole_number
from ..geometry import parse_pose_text, pose_from_heading
from .region import sample_start

RUN_SECTIONS = {"sim": ("sim", None), "depth": ("depth", None), "ground_truth": ("datagen", "ground_truth"),
                "scenes": ("scenes", None)}
"""Shipped config (file, section or None for all of it) a run's config holds as sections beside
``configs/explore.yaml``'s, so that ``--config`` and ``key=value`` reach them (``sim.camera.max_depth=5``,
``depth.emulated.fill_depth=20``, ``ground_truth.gain.volume=occluded``: the ground truth of the
``oracle`` methods, datagen's labels; ``scenes.floorplan.wall_height=2.4``: the scene sources' options)."""

RUN_OUTPUTS = ("metrics.json", "trajectory.json", "frontiers.json", "coverage.png", "config.yaml", "exploration.mp4",
               "recording.rrd", "exploration.mcap")
"""The files a run writes in its folder (:func:`main`, :func:`~.outputs.write_run`, ``explore --mcap``): a
command checks that none is a folder before the run (:func:`~frontiernet.io.check_output_files`)."""

MAX_STEPS = 100_000
"""The largest step budget a run takes: 33x the paper's largest (3,000 steps, scene 807), about a day of
the slowest method; more is a typo, which would otherwise run until killed."""


def shipped_section(section: str):
    """The shipped config of run section `section` (a key of :data:`RUN_SECTIONS`); ``depth`` less
    its ``source`` key (the run's source is ``--depth`` or ``run.depth``)."""
    from ..config import load_config
    from ..depth import source_options

    if section == "depth":
        return source_options()
    name, key = RUN_SECTIONS[section]
    return load_config(name) if key is None else load_config(name)[key]


def load_run_config(user_file=None, overrides=(), names=("explore",)):
    """The whole config of an exploration run, resolved once at the top.

    ``configs/<name>.yaml`` of `names` merged in order (``("explore", "demo")``: the demo's keys
    win), with the sections of :data:`RUN_SECTIONS`: ``sim`` (``configs/sim.yaml``), ``depth``
    (``configs/depth.yaml``, less its ``source`` key: the run's source is ``--depth`` or
    ``run.depth``), ``ground_truth`` (datagen's) and ``scenes`` (``configs/scenes.yaml``), then the
    user's YAML `user_file` and ``key=value`` `overrides` on top.

    Raises:
        InputError: an unreadable file, an unknown key (one line naming it) or a value of the
            wrong kind.
    """
    from ..config import load_config, merge_user

    conf = load_config(tuple(names))
    sections = {section: shipped_section(section) for section in RUN_SECTIONS}
    conf = OmegaConf.merge(conf, sections)
    return merge_user(conf, user_file, overrides, layout=run_layout(names))


def run_layout(names=("explore",)) -> dict:
    """Where the shipped files of a run's config sit in it (:func:`~frontiernet.config.check_ranges`):
    `names` at the top, each of :data:`RUN_SECTIONS` under its section."""
    return {"": names, **{section: name if key is None else f"{name}.{key}"
                          for section, (name, key) in RUN_SECTIONS.items()}}


def run_section(conf, section: str):
    """Section `section` (one of :data:`RUN_SECTIONS`) of a run config; the shipped one when the
    config has no such section (an ``explore.yaml``-only config)."""
    return conf[section] if section in conf else shipped_section(section)


def planning_world(spec: str, conf):
    """The :class:`~frontiernet.simulator.world.World` of scene `spec` without a renderer (the scene and
    its voxels under the run config `conf`'s ``sim`` and ``scenes`` sections): what a plan reads of a
    scene (its start poses, its budget). Raises InputError for an unknown or unreadable scene."""
    from ..simulator.world import build_world

    return build_world(spec, run_section(conf, "sim"), run_section(conf, "scenes"), renderer=False)


def run_depth_source(depth: str | None, conf) -> str:
    """The depth source of a run: `depth` or ``run.depth``, aliases resolved (``gt``); InputError
    for an unknown one (:func:`~frontiernet.depth.known_source`)."""
    from ..depth import known_source

    named = conf.run.depth
    return known_source(("null" if named is None else str(named)) if depth is None else depth)  # ('' is no source)


def check_run(conf, *, method: str = "frontiernet", model=None, depth: str | None = None,
              max_steps: int | None = None, start: str | None = None, seed: int | None = None,
              rerun: bool = False, show_prediction=None, video: bool = True) -> tuple[int, int, str]:
    """Before a run's setup (:func:`main` calls it first; a command before it makes any folder): the
    run's step budget, seed and depth source name, resolved; InputError for a budget < 1, a seed
    < 0, a ``run.video_fps`` <= 0, an unknown depth source or method, a `model` the method does not run
    or that is no file, a malformed `start`, a ``planner.clearance_m`` too small for the agent, `rerun`
    without rerun-sdk, a `show_prediction` without the video or whose predictor does not load
    (:func:`~.predicted.open_predictor`). (What needs the scene, such as a start outside it, is
    checked after it loads.)"""
    from ..depth import check_depth_files
    from ..config import check_ranges
    from ..errors import positive_number
    from ..io import input_file
    from .methods import check_method
    from .move_check import body_radius

    budget = whole_number(conf.run.max_steps if max_steps is None else max_steps,
                          "the step budget (--max-steps, run.max_steps)", 1, MAX_STEPS)
    seed = check_seed(conf.run.seed if seed is None else seed, "the seed (--seed, run.seed)")
    check_ranges(conf, run_layout())  # (a library caller's own config too: run.video_fps is the video's clock)
    check_sections(conf)
    depth_name = run_depth_source(depth, conf)
    check_depth_files(depth_name, conf.get("depth"))
    check_method(method, model, conf)  # a method's own file checks (seer, mapex: the predictor)
    if model is not None:
        input_file(model, "model file")
    if start is not None:
        parse_pose_text(start, "--start")  # x,y,z,yaw[,pitch]: a pitch is the camera's for the run (start_pitch_deg)
    agent = run_section(conf, "sim").agent
    body_radius(conf.planner, float(conf.map.voxel_size), positive_number(agent.radius_m, "agent.radius_m", "metres"))
    if rerun:
        from .recording import require_rerun

        require_rerun()
    if show_prediction is not None:
        if not video:
            raise InputError("--show-prediction draws the predicted map into exploration.mp4; leave out --no-video")
        if not shows_own_prediction(method, show_prediction):  # (its own: check_method's)
            shown_predictor(conf, show_prediction)
    return budget, seed, depth_name


def start_pitch_deg(start: str | None) -> float | None:
    """The camera pitch (degrees, > 0 looks up) a ``--start x,y,z,yaw,pitch`` gives, None without one. The robot
    keeps its camera's height and pitch for the whole run (:class:`~.motion.Motion`): as the start's z is the
    camera height of the run, its pitch is the run's ``motion.pitch_deg``, which every method reads."""
    if start is None or len(str(start).split(",")) != 5:
        return None
    return round(float(np.degrees(parse_pose_text(start, "--start")[4])), 9)


def check_sections(conf) -> None:
    """InputError naming the key of a run section that its settings refuse where its declared range lets
    it through (an even ``anchoring.gradient_kernel_px``, every ``anchoring.feature_weights`` 0): before the
    setup, not when the section is first read (the first frame, after the scene and the model loaded)."""
    from ..frontiers.settings import AnchoringSettings
    from ..mapping.checks import MapSettings
    from .nbvp_tree import NbvpSettings
    from .steps import AccountSettings
    from .surface import SurfaceSettings

    for settings, section in ((AnchoringSettings, "anchoring"), (MapSettings, "map"), (SurfaceSettings, "surface"),
                              (AccountSettings, "steps"), (NbvpSettings, "nbvp")):
        settings.from_config(conf[section])


def shows_own_prediction(method: str, show_prediction) -> bool:
    """Whether ``explore --show-prediction`` (alone: `show_prediction` True) draws the prediction the method
    keeps itself (:func:`~.methods.owns_topdown_prediction`: mapex, frontiernet-mapex) rather than one of
    its own (:func:`shown_predictor`)."""
    from .methods import owns_topdown_prediction

    return show_prediction is True and owns_topdown_prediction(method)


def shown_predictor(conf, show_prediction):
    """The loaded ``mapex`` predictor that ``explore --show-prediction`` draws when the method has no
    prediction of its own (:func:`main`): `show_prediction` True takes ``mapex.predictor`` (null: the
    shipped one), a path that file (:func:`~.predicted.open_predictor`)."""
    from .predicted import open_predictor

    return open_predictor(conf, "mapex", None if show_prediction is True else show_prediction)


def explore(scene: str, out: str | Path, user_file=None, overrides=(), **options) -> dict:
    """``frontiernet explore`` in one call: the run's config resolved once at the top
    (:func:`load_run_config` of the user's YAML `user_file` and ``key=value`` `overrides`), then
    :func:`main` with it; `options` are :func:`main`'s (method, model, depth, ...). Returns the metrics.

    Raises:
        InputError: as :func:`load_run_config` and :func:`main`.
    """
    return main(load_run_config(user_file, overrides), scene, out, **options)


def main(conf, scene: str, out: str | Path, *, method: str = "frontiernet", model=None, depth: str | None = None,
         max_steps: int | None = None, start: str | None = None, seed: int | None = None, video: bool = True,
         rerun: bool = False, progress: bool = True, step_outputs=(), show_prediction=None) -> dict:
    """Explore `scene` (a scene spec) and write the run's outputs to `out`; returns the metrics.

    Beside the outputs of :func:`~frontiernet.exploration.outputs.write_run`, ``config.yaml`` holds
    the run's whole config as used (``run.seed``, ``run.max_steps`` and ``run.depth`` resolved):
    ``--config config.yaml`` repeats the run.

    Args:
        conf: the run's config (:func:`load_run_config`: ``configs/explore.yaml`` with the
            sections of :data:`RUN_SECTIONS`, merged with the user's file and overrides; a
            section left out is the shipped one).
        method: an exploration method (:mod:`frontiernet.exploration.methods`: ``frontiernet``,
            ``oracle``, the ablations, ``classic``, ``gain-distance``, ``random-frontier``,
            ``vacuum``, plugins).
        model: model file of the learned methods (None: the shipped model).
        depth: depth source (``gt`` or a source of ``configs/depth.yaml``; None: ``run.depth``).
        max_steps, seed: override ``run.max_steps`` and ``run.seed``.
        start: ``"x,y,z,yaw[,pitch]"`` (metres; angles in degrees or with a ``rad`` suffix, see
            :func:`~frontiernet.geometry.parse_pose_text`; None: sampled with the seed); a pitch sets
            ``motion.pitch_deg``, the camera's tilt for the whole run (:func:`start_pitch_deg`).
        video: write ``exploration.mp4``; rerun: write ``recording.rrd`` (needs rerun-sdk).
        show_prediction: draw a ``mapex`` predictor's completion of the map into the video (a third
            panel): True for ``mapex.predictor`` (null: the shipped one), or a predictor file; None: off.
        step_outputs: more per-iteration outputs, ``on_step`` consumers of the explorer with a
            ``close()`` called after the run (``explore --mcap``'s
            :class:`~frontiernet.sequences.ros_explore.ExplorationMcap`, from a layer above).
    """
    from ..depth import make_depth_source
    from ..io import ensure_dir, write_text
    from ..simulator.world import build_world
    from .explorer import Explorer
    from .outputs import VideoWriter, write_run
    from .methods import MethodContext, make_method
    from .recording import RerunRecorder
    from .video import StepPictures

    budget, seed, depth_name = check_run(conf, method=method, model=model, depth=depth, max_steps=max_steps,
                                         start=start, seed=seed, rerun=rerun, show_prediction=show_prediction,
                                         video=video)
    # the explorer's own draws read run.seed; config.yaml records what the run used (a --start pitch too)
    conf = OmegaConf.merge(conf, {"run": {"seed": seed, "max_steps": budget, "depth": depth_name}})
    if (pitch_deg := start_pitch_deg(start)) is not None:
        conf = OmegaConf.merge(conf, {"motion": {"pitch_deg": pitch_deg}})
    sim = run_section(conf, "sim")
    clock = time.perf_counter()
    # the run's ray-cast engine (sim.raycast.backend) and scene options (scenes), not the shipped files'
    world = build_world(scene, sim, run_section(conf, "scenes"))
    loaded, voxels = world.scene, world.voxels
    if voxels.num_explorable == 0:
        raise InputError(f"{scene}: the scene has no free explorable space")
    rng = np.random.default_rng(seed)
    if start is None:
        T_start = sample_start(loaded, voxels, conf, rng)
    else:
        x, y, z, yaw, _ = parse_pose_text(start, "--start")  # (its pitch is motion.pitch_deg now)
        T_start = pose_from_heading(x, y, z, yaw, np.radians(float(conf.motion.pitch_deg)))
    depth_source = make_depth_source(depth_name, run_section(conf, "depth"))
    depth_source.reset(seed)
    context = MethodContext(conf, sim, model, loaded, voxels)  # the run's draws (run.seed) and map
    exploration_method = make_method(method, context)
    out = ensure_dir(out)
    recorder = RerunRecorder(out / "recording.rrd") if rerun else None
    writer = VideoWriter(out / "exploration.mp4", float(conf.run.video_fps)) if video else None
    # --show-prediction alone: the method's own prediction where it has one (mapex, frontiernet-mapex),
    # read, not predicted again; else a prediction of its own
    own = exploration_method.source.topdown if shows_own_prediction(method, show_prediction) else None
    prediction = own
    if show_prediction is not None and own is None:
        from .predicted import topdown_prediction

        prediction = topdown_prediction(conf, shown_predictor(conf, show_prediction), context.map.voxel_size)
    pictures = StepPictures(voxels, conf, writer, budget, progress=progress, prediction=prediction,
                            predicts=own is None)
    on_step = ((pictures,) if recorder is None else (pictures, recorder)) + tuple(step_outputs)
    explorer = Explorer(context, world.renderer, exploration_method, depth_source, T_start, on_step=on_step)
    setup_s = time.perf_counter() - clock
    try:
        with pictures:
            result = explorer.run(budget)
    finally:
        if writer is not None:
            writer.close()
        if recorder is not None:
            recorder.close()
        for output in step_outputs:
            output.close()
    info = {"scene": scene, "method": method, "depth": depth_name, "planner_mode": str(conf.planner.mode),
            "model": str(model or "shipped") if exploration_method.uses_model else None, "seed": seed,
            "start": np.round(T_start, 5).tolist(), "setup_s": round(setup_s, 2),
            "wall_s": round(time.perf_counter() - clock, 2)}
    record = write_run(out, result, budget, info, explorer.tracker)
    write_text(out / "config.yaml", OmegaConf.to_yaml(conf))
    if writer is not None:
        record["video"] = str(out / "exploration.mp4")
    if recorder is not None:
        record["rerun"] = str(out / "recording.rrd")
    return record
