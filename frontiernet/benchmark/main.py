"""``main(conf, scenes, methods, ...)``: the whole benchmark, behind ``frontiernet bench --scenes``."""

from __future__ import annotations

import copy
import logging
import time
from pathlib import Path

from omegaconf import OmegaConf

from ..config import dotted_parent, load_config
from ..depth import check_depth_files
from ..errors import InputError, check_seed, whole_number
from ..exploration.methods import check_method, method_names
from ..exploration.run import MAX_STEPS, RUN_SECTIONS, check_sections, load_run_config
from ..io import LOCK_NAME, check_output_files, check_output_folder, claim_output_folder
from ..scenes.spec import expand_specs
from ..workers import check_backend
from .changes import blocking_difference, runs_changed, with_idle_keys, with_keys_added_after
from .plan import MIN_BUDGET, depth_sources, plan_runs
from .budget import BudgetRule
from .report import common_starts, finished_methods, report_files, write_report
from .runner import finished_row, run_all, with_copies
from .store import FinishedRuns, discard_runs, plan_file, read_plan, write_plan


log = logging.getLogger(__name__)

MAX_STARTS = 1000
"""The most start poses per scene (``--starts``) and runs per start and method (``--repeats``) of a
benchmark: the paper's is 3 x 3; more would be sampled and planned for minutes before any run."""


def main(conf, scenes: list[str], methods: list[str], out: str | Path, *, starts: int = 3, repeats: int = 3,
         max_steps: int | None = None, workers: int = 1, backend: str = "local", seed: int | None = None,
         model=None, depth: str | None = None, scene_starts: bool = False, redo_changed: bool = False,
         progress: bool = True) -> dict:
    """Run every method on every scene from shared start poses and write the report to `out`.

    Args:
        conf: the run config (:func:`~frontiernet.exploration.run.load_run_config`: explore.yaml
            with the sections of :data:`~frontiernet.exploration.run.RUN_SECTIONS`, and the user's overrides); scenes: scene specs,
            expanded as datagen's (``procedural:1000-1009``, globs, a folder of KTH plans or
            HM3D scenes: :func:`~frontiernet.scenes.spec.expand_specs`);
        methods: method names (:mod:`frontiernet.exploration.methods`).
        starts, repeats: start poses per scene, runs per start and method.
        max_steps: one fixed step budget for every scene; None: scene-sized budgets, the paper's
            protocol (:mod:`.budget`, ``budget`` of ``configs/bench.yaml``), with Vox@25 / @50 at
            the steps where the methods on average reach 25 / 50 % coverage
            (:func:`~frontiernet.benchmark.report.add_shared_vox`). seed: start poses and run seeds
            (None: ``run.seed``); model: as ``frontiernet explore``.
        depth: the depth source as ``frontiernet explore`` takes it (None: ``run.depth``), or a
            comma list of sources (``gt,emulated``): every run once per source
            (:func:`~frontiernet.benchmark.plan.depth_sources`, :mod:`.plan`).
        workers, backend: parallel runs, ``local`` or ``ray``.
        scene_starts: start from the positions a scene ships (KTH plans: MapEx's) first.
        redo_changed: resume a benchmark whose settings differ only in settings that some of its
            runs alone read (``map.monocular_*`` and a source's ``depth`` section: that source's runs;
            a method's own section, ``nbvp``, ``omniscient``...: that method's runs;
            :func:`~frontiernet.benchmark.changes.runs_changed`): those finished runs are discarded and
            run again under this run's settings, the others kept.
    Returns:
        ``{"rows": [...], "results": path, "table": path, "plots": [...], "wall_s": s}``.
    Raises:
        InputError: an unknown method or scene, a budget too small for Vox@25, a model file
            that does not load, a depth list with an unknown, repeated or empty item, a changed
            plan in a folder that holds another benchmark's runs, a method the settings do not fit
            (:func:`~frontiernet.exploration.methods.check_method`), `scene_starts` where no scene
            ships start poses.
    """
    rule = None if max_steps is not None else BudgetRule.from_conf(load_config("bench").budget)
    budget = rule.min_steps if rule is not None else whole_number(max_steps, "--max-steps", 1, MAX_STEPS)
    if budget < MIN_BUDGET:
        raise InputError(f"the step budget must be at least {MIN_BUDGET} steps to measure Vox@25, got {budget}")
    whole_number(starts, "--starts", 1, MAX_STARTS)
    whole_number(repeats, "--repeats", 1, MAX_STARTS)
    seed = check_seed(conf.run.seed if seed is None else seed, "the seed (--seed, run.seed)", repeats)
    check_sections(conf)  # (a run's settings refused by every run, each after its scene loaded)
    out = check_output_folder(out, force=True)  # (a benchmark folder resumes)
    if out.is_dir() and plan_file(out) is None and any(path.name != LOCK_NAME for path in out.iterdir()):
        raise InputError(f"{out} holds files but no benchmark (no plan.json): give an empty or new --out "
                         "(a benchmark folder's own files are only its plan, runs and report)")
    check_backend(backend, workers)  # before plan.json is written: a refused run leaves nothing behind
    depths = depth_sources(depth, conf)
    for name in depths:  # weights missing: refused now, not as every run failing
        check_depth_files(name, conf.get("depth"))
    scenes = expand_specs(scenes)
    stored = read_plan(out) if plan_file(out) is not None else {"start_poses": {}, "runs": []}  # (re-read under the lock)
    # the report's files, before the runs and before --redo-changed discards any (refused after them, it lost them)
    check_output_files(out, report_files([*stored["start_poses"], *(scene for scene in scenes
                                                                       if scene not in stored["start_poses"])]))
    valid = method_names()
    if not methods:
        raise InputError(f"--methods names no method; valid: {', '.join(valid)}")
    for index, method in enumerate(methods):
        if not method:  # as --depth: 'classic,' is a comma too many, not a list of one
            raise InputError(f"--methods '{','.join(methods)}': an empty method name (a comma too many?)")
        if method not in valid:
            raise InputError(f"unknown method '{method}'; valid: {', '.join(valid)}")
        if method in methods[:index]:
            raise InputError(f"--methods names {method} twice; each method runs once per scene, start and repeat")
        check_method(method, conf=conf)  # its own checks (seer, mapex: the predictor), --set planner.mode=map_free
    if model is not None:  # a file that does not load is one error now, not a failed run per run
        from ..exploration.methods import runs_frontiernet_model
        from ..model import open_runtime

        planned = {run["method"] for run in stored["runs"]}
        if not any(runs_frontiernet_model(method) for method in (*methods, *planned)):  # (a plan it grows: its own)
            raise InputError(f"--model {model}: none of the methods {', '.join(methods)} runs a FrontierNet model, "
                             "so --model would be ignored; leave it out (seer and mapex take their predictor "
                             "from --set seer.predictor=FILE / mapex.predictor=FILE)")
        open_runtime(model)
    settings = {"budget": budget if rule is None else rule.as_dict(), "seed": seed,
                "model": str(model) if model else None, "depth": depth, "scene_starts": bool(scene_starts),
                "conf": OmegaConf.to_container(conf, resolve=True)}
    if rule is not None:
        settings["vox_steps"] = "coverage"
    with claim_output_folder(out, force=True):  # one benchmark at a time in a folder (--pack and --report read it)
        poses, budgets, previous = None, None, None
        if plan_file(out) is not None:  # resuming: the same settings, the same start poses and budgets
            previous = resumable_plan(out, settings, redo_changed)
            poses, budgets = previous["start_poses"], previous.get("budgets")
            keys, readers = previous.get("redo_runs") or ([], [])
            if keys:  # before the plan takes the new settings: a run stopped between redoes the rest
                log.warning("%s: the settings of its %s changed; %d finished runs of them discarded, to run again",
                            out, ", ".join(map(str, readers)), discard_runs(out, keys))
        clock = time.perf_counter()
        runs, start_poses, budgets = plan_runs(list(scenes), list(methods), starts, repeats, seed, conf, poses,
                                               scene_starts, depths, budgets, rule)
        planned = [{**run.as_dict(), "key": run.key} for run in runs]
        if previous is not None:  # a resumed plan grows: its runs this command does not name stay in it
            planned, start_poses, budgets = grown_plan(previous, planned, start_poses, budgets)
        write_plan(out, {"settings": settings, "start_poses": start_poses,
                         **({"budgets": budgets} if budgets else {}), "runs": planned})
        run_all(runs, {"out": str(out), "conf": settings["conf"], "max_steps": budget,
                       "model": settings["model"], "depth": depth}, workers, backend, progress)
        written = report(out)  # every run of the plan, this command's and those it kept
        return {**written, "wall_s": round(time.perf_counter() - clock, 1)}


def grown_plan(previous: dict, planned: list[dict], start_poses: dict, budgets: dict | None):
    """The plan of a resumed benchmark: this command's runs (`planned`, as plan.json stores them) and
    those of the `previous` plan it does not name (other methods, scenes, starts or repeats: a
    benchmark grows by a command that names only what it adds, and ``--report`` keeps covering the
    rest), with the start poses and budgets of both (a scene's longer pose list wins: its first poses
    are the same, :func:`~frontiernet.benchmark.plan.plan_runs`).

    Returns:
        (runs, start_poses, budgets): runs in the previous plan's order, then the new ones.
    """
    named = {run["key"] for run in planned}
    kept = [run for run in previous["runs"] if run["key"] not in named]
    if kept:
        log.info("%d runs of the plan that this command does not name are kept in it (bench --report covers them)",
                 len(kept))
    poses = {scene: list(value) for scene, value in previous["start_poses"].items()}
    for scene, value in start_poses.items():
        if len(value) >= len(poses.get(scene, [])):
            poses[scene] = value
    if budgets is not None:
        budgets = {**(previous.get("budgets") or {}), **budgets}
    order = {run["key"]: index for index, run in enumerate(previous["runs"])}
    runs = sorted(kept + planned, key=lambda run: order.get(run["key"], len(order)))
    return runs, poses, budgets


SHIPPED_DEFAULTS_BEFORE_SECTIONS = {
    "sim.agent.radius_m": 0.2,  # 2026-12-06: 0.1 (a robot planned through 0.6 m doors)
    "sim.voxels.floor_clearance_m": 0.2,  # the same day: the agent's radius
}
"""Defaults of a run section's shipped file that changed after plans had been made without that
section (:data:`~frontiernet.exploration.run.RUN_SECTIONS`: such a plan ran the shipped file of its
day), with the value of before: :func:`shipped_before` puts them back."""


def shipped_before(section: str, shipped: dict) -> dict:
    """Today's shipped `section` (a dict, copied) with the keys of
    :data:`SHIPPED_DEFAULTS_BEFORE_SECTIONS` of that section at their value of before: the section a
    plan made without it ran with."""
    section_conf = copy.deepcopy(shipped)
    for dotted, value in SHIPPED_DEFAULTS_BEFORE_SECTIONS.items():
        name, _, rest = dotted.partition(".")
        if name == section:
            parent, key = dotted_parent(section_conf, rest)
            if parent is not None:
                parent[key] = value
    return section_conf


def resumable_plan(out: Path, settings: dict, redo_changed: bool = False) -> dict:
    """The plan stored in benchmark folder `out` (``plan.json``) when a benchmark with `settings`
    (as :func:`main` builds them) may resume it; InputError naming the first setting that differs.
    Settings that only some of its runs read (those of some depth sources or methods) may differ with
    `redo_changed` (:func:`~frontiernet.benchmark.changes.runs_changed`): the plan then carries
    ``redo_runs``, the keys of the runs they change and their description (:func:`main` discards
    those finished).

    A plan made before the run config had a section of
    :data:`~frontiernet.exploration.run.RUN_SECTIONS` (``sim``, ``depth``, ``ground_truth``,
    ``scenes``) used the shipped file, as it was then (:func:`shipped_before`);
    one made before a key of :data:`~frontiernet.benchmark.changes.KEYS_ADDED_AFTER_PLANS` existed
    ran as that key's listed value does; a plan made before a key of
    :data:`~frontiernet.benchmark.changes.KEYS_IDLE_WHEN` existed, whose runs that key does not change
    (ground-truth depth, map mode), takes this run's value.
    Anything else that differs is a change of settings."""
    previous = read_plan(out, resume=True)
    shipped = OmegaConf.to_container(load_run_config(), resolve=True)
    for section in RUN_SECTIONS:  # a plan made before runs had these sections used the shipped files
        if section not in previous["settings"]["conf"]:
            previous["settings"]["conf"][section] = shipped_before(section, shipped[section])
    with_idle_keys(previous["settings"], settings)
    with_keys_added_after(previous["settings"]["conf"])
    old, new = previous["settings"]["budget"], settings["budget"]
    if isinstance(old, int) != isinstance(new, int):  # another protocol, not just another setting
        made = f"a fixed budget of {old} steps a scene" if isinstance(old, int) else "scene-sized budgets"
        give = f"--max-steps {old} resumes it" if isinstance(old, int) else "leave out --max-steps to resume it"
        raise InputError(f"{out} holds a benchmark made under another protocol ({made}); {give}, or use another "
                         "--out: its runs are not mixed with this protocol's")
    if previous["settings"] != settings:
        difference = blocking_difference(previous["settings"], settings)
        redo = runs_changed(previous, settings, FinishedRuns(out))
        if redo is None:
            raise InputError(f"{out} holds a benchmark with other settings ({difference}); use another --out or "
                             "remove it")
        if redo[0] and not redo_changed:
            raise InputError(f"{out} holds a benchmark with other settings ({difference}), which only its "
                             f"{', '.join(map(str, redo[1]))} read: --redo-changed runs those again (their finished "
                             "runs are discarded) and keeps the others; or use another --out")
        previous["redo_runs"] = redo
    return previous


def report(out: str | Path) -> dict:
    """Rebuild the report of benchmark folder `out` from the runs finished so far (per run or
    packed: :mod:`.store`); runs nothing, so it is safe while the benchmark runs
    (``frontiernet bench --report --out DIR``).

    Returns:
        as :func:`main`, plus ``pending`` (planned runs not finished yet) and no ``wall_s``.
    Raises:
        InputError: `out` holds no benchmark (no ``plan.json``), or a run's record is corrupt, or no
            run is finished while a report is there (an empty one would replace it).
    """
    out = Path(out)
    plan = read_plan(out)
    check_output_files(out, report_files(list(plan["start_poses"])))  # before any is written over
    runs, finished = plan["runs"], FinishedRuns(out)
    own = (finished_row(run, finished) for run in runs if not run.get("copy_of"))
    rows = with_copies(runs, {row["key"]: row for row in own if row is not None})
    reported = [row for row in rows if row is not None]
    pending = len(rows) - len(reported)
    kept = [name for name in ("table.md", "results.csv") if (out / name).is_file()]
    if not reported and kept:  # a folder whose runs left the tree (its sessions.md says where they are)
        raise InputError(f"{out}: none of its {pending} planned runs is finished here (no records under runs/), so "
                         f"its report ({', '.join(kept)}) is left as it is; bring its runs back first to rebuild it")
    scenes, methods = list(plan["start_poses"]), list(dict.fromkeys(run["method"] for run in runs))
    depths = list(dict.fromkeys(run["depth"] for run in runs if run.get("depth"))) or None
    written = write_report(out, reported, scenes, methods, pending, finished, depths,
                           interval=load_config("bench").report.interval,
                           vox_steps=plan["settings"].get("vox_steps", "budget"), starts=common_starts(runs),
                           defining=finished_methods(runs, reported))
    return {"rows": reported, **written, "pending": pending}


__all__ = ["grown_plan", "main", "report", "resumable_plan"]
