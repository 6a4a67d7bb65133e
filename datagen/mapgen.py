"""``frontiernet mapgen``: partial maps along simulated exploration runs, with the true occupancy, for the
map predictors (docs/mapprediction.md; the format is :mod:`datagen.mapshards`).

Each scene gets the runs of ``mapgen.runs`` (an exploration method and a depth source each, from its own
seeded start): the exploration loop of ``frontiernet explore`` (:class:`~frontiernet.exploration.explorer.Explorer`),
whose robot map is snapshotted every ``mapgen.snapshot_every_steps`` steps, with the frontier pieces of
that map (classic map frontiers in the planner's band: the centres of SEER's crops). One shard per run,
seeded from the run's seed, the scene and the run's index (:func:`datagen.generate.shard_seed`), so a
scene added later leaves the others' shards unchanged; shards run on processes or Ray
(:func:`frontiernet.workers.run_parallel`, as ``frontiernet datagen``), each written atomically, and
``--resume`` makes only the missing ones.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from frontiernet import __version__
from frontiernet.errors import InputError, check_seed, positive_number, whole_number
from frontiernet.io import check_output_name, claim_output_folder, write_json

from .generate import _slug, drop_stale_caches, prepare_output, shard_seed
from .mapshards import (map_shard_complete, read_map_dataset_info, read_map_shard_meta, write_map_dataset_info,
                        write_map_shard)
from .shards import INFO_NAME, SHARDS_DIR, remove_stale_temporaries
from .summary import scene_error

GENERATOR_VERSION = f"frontiernet-mapgen/{__version__}/1"
"""Names the snapshot recipe; bump the last number when the snapshots change."""
RUNTIME_KEYS = (("sim", "raycast"),)
"""Config sections that choose how, not what, is computed: left out of the config hash."""

log = logging.getLogger(__name__)
_WORLD: dict = {}  # per process: (scene spec, config hash) -> World (the last one)


RUN_KEYS_SET_HERE = {"max_steps": "each run's budget is mapgen.max_steps", "depth": "each run's depth is its "
                     "entry's in mapgen.runs", "seed": "each run is seeded from --seed and its scene",
                     "video_fps": "mapgen writes no video", "video_every_steps": "mapgen writes no video"}
"""The ``run`` keys of ``configs/explore.yaml`` that mapgen does not read, and what it uses instead."""


def load_mapgen_config(user_file=None, overrides=()):
    """``configs/explore.yaml`` with its run sections (:func:`~frontiernet.exploration.run.load_run_config`)
    and ``configs/mapgen.yaml`` (section ``mapgen``), then a user YAML file and ``key=value`` overrides.
    InputError for a user's value of a key of :data:`RUN_KEYS_SET_HERE` (it would be ignored in silence)."""
    from frontiernet.exploration.run import load_run_config

    names = ("explore", "mapgen")
    conf = load_run_config(user_file, overrides, names=names)
    if user_file is not None or overrides:
        shipped = load_run_config(names=names).run
        for key, instead in RUN_KEYS_SET_HERE.items():
            if conf.run.get(key) != shipped.get(key):
                raise InputError(f"run.{key}: mapgen does not read it ({instead}), got {conf.run.get(key)!r}")
    return conf


def config_hash(conf) -> str:
    """Short SHA-256 of :func:`hashed_settings`: names a dataset's settings."""
    return hashlib.sha256(json.dumps(hashed_settings(conf), sort_keys=True, separators=(",", ":")).encode()
                          ).hexdigest()[:16]


def hashed_settings(conf) -> dict:
    """The settings of a config (resolved, or the plain dict dataset.json stores) that :func:`config_hash`
    hashes: all but :data:`RUNTIME_KEYS` and the method sections (:data:`~frontiernet.benchmark.changes.
    METHOD_SECTIONS`, e.g. ``nbvp``) that no run of ``mapgen.runs`` reads, so a change to another method
    leaves the dataset resumable (a resume names the first setting that differs); a key added to the configs after
    the dataset was made (:data:`~frontiernet.benchmark.changes.KEYS_ADDED_AFTER_PLANS`, e.g.
    ``map_frontiers.min_cells_before_stop``) that its stored config lacks is read with the value under which the code
    ran before the key (:func:`~frontiernet.benchmark.changes.with_keys_added_after`), so the dataset resumes with
    that value (and is refused, naming it, with another)."""
    from frontiernet.benchmark.changes import METHOD_SECTIONS, with_keys_added_after

    settings = with_keys_added_after(OmegaConf.to_container(OmegaConf.create(conf), resolve=True))
    for section, key in RUNTIME_KEYS:
        settings.get(section, {}).pop(key, None)
    methods_run = {run.get("method") for run in settings.get("mapgen", {}).get("runs") or [] if isinstance(run, dict)}
    for section, readers in METHOD_SECTIONS.items():
        if not methods_run & set(readers):
            settings.pop(section, None)
    return settings


def _read_info_rehashed(out: Path) -> dict:
    """The dataset.json of `out` with its ``config_hash`` recomputed from its stored config by today's
    :func:`config_hash`: a dataset made before a method section was left out of the hash, or before a key was added
    (:func:`hashed_settings`), still resumes."""
    info = read_map_dataset_info(out)
    if isinstance(info.get("config"), dict):
        info = {**info, "config_hash": config_hash(OmegaConf.create(info["config"]))}
    return info


def check_runs(conf) -> list[dict]:
    """The checked ``mapgen`` settings' runs as [{method, depth}]; InputError naming the first bad key (a
    ``first_snapshot_step`` at or past ``max_steps`` too: no run would take a snapshot), or a run's method or
    depth source whose files are missing (a predictor, a depth model's weights)."""
    from frontiernet.depth import DEPTH_SOURCES, check_depth_files, depth_source_name
    from frontiernet.exploration.methods import METHODS, check_method
    from frontiernet.exploration.run import MAX_STEPS

    section = conf.mapgen
    max_steps = whole_number(section.max_steps, "mapgen.max_steps", 1, MAX_STEPS)  # an exploration run's budget
    whole_number(section.snapshot_every_steps, "mapgen.snapshot_every_steps", 1, MAX_STEPS)
    first = whole_number(section.first_snapshot_step, "mapgen.first_snapshot_step", 0, MAX_STEPS)
    if first >= max_steps:  # a dataset of no snapshot
        raise InputError(f"mapgen.first_snapshot_step {first} must be below mapgen.max_steps {max_steps} (each run's "
                         "step budget): the runs would end before (or at) their first snapshot")
    runs = OmegaConf.to_container(section.runs, resolve=True) if section.runs is not None else []
    if not isinstance(runs, list) or not runs:
        raise InputError("mapgen.runs must list at least one run ({method: NAME, depth: SOURCE})")
    checked = []
    for index, run in enumerate(runs):
        if not isinstance(run, dict) or set(run) != {"method", "depth"}:
            raise InputError(f"mapgen.runs[{index}] must be a mapping with exactly the keys method and depth, "
                             f"got {run!r}")
        if run["method"] not in METHODS:
            raise InputError(f"mapgen.runs[{index}].method: unknown exploration method {run['method']!r}; "
                             f"known: {', '.join(METHODS.names())}")
        depth = depth_source_name(str(run["depth"]))
        if depth not in DEPTH_SOURCES:
            raise InputError(f"mapgen.runs[{index}].depth: unknown depth source {run['depth']!r}; known: gt, "
                             f"{', '.join(DEPTH_SOURCES.names())}")
        check_method(str(run["method"]), None, conf)  # its own files (seer's, mapex's predictor) and the
        check_depth_files(depth, conf.get("depth"))  # depth model's weights: refused now, not by every run
        checked.append({"method": str(run["method"]), "depth": depth})
    return checked


@dataclass(frozen=True)
class MapTask:
    """One shard: run `run_index` (`method` with `depth`) of scene `spec`, seeded with `seed`."""

    spec: str
    scene_index: int
    run_index: int
    method: str
    depth: str
    seed: int
    path: str


def plan_map_tasks(specs: list[str], runs: list[dict], seed: int, out: Path) -> list[MapTask]:
    """The shards of a run, scene by scene."""
    return [MapTask(spec, scene_index, run_index, run["method"], run["depth"], shard_seed(seed, spec, run_index),
                    str(out / SHARDS_DIR / f"{scene_index:05d}-{_slug(spec)}-r{run_index:02d}.zip"))
            for scene_index, spec in enumerate(specs) for run_index, run in enumerate(runs)]


class Snapshots:
    """The explorer's step consumer that keeps the robot's map every ``snapshot_every_steps`` steps from
    ``first_snapshot_step`` on (packed bits: a KTH plan's map is 16 M voxels), with its map frontiers."""

    def __init__(self, conf) -> None:
        self.conf, self.taken = conf, []
        self.every = int(conf.mapgen.snapshot_every_steps)
        self.next_step = int(conf.mapgen.first_snapshot_step)

    def __call__(self, explorer, record, frame, seen) -> None:
        from frontiernet.frontiers.map_frontiers import map_frontiers

        if record.step < self.next_step:
            return
        self.next_step = (record.step // self.every + 1) * self.every
        occupancy, z = explorer.map, explorer.motion.z
        frontiers = map_frontiers(occupancy, z, self.conf, explorer.agent.pose, gain="uniform")
        if not frontiers:  # nothing near a frontier to learn or score
            return
        self.taken.append({
            "observed": np.packbits(occupancy.observed.reshape(-1)),
            "occupied": np.packbits(occupancy.occupied_mask().reshape(-1)),
            "record": {"step": int(record.step), "position": [round(float(v), 4) for v in record.position],
                       "yaw": round(float(record.yaw), 4),
                       "floor_z": round(z - float(self.conf.motion.camera_height_m), 4),
                       "coverage": round(float(record.coverage), 5), "known_m3": round(float(record.known_m3), 3),
                       "frontiers": [[round(float(f.position[0]), 3), round(float(f.position[1]), 3), int(f.num_pixels)]
                                     for f in frontiers]}})


def _world(spec: str, conf, digest: str):
    from frontiernet.simulator.world import build_world

    key = (spec, digest)
    if key not in _WORLD:
        _WORLD.clear()
        _WORLD[key] = build_world(spec, conf.sim, conf.scenes)
    return _WORLD[key]


def run_map_task(task: dict, conf_dict: dict, info: dict) -> dict:
    """Explore one scene once and write its shard (:class:`MapTask`); never raises: a failure comes back
    as a result with its error (one line)."""
    from frontiernet.depth import make_depth_source
    from frontiernet.exploration.explorer import Explorer
    from frontiernet.exploration.methods import MethodContext, make_method
    from frontiernet.exploration.region import sample_start

    start = time.perf_counter()
    name = os.path.basename(task["path"])
    try:
        seed = int(task["seed"]) % (2 ** 31)
        conf = OmegaConf.merge(OmegaConf.create(conf_dict), {"run": {"seed": seed, "depth": task["depth"]}})
        world = _world(task["spec"], conf, info["config_hash"])
        rng = np.random.default_rng(task["seed"])
        T_start = sample_start(world.scene, world.voxels, conf, rng)
        depth = make_depth_source(task["depth"], conf.depth)
        depth.reset(seed)
        context = MethodContext(conf, conf.sim, None, world.scene, world.voxels)
        snapshots = Snapshots(conf)
        explorer = Explorer(context, world.renderer, make_method(task["method"], context), depth, T_start,
                            on_step=(snapshots,))
        result = explorer.run(int(conf.mapgen.max_steps))
        voxels = world.voxels
        meta = {"scene": task["spec"], "scene_index": task["scene_index"], "run_index": task["run_index"],
                "method": task["method"], "depth": task["depth"], "seed": task["seed"],
                "start": np.round(T_start, 5).tolist(), "origin": voxels.origin.tolist(),
                "voxel_size": float(voxels.voxel_size), "stop_reason": result.stop_reason,
                "steps": int(result.records[-1].step), "coverage": float(result.records[-1].coverage),
                "camera_height_m": float(conf.motion.camera_height_m), "config_hash": info["config_hash"],
                "generator_version": info["generator_version"]}
        write_map_shard(task["path"], {"occupied": voxels.occupied, "explorable": voxels.explorable},
                        snapshots.taken, meta)
        return {"task": name, "spec": task["spec"], "ok": True, "snapshots": len(snapshots.taken),
                "steps": meta["steps"], "seconds": time.perf_counter() - start}
    except InputError as error:  # the scene's fault (a bad spec option, an unreadable file)
        message, bad_input = scene_error(task["spec"], error), True
    except Exception as error:  # a failing scene is reported, never kills the run
        log.debug("map shard %s failed", name, exc_info=True)
        message, bad_input = f"{type(error).__name__}: {error}", False
    return {"task": name, "spec": task["spec"], "ok": False, "error": (message.splitlines() or [""])[0],
            "bad_input": bad_input, "seconds": time.perf_counter() - start}


class _Progress:
    """A rich bar of finished runs (snapshots and failures counted), or nothing."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.bar, self.snapshots, self.failed = None, 0, 0
        if enabled and total:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, \
                TimeRemainingColumn

            self.bar = Progress(TextColumn("mapgen"), BarColumn(), MofNCompleteColumn(),
                                TextColumn("runs  {task.fields[note]}"), TimeElapsedColumn(), TimeRemainingColumn())
            self.task = self.bar.add_task("runs", total=total, note="")
            self.bar.start()

    def done(self, result: dict) -> None:
        self.snapshots += result.get("snapshots", 0)
        self.failed += not result["ok"]
        if self.bar is not None:
            note = f"{self.snapshots} snapshots" + (f", {self.failed} failed" if self.failed else "")
            self.bar.update(self.task, advance=1, note=note)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def generate_maps(scenes: list[str], out: str | Path, conf, *, seed: int = 0, workers: int = 1,
                  backend: str = "local", resume: bool = False, progress: bool = True) -> dict:
    """Generate (or resume) a map dataset in `out`; returns the summary also written to ``out/summary.json``.

    Raises:
        InputError: bad scenes, settings or options, an unusable `out` or one another run writes
            (:func:`~frontiernet.io.claim_output_folder`), a resume that does not match the dataset there (all
            before anything is written). Failing scenes do not raise: they are reported.
    """
    from frontiernet.scenes.spec import checked_spec, expand_specs
    from frontiernet.workers import check_backend, run_parallel

    from .backends import _init_worker

    out = Path(out)
    if not scenes:
        raise InputError("no scenes given (--scenes SPEC ...)")
    check_seed(seed, "--seed")
    check_backend(backend, workers)
    runs = check_runs(conf)
    voxel_size = positive_number(conf.sim.voxels.voxel_size, "sim.voxels.voxel_size", "metres")
    if not np.isclose(voxel_size, float(conf.map.voxel_size), rtol=1e-9, atol=0.0):
        raise InputError(f"map.voxel_size {conf.map.voxel_size} m differs from sim.voxels.voxel_size {voxel_size} m")
    specs = expand_specs(scenes)
    for spec in specs:
        checked_spec(spec)  # a malformed or missing scene fails before any work starts
    conf_dict = OmegaConf.to_container(conf, resolve=True)
    info = {"generator_version": GENERATOR_VERSION, "config_hash": config_hash(conf), "seed": seed, "scenes": specs,
            "runs": runs, "voxel_size": voxel_size, "config": conf_dict}
    check_output_name(out / INFO_NAME)  # before the system is asked about it (ENAMETOOLONG)
    created, existed = not (out / INFO_NAME).exists(), out.exists()
    with claim_output_folder(out, force=True):  # one run at a time writes a dataset (--resume included)
        prepare_output(out, info, resume, ("config_hash", "seed", "scenes", "runs", "voxel_size", "generator_version"),
                       _read_info_rehashed, write_map_dataset_info, command="mapgen", settings=hashed_settings,
                       shard_kind="map shard")
        remove_stale_temporaries(out / SHARDS_DIR)
        tasks = plan_map_tasks(specs, runs, seed, out)
        todo = [task for task in tasks if not map_shard_complete(task.path)]
        bar = _Progress(len(todo), progress)
        start = time.perf_counter()
        threads = max(1, (os.cpu_count() or 1) // workers)

        def died(index: int, error: str) -> dict:
            return {"task": os.path.basename(todo[index].path), "spec": todo[index].spec, "ok": False, "error": error,
                    "bad_input": False, "seconds": 0.0}

        try:
            with drop_stale_caches(out, [task.path for task in todo]):  # derived from the dataset as it was
                results = run_parallel(run_map_task, [(asdict(task), conf_dict, info) for task in todo],
                                       backend=backend, workers=workers, died=died, retries=1,
                                       on_result=lambda index, result: bar.done(result),
                                       initializer=_init_worker if workers > 1 else None, initargs=(None, threads))
        finally:
            bar.close()
        remove_stale_temporaries(out / SHARDS_DIR)
        summary = summarise_maps(tasks, results, time.perf_counter() - start, len(tasks) - len(todo))
        if created and summary["runs"] == 0 and results:  # every run failed: leave no empty dataset in the way
            if existed:
                shutil.rmtree(out / SHARDS_DIR, ignore_errors=True)
                (out / INFO_NAME).unlink(missing_ok=True)
            else:
                shutil.rmtree(out)
            failures = summary["failed_scenes"] or [{"scene": specs[0], "error": "no run made"}]
            failure = failures[0]
            raise InputError(f"{failure['scene']}: {failure['error']} (every run failed; nothing was left in {out})")
        write_json(out / "summary.json", summary)
        return summary


def summarise_maps(tasks: list[MapTask], results: list[dict], seconds: float, done_before: int) -> dict:
    """Runs, snapshots and frontier pieces on disk, failures and speed of this run."""
    shards = [Path(task.path) for task in tasks if Path(task.path).is_file()]
    metas = [read_map_shard_meta(path) for path in shards]
    failures = {}
    for result in results:
        if not result["ok"]:
            failures.setdefault(result["spec"], (result["error"], result.get("bad_input", False)))
    made = [r for r in results if r["ok"]]
    return {"runs": len(shards), "runs_planned": len(tasks), "runs_done_before": done_before,
            "scenes": len({meta["scene"] for meta in metas}),
            "snapshots": sum(len(meta["snapshots"]) for meta in metas),
            "frontier_pieces": sum(len(r["frontiers"]) for meta in metas for r in meta["snapshots"]),
            "runs_this_session": len(made), "seconds": round(seconds, 1),
            "seconds_per_run": round(sum(r["seconds"] for r in made) / len(made), 2) if made else None,
            "failed_scenes": [{"scene": spec, "error": error, "bad_input": bad}
                              for spec, (error, bad) in failures.items()],
            "failed_runs": len(results) - len(made)}
