"""Benchmark plan: start poses per scene and the runs (scene x method x start x repeat).

Start poses are sampled once per scene with the benchmark's seed (the explorer's own
:func:`~frontiernet.exploration.region.start_sampler`: camera height above the floor, clearance
from obstacles, inside the region the robot can travel, random heading) and shared by every
method and repeat, so methods differ by their goal choice alone. Repeat r of a start runs with
seed ``seed + r`` (the depth source, anchoring's pixel subset and random methods draw from it).
A method that draws nothing, with a depth source that is not seeded (``classic`` and
``gain-distance`` on ground-truth depth:
:func:`~frontiernet.exploration.methods.repeats_identically`), would repeat its run exactly:
its repeats > 0 are marked ``copy_of`` repeat 0 and reported from it instead of being run again.

With several depth sources (``frontiernet bench --depth gt,emulated``: the paper's ground-truth
and monocular regimes), every (scene, start, repeat, method) runs once per source, from the same
start pose with the same seed; each run carries its source (:attr:`RunSpec.depth`, in its key),
and whether its repeats are copies is decided by its own source. With one source the runs carry
none and their keys are those of every benchmark made before several existed.
"""

from __future__ import annotations

import hashlib
import logging
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..config import dotted_parent
from ..errors import InputError

log = logging.getLogger(__name__)

MIN_BUDGET = 4  # Vox@25 needs a step at a quarter of the budget

KEYS_ADDED_AFTER_PLANS = {
    "planner.approach_radius_m": 0.0,  # 0cebd7e: 0 = the paper's tree edge only, as before the key
    # 5ce9d0d: the explorable-space rule; plans made before it used the enclosed rule, which ignores
    # the reachable rule's four settings (listed with their defaults). A plan without them resumes
    # with --set sim.voxels.explorable=enclosed (the same voxels on every published scene)
    "sim.voxels.explorable": "enclosed",
    "sim.voxels.wall_gap_m": 1.5,
    "sim.voxels.floor_headroom_m": 1.0,
    "sim.voxels.floor_clearance_m": 0.2,
    "sim.voxels.seed_search_m": 0.5,
    "tracking.observe_every_steps": 1,  # every frame, as before the key
    # 3cfd09c: the monocular sensor model of the map, off (null) as before the keys
    "map.monocular_hit_range_m": None,
    "map.monocular_free_fraction": None,
    "map.monocular_far_hit_max": None,
    "map.monocular_log_odds_miss": None,
    "planner.obstacle_memory_frames": 0,  # map-free mode's obstacle memory, off as before the key
    # 1d0b1c0: the public code's cluster merge, off (nearest) as before the key; its settings do
    # nothing under nearest (listed with their defaults)
    "tracking.merge": "nearest",
    "tracking.merge_clusters": {"eps": 1.8, "direction_weight": 2.0},
    "planner.traversed_is_free": False,  # the map alone decides what is traversable, as before the key
    # issue 54: the omniscient bound's settings (they change no run of any other method)
    "omniscient": {"candidate_spacing_m": 0.7, "yaw_count": 8, "view_width_px": 16, "max_candidates": 150,
                   "refresh_every_steps": 1},
    "planner.forgive_before_stop": False,  # issue 54: a goal given up on stays given up on, as before
    # issue 55: the explorable space of one storey (null: the largest floor's seed, only the void cut)
    "sim.voxels.storey_floor_share": None,
    "sim.voxels.storey_slab_share": None,
    # issue 54: oblique monocular pixels left out of the map (null: all integrated, as before the keys)
    "map.monocular_max_incidence_deg": None,
    "map.monocular_normal_window_px": 9,
    "planner.start_failure": "blame",  # issue 54: a route's failed first increment always blames its goal, as before
    "planner.monocular_traversed_is_free": False,  # issue 54: monocular maps alone decide what is traversable, as before
    "planner.bumps_are_obstacles": False,  # issue 54: a collision leaves the robot's map as it was, as before
    # --method nbvp's settings (Bircher et al. 2016; they change no run of any other method)
    "nbvp": {"extension_m": 1.0, "degressive_coeff": 0.5, "init_iterations": 15, "cutoff_iterations": 200,
             "gain_range_m": 3.5, "gain_width_px": 16, "yaw_samples": 1, "overshoot_m": 0.0, "attempts_per_node": 1000,
             "stall_frames": 17, "found_on": "views", "yaw_window_deg": 45.0, "sample_region": "box",
             "edge_check": "body"},
    # issue 54: NBVP's gain test on the branch's views and its node yaws within the drive window; a plan made with
    # the nbvp section before them ran the discounted test and uniform yaws (one without it ran no nbvp: the above)
    "nbvp.found_on": "discounted",
    "nbvp.yaw_window_deg": 180.0,
    "nbvp.sample_region": "known_free",  # issue 54: the tree's goals drawn over the known-free cells, as before the key
    "nbvp.edge_check": "cells",  # issue 54: the tree's edge points checked by their cell only, as before the key
    # issue 56: the map-predicting methods' settings (they change no run of any other method)
    "seer": {"predictor": None, "candidate_rmin_m": 0.5, "candidate_rmax_m": 1.2, "candidate_rnum": 3,
             "candidate_dphi_deg": 15.0, "yaw_offsets_deg": [-50.0, -30.0, -10.0, 10.0, 30.0, 50.0],
             "min_view_distance_m": 0.75, "max_velocity_mps": 1.0, "w_dir": 1.5, "cluster_min_cells": 5,
             "cluster_max_extent_m": 2.4, "view_width_px": 16, "repredict_new_voxels": 5000,
             "max_predictions_per_step": 2, "reuse_distance_m": 1.0},
    "mapex": {"predictor": None, "min_cells": 11, "max_extent_m": 1000.0, "visibility_range_m": 3.5, "num_rays": 256,
              "hit_probability": 0.8, "repredict_new_cells": 300, "value_floor": 1e-06},
    # issue 56: frontiernet-mapex's settings (they change no run of any other method)
    "frontiernet_mapex": {"weight": 0.5, "column_height_m": 2.5},
    # the step account's thresholds (exploration/steps.py: metrics.json's step_account): reporting only, no run changes
    "steps": {"translation_m": 0.02, "new_volume_m3": 0.05, "revisit_cell_m": 0.5, "revisit_after_steps": 10,
              "livelock_window_steps": 50, "livelock_gain_m3": 1.0, "livelock_radius_m": 2.0,
              "premature_unseen": 0.1, "reachable_dilation_m": 0.3},
}
"""Keys added to ``configs/explore.yaml`` after benchmarks had been planned, each with the value
under which the code runs as it did before the key existed. The rule: a ``plan.json`` whose config
lacks such a key is read as having that value (:func:`with_keys_added_after`), so the benchmark
resumes when this run's config has that value too and is refused when it sets another (a change
of settings). A key whose default changes what runs do must not be listed: a plan without it then
stays refused, as every plan that lacks or differs in any other key."""


@dataclass(frozen=True)
class RunSpec:
    """One exploration run of the benchmark.

    Attributes:
        scene: scene spec; method: method name; start, repeat: indices.
        start_pose: (x, y, z, yaw) metres and degrees, world frame.
        seed: the run's seed.
        copy_of: the key of the run this one would repeat exactly (not run; see the module
            docstring), or None.
        depth: the run's depth source (a name of :data:`frontiernet.depth.SOURCES`) when the
            benchmark has several, else None (every run takes the benchmark's one source).
        max_steps: the run's step budget: its scene's under scene-sized budgets (:mod:`.budget`),
            else None (every run takes the benchmark's one fixed budget).
    """

    scene: str
    method: str
    start: int
    repeat: int
    start_pose: tuple
    seed: int
    copy_of: str | None = None
    depth: str | None = None
    max_steps: int | None = None

    @property
    def key(self) -> str:
        """Relative folder of the run's outputs: ``<scene key>/<method>/start<i>_repeat<r>``, and
        with a depth source ``<scene key>/<method>@<depth>/start<i>_repeat<r>`` (a pack per
        scene, method and source: :mod:`.store`)."""
        group = f"{self.method}@{self.depth}" if self.depth else self.method
        return f"{scene_key(self.scene)}/{group}/start{self.start}_repeat{self.repeat}"

    def as_dict(self) -> dict:
        """The run as plan.json stores it; ``depth`` and ``max_steps`` only when set (a one-source,
        fixed-budget plan is as before)."""
        record = {**asdict(self), "start_pose": list(self.start_pose)}
        for optional in ("depth", "max_steps"):
            if record[optional] is None:
                del record[optional]
        return record


def depth_sources(depth: str | None, conf) -> list[str]:
    """The depth sources of a benchmark: `depth` (``--depth``), or ``run.depth`` when None, as a
    comma list of names of :data:`frontiernet.depth.SOURCES` (aliases resolved: ``gt``).

    Raises:
        InputError: an empty item, an unknown source (the valid ones listed) or one given twice
            (``gt,ground_truth`` too).
    """
    from ..depth import known_source

    text = str(depth or conf.run.depth)
    names = []
    for item in text.split(","):
        if not item.strip():
            raise InputError(f"depth sources '{text}' (--depth, run.depth) have an empty item")
        name = known_source(item.strip())
        if name in names:
            raise InputError(f"depth source '{name}' is given twice in '{text}' (--depth, run.depth)")
        names.append(name)
    return names


def _on_ground_truth_only(stored: dict) -> bool:
    from omegaconf import OmegaConf

    return depth_sources(stored["depth"], OmegaConf.create(stored["conf"])) == ["ground_truth"]


def _in_map_mode(stored: dict) -> bool:
    return str(stored["conf"]["planner"]["mode"]) == "map"


def _under_the_enclosed_rule(stored: dict) -> bool:
    """The plan's explorable space is the ``enclosed`` rule's (a plan without the key predates the
    ``reachable`` rule: :data:`KEYS_ADDED_AFTER_PLANS`), which reads no ``reachable`` setting."""
    voxels = stored["conf"].get("sim", {}).get("voxels", {})
    return str(voxels.get("explorable", KEYS_ADDED_AFTER_PLANS["sim.voxels.explorable"])) == "enclosed"


KEYS_IDLE_WHEN = {
    "map.depth_edge_rtol": _on_ground_truth_only,  # the map leaves out depth edges only for sources
                                                   # with flying pixels (94cd18a)
    "planner.obstacle_memory_frames": _in_map_mode,  # the map-free move check's memory (7d7d5e4)
    "sim.voxels.storey_floor_share": _under_the_enclosed_rule,  # the reachable rule's storey (issue 55)
    "sim.voxels.storey_slab_share": _under_the_enclosed_rule,
}
"""Keys added to ``configs/explore.yaml`` after benchmarks had been planned that change no run of
a plan meeting the key's condition (a function of the stored settings). Such a plan that lacks the
key resumes with the value this run's config has (:func:`with_idle_keys`), whatever its default;
a plan that does not meet the condition reads the key as :data:`KEYS_ADDED_AFTER_PLANS` says, or
is refused, as its runs would change."""


def with_idle_keys(stored: dict, settings: dict) -> dict:
    """A stored plan's settings (a dict, changed in place and returned) with each key of
    :data:`KEYS_IDLE_WHEN` its config lacks taken from this run's `settings`, where the plan meets
    the key's condition (see there). Call it before :func:`with_keys_added_after`."""
    for dotted, idle in KEYS_IDLE_WHEN.items():
        section, key = dotted_parent(stored["conf"], dotted)
        now, now_key = dotted_parent(settings["conf"], dotted)
        if section is not None and key not in section and now is not None and now_key in now and idle(stored):
            section[key] = now[now_key]
    return stored


def with_keys_added_after(conf: dict) -> dict:
    """A stored plan's run config (a dict, changed in place and returned) with every key of
    :data:`KEYS_ADDED_AFTER_PLANS` it lacks set to the value of the code before the key (see there);
    a key it has keeps its value."""
    for dotted, old_behaviour in KEYS_ADDED_AFTER_PLANS.items():
        section, key = dotted_parent(conf, dotted)
        if section is not None:
            section.setdefault(key, old_behaviour)
    return conf


def differences(old, new, prefix: str = ""):
    """Every dotted key whose value differs between two nested dicts, in sorted key order, as
    ``(key, "key: OLD in the plan, NEW now")`` (``absent`` for a missing key)."""
    if isinstance(old, dict) and isinstance(new, dict):
        for key in sorted(set(old) | set(new), key=str):
            name = f"{prefix}{key}"
            if key not in old or key not in new:
                shown = [repr(side[key]) if key in side else "absent" for side in (old, new)]
                yield name, f"{name}: {shown[0]} in the plan, {shown[1]} now"
            else:
                yield from differences(old[key], new[key], f"{name}.")
    elif old != new:
        name = prefix.rstrip(".")
        yield name, f"{name}: {old!r} in the plan, {new!r} now"


def first_difference(old, new, prefix: str = "") -> str | None:
    """The first of :func:`differences` as its text; None when equal."""
    return next((text for _, text in differences(old, new, prefix)), None)


METHOD_SECTIONS = {
    "nbvp": ("nbvp",),
    "omniscient": ("omniscient",),
    "seer": ("seer",),
    "mapex": ("mapex", "frontiernet-mapex"),  # frontiernet-mapex reads mapex's predictor settings
    "frontiernet_mapex": ("frontiernet-mapex",),
}
"""The sections of ``configs/explore.yaml`` that only some methods' runs read, with those methods
(the factories of :mod:`frontiernet.exploration.methods` that parse them)."""


@dataclass(frozen=True)
class Readers:
    """The runs of a benchmark that read one setting: those of depth sources `sources` and methods
    `methods` (None: every source, every method)."""

    sources: frozenset | None = None
    methods: frozenset | None = None

    def reads(self, run: dict, single_source: str) -> bool:
        """Whether the planned `run` (a plan's ``runs`` entry) is one of them; `single_source`: the
        source of a plan whose runs carry none."""
        return ((self.sources is None or (run.get("depth") or single_source) in self.sources)
                and (self.methods is None or run["method"] in self.methods))

    def __str__(self) -> str:  # "emulated-depth runs", "nbvp runs", "emulated-depth nbvp runs"
        words = [] if self.sources is None else [" and ".join(sorted(self.sources)) + "-depth"]
        words += [] if self.methods is None else [" and ".join(sorted(self.methods))]
        return " ".join(words + ["runs"])


def _runs_reading(dotted: str, stored: dict | None = None, settings: dict | None = None) -> Readers | None:
    """The benchmark runs that alone read the setting `dotted` (``conf.<section>.<key>...``): the map's
    monocular sensor model and its depth-edge filter apply only to sources with flying pixels
    (:meth:`~frontiernet.mapping.checks.MapSettings.ray_model`), as the planner's ``monocular_*`` keys
    (:class:`~frontiernet.exploration.explorer.Explorer`), and ``planner.traversed_is_free`` only to
    sources without them while ``planner.monocular_traversed_is_free`` holds in both the stored and
    this run's `settings` (the others keep their traversed cells either way); a source's own ``depth``
    section only to it, a method's own section (:data:`METHOD_SECTIONS`) only to that method's runs;
    None for every other setting (read by every run)."""
    from ..depth import SOURCES

    parts = dotted.split(".")
    section, key = (parts[1], parts[2]) if len(parts) > 2 and parts[0] == "conf" else (None, "")
    flying = frozenset(name for name, source in SOURCES.items() if source.flying_pixels)
    if (section in ("map", "planner") and key.startswith("monocular_")) or (section, key) == ("map", "depth_edge_rtol"):
        return Readers(sources=flying)
    if (section, key) == ("planner", "traversed_is_free") and all(bool(((side or {}).get("conf") or {}).get(
            "planner", {}).get("monocular_traversed_is_free")) for side in (stored, settings)):
        return Readers(sources=frozenset(SOURCES) - flying)
    if len(parts) > 2 and parts[:2] == ["conf", "depth"] and parts[2] in SOURCES:
        return Readers(sources=frozenset({parts[2]}))
    if len(parts) > 1 and parts[0] == "conf" and parts[1] in METHOD_SECTIONS:
        return Readers(methods=frozenset(METHOD_SECTIONS[parts[1]]))
    return None


def blocking_difference(stored: dict, settings: dict) -> str | None:
    """The first of :func:`differences` that :func:`runs_changed` cannot redo (a setting that every
    run reads), as its text; else the first difference; None when equal."""
    found = list(differences(stored, settings))
    blocking = [text for dotted, text in found if _runs_reading(dotted, stored, settings) is None]
    return (blocking or [text for _, text in found] or [None])[0]


def runs_changed(plan: dict, settings: dict) -> tuple[list[str], list[Readers]] | None:
    """The planned runs of a stored `plan` (``settings`` as :func:`with_idle_keys` and
    :func:`with_keys_added_after` leave them, and ``runs``) that this run's `settings` change, when
    every setting in which the two differ is read by some runs alone (:func:`_runs_reading`): (their
    keys, in plan order; the readers of the changed settings). Empty keys: the change reaches none of
    its runs (a monocular key of a ground-truth plan, the section of a method it does not run). None
    when a setting that every run reads differs (another benchmark)."""
    from omegaconf import OmegaConf

    stored = plan["settings"]
    sources = depth_sources(stored["depth"], OmegaConf.create(stored["conf"]))
    methods = {run["method"] for run in plan["runs"]}
    readers = []
    for dotted, _ in differences(stored, settings):
        reader = _runs_reading(dotted, stored, settings)
        if reader is None:
            return None
        reader = Readers(None if reader.sources is None else reader.sources & frozenset(sources),
                         None if reader.methods is None else reader.methods & frozenset(methods))
        if reader.sources != frozenset() and reader.methods != frozenset() and reader not in readers:
            readers.append(reader)  # (as described: the plan's own sources and methods among them)
    keys = [run["key"] for run in plan["runs"] if any(reader.reads(run, sources[0]) for reader in readers)]
    return keys, readers


def scene_key(spec: str) -> str:
    """A short, filesystem-safe, unique name of a scene spec (its stem and a spec hash)."""
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(str(spec).split("?")[0]).name or str(spec))[:40]
    return f"{stem}-{hashlib.sha1(str(spec).encode()).hexdigest()[:6]}"


def start_poses(spec: str, count: int, seed: int, conf, scene_starts: bool = False, world=None) -> list[tuple]:
    """`count` start poses (x, y, z, yaw_deg) of scene `spec`, seeded (see the module docstring).

    With `scene_starts`, the positions a scene ships come first (a KTH plan folder's MapEx
    ``start_poses.json``, in its order; heading seeded, camera at ``motion.camera_height_m``),
    except those outside the scene's main region (:func:`~frontiernet.exploration.region.start_sampler`:
    shut in by doors too narrow for the robot; logged and left out); sampled poses fill up the count.
    `world`: the scene's :func:`~frontiernet.exploration.run.planning_world`, when the caller has it already (None: built here).

    Raises:
        InputError: an unknown or unreadable scene, or one without free space to start from.
    """
    from ..exploration.motion import yaw_of
    from ..exploration.region import camera_z, start_sampler
    from ..exploration.run import planning_world

    world = world if world is not None else planning_world(spec, conf)
    scene, voxels = world.scene, world.voxels
    rng = np.random.default_rng([int(seed), int(hashlib.sha1(spec.encode()).hexdigest()[:8], 16)])
    region, draw = start_sampler(scene, voxels, conf)  # one clearance map for the check and the draws
    poses = []
    if scene_starts:
        z = camera_z(scene, voxels, conf)
        for index, (x, y) in enumerate(scene.metadata.extra.get("start_xy", [])):
            yaw = float(rng.uniform(-180.0, 180.0))
            i, j = voxels.world_to_index(np.array([x, y, z]))[:2]
            if not region[i, j]:
                log.warning("%s: shipped start %d at (%.2f, %.2f) is shut in by doors too narrow for the robot "
                            "(planner.clearance_m); left out", spec, index, x, y)
            elif len(poses) < count:
                poses.append((round(float(x), 4), round(float(y), 4), round(z, 4), round(yaw, 4)))
    while len(poses) < count:
        T = draw(rng)
        poses.append(tuple(round(float(v), 4) for v in (*T[:3, 3], np.degrees(yaw_of(T)))))
    return poses


def plan_runs(scenes: list[str], methods: list[str], starts: int, repeats: int, seed: int, conf,
              poses: dict | None = None, scene_starts: bool = False,
              depths: list[str] = ("ground_truth",), budgets: dict | None = None,
              rule=None) -> tuple[list[RunSpec], dict, dict | None]:
    """Every run of the benchmark, scene by scene, start by start, repeat by repeat, method by
    method, depth source by depth source, the start poses they use (scene -> list of
    (x, y, z, yaw_deg)) and, under scene-sized budgets, the budgets (scene -> steps; else None).
    Each scene is loaded once for what is missing of both.

    Args:
        poses: start poses already sampled, by scene (e.g. read back from a previous
            ``plan.json`` so a resumed benchmark keeps them); missing scenes are sampled.
        scene_starts: use the start positions a scene ships first (:func:`start_poses`).
        depths: the depth sources' names (:data:`frontiernet.depth.SOURCES`, as
            :func:`depth_sources` gives them); each decides with the method whether that
            source's repeats are copies. With several, each run carries its source (module docstring).
        budgets: scene -> step budget already set (read back from a previous ``plan.json``), with
            `rule`; rule: the :class:`~frontiernet.benchmark.budget.BudgetRule` of scene-sized budgets
            (each run carries its scene's; missing scenes are sized by it), or None: the benchmark's
            one fixed budget.
    Raises:
        InputError: no scenes or methods, an unknown method (the valid ones listed), starts or
            repeats below 1, a scene that does not load, `scene_starts` where no scene sampled here
            ships start poses.
    """
    from ..exploration.methods import method_names, repeats_identically

    if not scenes:
        raise InputError("give at least one scene (--scenes)")
    if not methods:
        raise InputError("give at least one method (--methods)")
    valid = method_names()
    for method in methods:
        if method not in valid:
            raise InputError(f"unknown method '{method}'; valid: {', '.join(valid)}")
    if int(starts) < 1 or int(repeats) < 1:
        raise InputError(f"--starts and --repeats must be at least 1, got {starts} and {repeats}")
    from ..exploration.run import planning_world
    from .budget import scene_budget

    given = set(poses or {})  # scenes whose poses a resumed plan holds
    poses, budgets = dict(poses or {}), None if rule is None else dict(budgets or {})
    runs, shipping = [], []  # shipping: the scenes sampled here that ship start poses
    for scene in scenes:
        need_poses = scene not in poses or len(poses[scene]) < int(starts)
        need_budget = budgets is not None and scene not in budgets
        world = planning_world(scene, conf) if need_poses or need_budget else None
        if need_poses:
            poses[scene] = start_poses(scene, int(starts), seed, conf, scene_starts, world)
            shipping += [scene] if world.scene.metadata.extra.get("start_xy") else []
        if need_budget:
            budgets[scene] = scene_budget(scene, conf, rule, world)[0]
        for start in range(int(starts)):
            for repeat in range(int(repeats)):
                for method in methods:
                    for depth in depths:
                        regime = depth if len(depths) > 1 else None
                        budget = None if budgets is None else int(budgets[scene])
                        first = RunSpec(scene, method, start, 0, tuple(poses[scene][start]), int(seed), depth=regime)
                        copy_of = first.key if repeat > 0 and repeats_identically(method, depth) else None
                        runs.append(RunSpec(scene, method, start, repeat, first.start_pose, int(seed) + repeat,
                                            copy_of, regime, budget))
    if scene_starts and not shipping and not given:  # (a resumed plan's poses were checked when it was made)
        raise InputError(f"--scene-starts: none of the scenes ships start poses (a KTH plan folder's "
                         "start_poses.json does), so every start would be drawn as without it; leave it out")
    return runs, {scene: [list(pose) for pose in poses[scene][:int(starts)]] for scene in scenes}, budgets


__all__ = ["RunSpec", "plan_runs", "depth_sources", "start_poses", "scene_key", "MIN_BUDGET", "KEYS_ADDED_AFTER_PLANS",
           "with_keys_added_after", "differences", "first_difference", "blocking_difference", "runs_changed", "Readers",
           "METHOD_SECTIONS"]
