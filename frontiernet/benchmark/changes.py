"""What a change of settings does to a stored benchmark (``frontiernet bench --out`` of a folder that
holds one): the keys added to the configs after it was planned, read as the code ran before them
(:data:`KEYS_ADDED_AFTER_PLANS`) or as this run's config has them where they change none of its runs
(:data:`KEYS_IDLE_WHEN`); the settings in which the two differ (:func:`differences`); and which of its
runs a difference reaches (:func:`runs_changed`: those of some depth sources, of some methods, or
those that collided or stopped with no frontier left), so that ``--redo-changed`` runs those again and keeps the rest.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..config import differences as config_differences, dotted_parent
from .plan import depth_sources

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
    "map_frontiers.min_cells_before_stop": None,  # issue 54: a run with no frontier left stops, as before
    "tracking.bury_visited": False,  # issue 54: a visited frontier is dropped, its next proposal kept, as before
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
             "max_predictions_per_step": 2, "reuse_distance_m": 1.0, "max_scored_clusters_per_step": None},
    "seer.max_scored_clusters_per_step": None,  # issue 55: every cluster scored every step, as before the key
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


def differences(old, new):
    """Every dotted key whose value differs between a stored plan's settings `old` and this run's `new`,
    as ``(key, "key: OLD in the plan, NEW now")`` (:func:`frontiernet.config.differences`)."""
    return config_differences(old, new, before="the plan")


METHOD_SECTIONS = {
    "nbvp": ("nbvp",),
    "omniscient": ("omniscient",),
    "seer": ("seer",),
    "mapex": ("mapex", "frontiernet-mapex"),  # frontiernet-mapex reads mapex's predictor settings
    "frontiernet_mapex": ("frontiernet-mapex",),
}
"""The sections of ``configs/explore.yaml`` that only some methods' runs read, with those methods
(the factories of :mod:`frontiernet.exploration.methods` that parse them)."""


WIDENING_METHODS = frozenset({"mapex", "seer"})
REGION_METHODS = frozenset({"mapex"})
"""The methods besides the map methods whose frontiers are regions of the map's frontier cells (their
:class:`~frontiernet.exploration.methods.Method`'s ``map_regions``), whose runs alone read
``tracking.bury_visited``."""
"""The methods besides the map methods whose frontier regions widen before a stop
(``map_frontiers.min_cells_before_stop``: :func:`~frontiernet.exploration.sources.widened_min_cells`)."""
FINISHED_WHEN = {"collided": lambda metrics: bool(metrics.get("collisions")),
                 "stopped": lambda metrics: metrics.get("stop_reason") == "no frontiers left"}
"""Conditions on a finished run's metrics under which a setting reaches it (:class:`Readers`' `when`): one
that acts only on a collision, or only where a run would stop with no frontier left."""
_RUNS_WHEN = {None: "runs", "collided": "collided runs", "stopped": "runs that stopped with no frontier left"}


@dataclass(frozen=True)
class Readers:
    """The runs of a benchmark that read one setting: those of depth sources `sources` and methods
    `methods` (None: every source, every method); with `when` (a key of :data:`FINISHED_WHEN`), only
    finished ones that meet it (those that collided, or that stopped with no frontier left)."""

    sources: frozenset | None = None
    methods: frozenset | None = None
    when: str | None = None

    def reads(self, run: dict, single_source: str, metrics: dict | None = None) -> bool:
        """Whether the planned `run` (a plan's ``runs`` entry; `metrics`: its finished record, None when
        unknown) is one of them; `single_source`: the source of a plan whose runs carry none."""
        return ((self.sources is None or (run.get("depth") or single_source) in self.sources)
                and (self.methods is None or run["method"] in self.methods)
                and (self.when is None or metrics is None or FINISHED_WHEN[self.when](metrics)))

    def __str__(self) -> str:  # "emulated-depth runs", "nbvp runs", "collided runs", "classic runs that stopped ..."
        words = [] if self.sources is None else [" and ".join(sorted(self.sources)) + "-depth"]
        words += [] if self.methods is None else [" and ".join(sorted(self.methods))]
        return " ".join(words + [_RUNS_WHEN[self.when]])


def _runs_reading(dotted: str, stored: dict | None = None, settings: dict | None = None) -> Readers | None:
    """The benchmark runs that alone read the setting `dotted` (``conf.<section>.<key>...``): the map's
    monocular sensor model and its depth-edge filter apply only to sources with flying pixels
    (:meth:`~frontiernet.mapping.checks.MapSettings.ray_model`), as the planner's ``monocular_*`` keys
    (:class:`~frontiernet.exploration.explorer.Explorer`), and ``planner.traversed_is_free`` only to
    sources without them while ``planner.monocular_traversed_is_free`` holds in both the stored and
    this run's `settings` (the others keep their traversed cells either way); a source's own ``depth``
    section only to it, a method's own section (:data:`METHOD_SECTIONS`) only to that method's runs;
    ``tracking.bury_visited`` only to the runs of methods whose frontiers are map frontier regions (the map
    methods and :data:`REGION_METHODS`), ``planner.bumps_are_obstacles`` only to runs that collided (a run without a collision is the same to
    the step either way), ``map_frontiers.min_cells_before_stop`` only to the runs of the methods of map
    frontier regions (the map methods, mapex and seer) that stopped with no frontier left (the same to the
    step before); None for every other setting (read
    by every run)."""
    from ..depth import SOURCES
    from ..exploration.methods import MAP_METHODS

    parts = dotted.split(".")
    section, key = (parts[1], parts[2]) if len(parts) > 2 and parts[0] == "conf" else (None, "")
    flying = frozenset(name for name, source in SOURCES.items() if source.flying_pixels)
    if (section in ("map", "planner") and key.startswith("monocular_")) or (section, key) == ("map", "depth_edge_rtol"):
        return Readers(sources=flying)
    if (section, key) == ("planner", "traversed_is_free") and all(bool(((side or {}).get("conf") or {}).get(
            "planner", {}).get("monocular_traversed_is_free")) for side in (stored, settings)):
        return Readers(sources=frozenset(SOURCES) - flying)
    if (section, key) == ("planner", "bumps_are_obstacles"):
        return Readers(when="collided")
    if (section, key) == ("tracking", "bury_visited"):
        return Readers(methods=frozenset(MAP_METHODS) | REGION_METHODS)
    if (section, key) == ("map_frontiers", "min_cells_before_stop"):
        return Readers(methods=frozenset(MAP_METHODS) | WIDENING_METHODS, when="stopped")
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


def runs_changed(plan: dict, settings: dict, finished=None) -> tuple[list[str], list[Readers]] | None:
    """The planned runs of a stored `plan` (``settings`` as :func:`with_idle_keys` and
    :func:`with_keys_added_after` leave them, and ``runs``) that this run's `settings` change, when
    every setting in which the two differ is read by some runs alone (:func:`_runs_reading`): (their
    keys, in plan order; the readers of the changed settings). Empty keys: the change reaches none of
    its runs (a monocular key of a ground-truth plan, the section of a method it does not run). None
    when a setting that every run reads differs (another benchmark). `finished`: the folder's finished runs
    (:class:`~frontiernet.benchmark.store.FinishedRuns`) for a setting read only by runs that collided or
    stopped (None: all read it)."""
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
                         None if reader.methods is None else reader.methods & frozenset(methods), reader.when)
        if reader.sources != frozenset() and reader.methods != frozenset() and reader not in readers:
            readers.append(reader)  # (as described: the plan's own sources and methods among them)
    metrics = {run["key"]: finished.metrics(run["key"]) or {} for run in plan["runs"]} \
        if finished is not None and any(reader.when for reader in readers) else {}
    keys = [run["key"] for run in plan["runs"]
            if any(reader.reads(run, sources[0], metrics.get(run["key"])) for reader in readers)]
    return keys, readers


__all__ = ["KEYS_ADDED_AFTER_PLANS", "KEYS_IDLE_WHEN", "METHOD_SECTIONS", "FINISHED_WHEN", "Readers", "with_idle_keys",
           "with_keys_added_after", "differences", "blocking_difference", "runs_changed"]
