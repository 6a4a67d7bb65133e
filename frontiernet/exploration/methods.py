"""Exploration methods: where goal candidates come from and how the goal is chosen.

Every method runs inside the same :class:`~frontiernet.exploration.explorer.Explorer`: the
same simulator, occupancy map, frontier bookkeeping, path planner and motion. A method only
decides (1) its **frontier source**, the candidate goals proposed each frame, and (2) its
**goal rule**, how the planner ranks the reachable candidates. Differences between methods
in a benchmark therefore come from the goal choice alone.

=======================  ====================================  ======================  ====================
method                   frontiers                             gain                    goal rule
=======================  ====================================  ======================  ====================
frontiernet              the model on the image, anchored      predicted (class)       gain / distance (Eq. 8)
oracle                   datagen's ground truth on the image   ground truth            gain / distance
df-uniform               the model's distance field            uniform                 gain / distance
discontinuity-gain       depth discontinuities F_d             the model's             gain / distance
discontinuity-uniform    depth discontinuities F_d             uniform                 gain / distance
oracle-uniform           datagen's ground truth on the image   uniform                 gain / distance
frontiernet-oracle-gain  the model on the image, anchored      ground truth            gain / distance
classic                  the map: free cells beside unknown    --                      nearest (Yamauchi 1997)
gain-distance            the map's frontiers                   visible unknown volume  gain / distance (NBVP, SEER, MapEx)
random-frontier          the map's frontiers                   --                      random, fixed per frontier
vacuum                   none                                  --                      straight on until blocked, then a
                                                                                       random turn (GLEAM's "vacuum")
=======================  ====================================  ======================  ====================

The first five are the paper's system and its Fig. 9 ablations, the next two the oracle's
"where" / "how much" hybrids of issue 27 (``datagen`` registers them, as it does ``oracle``);
the rest are the baselines of issue 6. **Adding a method**: build a :class:`Method` from a :class:`FrontierSource` (an
:class:`ImageSource` around your own :class:`~frontiernet.exploration.perception.Perception`,
the :class:`MapSource`, or a subclass with your own ``__call__``) and a goal rule, and
register a factory ``make(model, scene, voxels, sim_conf, conf) -> Method`` under the entry
point group ``frontiernet.methods`` (docs/exploration.md has an example).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .perception import BUILTIN_PERCEPTIONS, PerceptionResult, make_perception, perception_plugins, plain_view

METHOD_GROUP = "frontiernet.methods"
GOAL_RULES = ("utility", "nearest", "random", "vacuum")


class FrontierSource:
    """Proposes one frame's frontier observations.

    ``source(explorer, frame, depth, timed) -> (observations, view)``: `observations` are
    :class:`~frontiernet.frontiers.anchoring.FrontierObservation`-like records in the world
    frame; `view` a :class:`~frontiernet.exploration.perception.PerceptionResult` for the
    video (frontier pixels, or none). `timed(stage, function, *args)` times a stage of the
    step (``perception``, ``anchoring``). The explorer's map already holds this frame.
    """

    def __call__(self, explorer, frame, depth: np.ndarray, timed) -> tuple[list, PerceptionResult]:
        raise NotImplementedError


class ImageSource(FrontierSource):
    """Frontier pixels from a perception, lifted to 3D by anchoring (paper III-E)."""

    def __init__(self, perception) -> None:
        self.perception = perception

    def __call__(self, explorer, frame, depth, timed):
        from ..frontiers import anchor_prediction

        seen = timed("perception", self.perception, frame, depth)
        observations = timed("anchoring", anchor_prediction, seen.distance_field, seen.gain_class, seen.depth, seen.K,
                             frame.T_world_cam, explorer.conf.anchoring, seen.labels, explorer.rng)
        return observations, seen


class MapSource(FrontierSource):
    """Frontiers of the occupancy map at the robot's height (Yamauchi 1997): free cells next
    to unknown ones, clustered; gain ``uniform`` or ``unknown_volume`` (the unknown volume a
    camera at the frontier would see). Timed as ``anchoring`` (frontier extraction)."""

    def __init__(self, gain: str) -> None:
        self.gain = gain

    def __call__(self, explorer, frame, depth, timed):
        from ..frontiers.map_frontiers import map_frontiers

        observations = timed("anchoring", map_frontiers, explorer.map, explorer.motion.z, explorer.conf,
                             frame.T_world_cam, self.gain)
        return observations, plain_view(frame, depth)


@dataclass
class Method:
    """An exploration method (see the module docstring).

    Attributes:
        name: as on the command line.
        source: its frontier source (None: no frontiers, e.g. ``vacuum``).
        goal: ``utility`` (gain^e / distance, paper Eq. 8), ``nearest`` (1 / distance),
            ``random`` (a random score drawn once per frontier) or ``vacuum`` (no planner).
        fresh_frontiers: the frontier set is this frame's proposals only (map frontiers are
            recomputed from the whole map every frame); otherwise observations are merged
            into the tracked frontiers across frames (image frontiers).
    """

    name: str
    source: FrontierSource | None
    goal: str = "utility"
    fresh_frontiers: bool = False

    def __post_init__(self) -> None:
        if self.goal not in GOAL_RULES:
            raise InputError(f"method {self.name!r}: goal rule must be one of {', '.join(GOAL_RULES)}, got {self.goal!r}")
        if self.source is None and self.goal != "vacuum":
            raise InputError(f"method {self.name!r} has no frontier source: only the vacuum goal rule works without one")


IMAGE_METHODS = tuple(BUILTIN_PERCEPTIONS)  # the paper's system and its Fig. 9 ablations
MAP_METHODS = {"classic": ("uniform", "nearest"), "gain-distance": ("unknown_volume", "utility"),
               "random-frontier": ("uniform", "random")}


#: Methods that draw no random numbers: with a depth source that is not seeded, a run depends on
#: its start alone (the benchmark runs them once per start; see :func:`repeats_identically`).
DRAW_FREE_METHODS = tuple(name for name, (_, goal) in MAP_METHODS.items() if goal != "random")


def repeats_identically(method: str, depth: str) -> bool:
    """True when runs of `method` with depth source `depth` (a name of
    :data:`frontiernet.depth.SOURCES`) that differ only in their seed are the same run: the method
    is in :data:`DRAW_FREE_METHODS` and the depth source is not seeded. The image methods draw
    (anchoring's pixel subset), as do ``random-frontier``, ``vacuum`` and, to be safe, plugins."""
    from ..depth import SOURCES

    return method in DRAW_FREE_METHODS and depth in SOURCES and not SOURCES[depth].seeded


def method_names() -> list[str]:
    """Every method name: built-in, perception plugins (e.g. datagen's ``oracle``), method plugins."""
    from importlib.metadata import entry_points

    plugins = [entry.name for entry in entry_points(group=METHOD_GROUP)]
    return sorted(set(IMAGE_METHODS) | set(perception_plugins()) | set(MAP_METHODS) | {"vacuum"} | set(plugins))


def make_method(name: str, model=None, scene=None, voxels=None, sim_conf=None, conf=None) -> Method:
    """Build the method `name` (`model`: the model file of the learned methods, None = shipped).

    Raises:
        InputError: an unknown name (the valid ones are listed) or a model that does not load.
    """
    from importlib.metadata import entry_points

    if name in MAP_METHODS:
        gain, goal = MAP_METHODS[name]
        return Method(name, MapSource(gain), goal, fresh_frontiers=True)
    if name == "vacuum":
        return Method(name, None, "vacuum")
    plugins = {entry.name: entry for entry in entry_points(group=METHOD_GROUP)}
    if name in plugins:
        return plugins[name].load()(model, scene, voxels, sim_conf, conf)
    if name in IMAGE_METHODS or name in perception_plugins():
        return Method(name, ImageSource(make_perception(name, model, scene, voxels, sim_conf, conf=conf)))
    raise InputError(f"unknown exploration method '{name}'; valid: {', '.join(method_names())}")


__all__ = ["FrontierSource", "ImageSource", "MapSource", "Method", "make_method", "method_names", "GOAL_RULES",
           "DRAW_FREE_METHODS", "repeats_identically"]
