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

from ..errors import InputError

log = logging.getLogger(__name__)

MIN_BUDGET = 4  # Vox@25 needs a step at a quarter of the budget

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

    text = str(conf.run.depth if depth is None else depth)  # (--depth '' names no source: not run.depth's)
    if not text.strip():
        known_source(text)  # the one line explore --depth '' gives: unknown, the valid ones listed
    names = []
    for item in text.split(","):
        if not item.strip():
            raise InputError(f"depth sources '{text}' (--depth, run.depth) have an empty item")
        name = known_source(item.strip())
        if name in names:
            raise InputError(f"depth source '{name}' is given twice in '{text}' (--depth, run.depth)")
        names.append(name)
    return names


def scene_key(spec: str) -> str:
    """A short, filesystem-safe, unique name of a scene spec (its stem and a spec hash)."""
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(str(spec).split("?")[0]).name or str(spec))[:40]
    return f"{stem}-{hashlib.sha1(str(spec).encode()).hexdigest()[:6]}"


def start_poses(spec: str, count: int, seed: int, conf, scene_starts: bool = False, world=None) -> list[tuple]:
    """`count` start poses (x, y, z, yaw_deg) of scene `spec`, seeded (see the module docstring).

    With `scene_starts`, the positions a scene ships come first (a KTH plan folder's MapEx
    ``start_poses.json``, in its order; heading seeded, camera at ``motion.camera_height_m``),
    except those outside the scene's main region (:func:`~frontiernet.exploration.region.start_sampler`:
    shut in by doors too narrow for the robot, or too near a wall; logged in one line and left out); sampled
    poses fill up the count. (A start outside the plan's rooms is the start file's error, refused when the plan
    loads: :func:`~frontiernet.scenes.floorplan.plan_start_positions`.)
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
    poses, left_out = [], []
    if scene_starts:
        z = camera_z(scene, voxels, conf)
        for index, (x, y) in enumerate(scene.metadata.extra.get("start_xy", [])):
            yaw = float(rng.uniform(-180.0, 180.0))
            i, j = voxels.world_to_index(np.array([x, y, z]))[:2]
            if not region[i, j]:
                left_out.append(f"{index} at ({x:.2f}, {y:.2f})")
            elif len(poses) < count:
                poses.append((round(float(x), 4), round(float(y), 4), round(z, 4), round(yaw, 4)))
    if left_out:  # (one line for the scene; a start off its plan's rooms was refused as the file's error on load)
        log.warning("%s: shipped start%s %s lie%s outside the region the robot can travel: shut in by doors too "
                    "narrow for it, or nearer a wall than planner.clearance_m = %g m; left out, sampled starts take "
                    "their place", spec, "s" if len(left_out) > 1 else "", ", ".join(left_out),
                    "" if len(left_out) > 1 else "s", float(conf.planner.clearance_m))
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
        if need_poses:  # a resumed plan's poses stay as they are (its finished runs started there); more added
            drawn = start_poses(scene, int(starts), seed, conf, scene_starts, world)
            poses[scene] = list(poses.get(scene, []))[:int(starts)] + list(drawn[len(poses.get(scene, [])):])
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


__all__ = ["RunSpec", "plan_runs", "depth_sources", "start_poses", "scene_key", "MIN_BUDGET"]
