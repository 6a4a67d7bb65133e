"""Exploration methods: where goal candidates come from and how the goal is chosen.

Every method runs inside the same :class:`~frontiernet.exploration.explorer.Explorer`: the
same simulator, occupancy map, frontier bookkeeping, path planner and motion. A method only
decides (1) its **frontier source**, the candidate goals proposed each frame, and (2) its
**goal rule**, how the planner ranks the reachable candidates. Differences between methods
in a benchmark therefore come from the goal choice alone.

=======================  ====================================  ======================  ====================
method                   frontiers                             gain                    goal rule
=======================  ====================================  ======================  ====================
frontiernet              the model on the image, anchored      predicted (class)       gain^e / dist. (Eq. 8)
oracle                   datagen's ground truth on the image   ground truth            gain^e / distance
df-uniform               the model's distance field            uniform                 gain^e / distance
discontinuity-gain       depth discontinuities F_d             the model's             gain^e / distance
discontinuity-uniform    depth discontinuities F_d             uniform                 gain^e / distance
oracle-uniform           datagen's ground truth on the image   uniform                 gain^e / distance
frontiernet-oracle-gain  the model on the image, anchored      ground truth            gain^e / distance
classic                  the map: free cells beside unknown    --                      nearest (Yamauchi 1997)
gain-distance            the map's frontiers                   visible unknown volume  gain^e / dist. (NBVP, SEER, MapEx)
random-frontier          the map's frontiers                   --                      random, fixed per frontier
vacuum                   none                                  --                      straight on until blocked, then a
                                                                                       random turn (GLEAM's "vacuum")
omniscient               reachable views of the robot's map    true unseen volume      gain / distance: the bound
                                                                                       (:mod:`.omniscient`)
nbvp                     an RRT of views in the robot's map    visible unknown volume  the best branch's first node, then
                                                                                       plan again (Bircher 2016, :mod:`.nbvp`)
=======================  ====================================  ======================  ====================

The first five are the paper's system and its Fig. 9 ablations, the next two the oracle's
"where" / "how much" hybrids of issue 27 (``datagen`` registers them, as it does ``oracle``);
the rest are the baselines of issue 6.

**Adding a method** (docs/exploration.md): write a factory ``make(context) -> Method`` that
builds a :class:`Method` from a :class:`FrontierSource` (an :class:`ImageSource` around your own
:class:`~frontiernet.exploration.perception.Perception`, see :func:`image_method`; the
:class:`MapSource`; or a subclass with your own ``__call__``) and a goal rule (or, without
frontiers, its own moves: :attr:`Method.moves`, as ``vacuum``'s :mod:`.vacuum`), and register it
under the entry point group ``frontiernet.methods`` (:data:`METHODS`). The
:class:`MethodContext` gives it the run's config, random generator and map (and the model file,
scene and voxels); the built-in methods are built the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..registry import Registry
from .ablations import discontinuity_frontiers, uniform_gain
from .perception import Perception, PerceptionResult, plain_view
from .vacuum import VacuumMoves

GOAL_RULES = ("utility", "nearest", "random", "rate", "vacuum")


@dataclass
class MethodContext:
    """What a method is built with: one per run, shared with the explorer that runs it.

    Attributes:
        conf: the run config (:func:`~frontiernet.exploration.run.load_run_config`:
            ``configs/explore.yaml`` with sections ``sim``, ``depth``, ``ground_truth``).
        sim_conf: the sim config the run uses (camera, agent: ``conf``'s ``sim`` section).
        model: the model file of the learned methods (None: the shipped model).
        scene, voxels: the scene and its :class:`~frontiernet.simulator.voxels.VoxelGrid` (the
            oracle's ground truth; the map's extent). None: a method that needs them cannot be built.
        rng: the run's draws (anchoring's pixel subset, vacuum's turns); None:
            ``default_rng(conf.run.seed)``.
        map: the robot's :class:`~frontiernet.mapping.OccupancyMap`, which the explorer fills
            each frame and map methods read; None: an empty map over `voxels` (``conf.map``).
    """

    conf: Any
    sim_conf: Any
    model: str | Path | None = None
    scene: Any = None
    voxels: Any = None
    rng: np.random.Generator | None = None
    map: Any = None

    def __post_init__(self) -> None:
        if self.rng is None:
            self.rng = np.random.default_rng(int(self.conf.run.seed))
        if self.map is None and self.voxels is not None:
            from ..mapping import OccupancyMap

            self.map = OccupancyMap.like(self.voxels, self.conf.map)


class FrontierSource:
    """Proposes one frame's frontier observations.

    ``source(frame, depth, stopwatch) -> (observations, view)``: `observations` are
    :class:`~frontiernet.frontiers.anchoring.FrontierObservation`-like records in the world
    frame; `view` a :class:`~frontiernet.exploration.perception.PerceptionResult` for the
    video (frontier pixels, or none). `frame` is the rendered
    :class:`~frontiernet.simulator.camera.Frame` (its pose ``T_world_cam``), `depth` (H, W)
    float32 metres, NaN invalid, the robot's depth. `stopwatch` is the explorer's
    :class:`~frontiernet.timing.Stopwatch`: ``with stopwatch("perception"): ...`` times a stage of
    the step (``perception``, ``anchoring``). The run's map already holds this frame.
    """

    def __call__(self, frame, depth: np.ndarray, stopwatch) -> tuple[list, PerceptionResult]:
        raise NotImplementedError


class ImageSource(FrontierSource):
    """Frontier pixels from a perception, lifted to 3D by anchoring (paper III-E).

    Args:
        perception: frame, depth -> :class:`~frontiernet.exploration.perception.PerceptionResult`.
        anchoring: the ``anchoring`` section of the run config.
        rng: the generator of anchoring's pixel subset (the run's).
    """

    def __init__(self, perception: Perception, anchoring, rng: np.random.Generator) -> None:
        self.perception, self.anchoring, self.rng = perception, anchoring, rng

    def __call__(self, frame, depth, stopwatch):
        from ..frontiers import anchor_prediction

        with stopwatch("perception"):
            seen = self.perception(frame, depth)
        with stopwatch("anchoring"):
            observations = anchor_prediction(seen.distance_field, seen.gain_class, seen.depth, seen.K,
                                             frame.T_world_cam, self.anchoring, seen.labels, self.rng, seen.gain_logits)
        return observations, seen


class MapSource(FrontierSource):
    """Frontiers of the occupancy map at the camera's height (Yamauchi 1997): free cells next
    to unknown ones, clustered; gain ``uniform`` or ``unknown_volume`` (the unknown volume a
    camera at the frontier would see). Timed as ``anchoring`` (frontier extraction).

    Args:
        gain: ``uniform`` or ``unknown_volume``.
        occupancy: the run's map (:attr:`MethodContext.map`).
        conf: the run config (``map_frontiers``, ``planner.height_band_m``, ``tracking.gain_view``).
    """

    def __init__(self, gain: str, occupancy, conf) -> None:
        if occupancy is None:
            raise ValueError("map frontiers need the run's map (a MethodContext with voxels)")
        self.gain, self.map, self.conf = gain, occupancy, conf

    def __call__(self, frame, depth, stopwatch):
        from ..frontiers.map_frontiers import map_frontiers

        z = float(frame.T_world_cam[2, 3])  # the camera height the robot keeps
        with stopwatch("anchoring"):
            observations = map_frontiers(self.map, z, self.conf, frame.T_world_cam, self.gain)
        return observations, plain_view(frame, depth)


@dataclass
class Method:
    """An exploration method (see the module docstring).

    Attributes:
        name: as on the command line.
        source: its frontier source (None: no frontiers, e.g. ``vacuum``).
        goal: ``utility`` (gain^e / distance, paper Eq. 8), ``nearest`` (1 / distance),
            ``random`` (a random score drawn once per frontier), ``rate`` (gain / distance: volume
            per metre, whatever ``planner.gain_exponent``) or ``vacuum`` (no planner: the
            method's own `moves`).
        fresh_frontiers: the frontier set is this frame's proposals only (map frontiers are
            recomputed from the whole map every frame); otherwise observations are merged
            into the tracked frontiers across frames (image frontiers).
        uses_model: it runs the FrontierNet model file (a run records which file).
        moves: the method's own moves, which the explorer follows instead of planned routes
            (goal rule ``vacuum``): ``next_pose(T_world_cam, motion, check_move) -> (4, 4) pose``
            for each increment (`check_move` the explorer's move check) and ``bumped(T_world_cam)``
            after a collision, e.g. :class:`~frontiernet.exploration.vacuum.VacuumMoves`. None:
            the planner's route to the chosen frontier.
    """

    name: str
    source: FrontierSource | None
    goal: str = "utility"
    fresh_frontiers: bool = False
    uses_model: bool = False
    moves: Any = None

    def __post_init__(self) -> None:
        if self.goal not in GOAL_RULES:
            raise InputError(f"method {self.name!r}: goal rule must be one of {', '.join(GOAL_RULES)}, got {self.goal!r}")
        if self.source is None and self.goal != "vacuum":
            raise InputError(f"method {self.name!r} has no frontier source: only the vacuum goal rule works without one")
        if (self.goal == "vacuum") != (self.moves is not None):
            raise InputError(f"method {self.name!r}: the vacuum goal rule and a method's own moves go together")

    def propose(self, frame, depth: np.ndarray, stopwatch) -> tuple[list, PerceptionResult]:
        """This frame's frontier observations and the view for the video (see :class:`FrontierSource`;
        none and the plain camera view without a source)."""
        if self.source is None:
            return [], plain_view(frame, depth)
        return self.source(frame, depth, stopwatch)


def image_method(name: str, perception: Perception, context: MethodContext, uses_model: bool = False) -> Method:
    """The method `name` of `perception`'s frontier pixels, anchored to 3D and merged across
    frames, goals by gain / distance (paper Eq. 8). `uses_model`: the perception runs the model."""
    perception.name = name
    return Method(name, ImageSource(perception, context.conf.anchoring, context.rng), uses_model=uses_model)


class ModelPerception(Perception):
    """FrontierNet on each frame through a runtime (:class:`~frontiernet.model.Runtime`).

    Args:
        runtime: anything with ``conf``, ``labels`` and ``predict_frame`` (torch Predictor, ONNX,
            TorchScript).
        size: working size (None: the model's ``inference.size``).
    """

    name = "frontiernet"

    def __init__(self, runtime, size: int | None = None) -> None:
        self.runtime = runtime
        self.size = int(size or runtime.conf["inference"]["size"])

    def __call__(self, frame, depth: np.ndarray) -> PerceptionResult:
        result, K = self.runtime.predict_frame(frame.rgb, depth, frame.K, size=self.size)
        return PerceptionResult(result["rgb"], result["depth"], K, result["distance_field"], result["gain_class"],
                                dict(self.runtime.labels), result["gain_logits"])


def model_perception(context: MethodContext) -> ModelPerception:
    """FrontierNet on each frame, from the context's model file (None: the shipped model)."""
    from ..model import open_runtime

    return ModelPerception(open_runtime(context.model))


MAP_METHODS = {"classic": ("uniform", "nearest"), "gain-distance": ("unknown_volume", "utility"),
               "random-frontier": ("uniform", "random")}
"""The map methods: name -> (map frontiers' gain, goal rule)."""


def _frontiernet(context: MethodContext) -> Method:
    return image_method("frontiernet", model_perception(context), context, uses_model=True)


def _df_uniform(context: MethodContext) -> Method:
    return image_method("df-uniform", uniform_gain(model_perception(context), context.conf), context, uses_model=True)


def _discontinuity_gain(context: MethodContext) -> Method:
    perception = discontinuity_frontiers(model_perception(context), context.conf)
    return image_method("discontinuity-gain", perception, context, uses_model=True)


def _discontinuity_uniform(context: MethodContext) -> Method:
    perception = uniform_gain(discontinuity_frontiers(None, context.conf), context.conf)
    return image_method("discontinuity-uniform", perception, context)


def _map_method(name: str):
    """The factory of map method `name` (:data:`MAP_METHODS`)."""
    gain, goal = MAP_METHODS[name]
    return lambda context: Method(name, MapSource(gain, context.map, context.conf), goal, fresh_frontiers=True)


def _vacuum(context: MethodContext) -> Method:
    return Method("vacuum", None, "vacuum", moves=VacuumMoves(context.rng))


def _omniscient(context: MethodContext) -> Method:
    from .omniscient import make_omniscient  # it builds on this module's FrontierSource

    return make_omniscient(context)


def _nbvp(context: MethodContext) -> Method:
    from .nbvp import make_nbvp  # it builds on this module's FrontierSource

    return make_nbvp(context)


METHODS = Registry("exploration method", "frontiernet.methods", {
    "frontiernet": _frontiernet, "df-uniform": _df_uniform, "discontinuity-gain": _discontinuity_gain,
    "discontinuity-uniform": _discontinuity_uniform, **{name: _map_method(name) for name in MAP_METHODS},
    "vacuum": _vacuum, "omniscient": _omniscient, "nbvp": _nbvp})
"""Every exploration method: name -> factory ``make(context: MethodContext) -> Method``. Built in:
the paper's system and its Fig. 9 ablations (:mod:`.ablations`; only ``discontinuity-uniform``
loads no model), the map methods, ``vacuum``; other packages register under the entry point
group ``frontiernet.methods`` (``datagen``: ``oracle`` and its hybrids)."""


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
    """Every method name, sorted: built in and registered (e.g. datagen's ``oracle``)."""
    return sorted(METHODS.names())


def make_method(name: str, context: MethodContext) -> Method:
    """Build the method `name` of :data:`METHODS` for a run (`context`).

    Raises:
        InputError: an unknown name (the valid ones are listed) or a model that does not load.
    """
    return METHODS.get(name)(context)


__all__ = ["FrontierSource", "ImageSource", "MapSource", "Method", "MethodContext", "METHODS", "make_method",
           "method_names", "image_method", "ModelPerception", "model_perception", "GOAL_RULES", "DRAW_FREE_METHODS",
           "repeats_identically"]
