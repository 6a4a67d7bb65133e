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
seer                     views on circles around the map's     unknown volume seen     gain / (path time + heading cost)
                         frontier clusters                     through the predicted   (tyuezhan/SEER, :mod:`.seer`)
                                                               3D crop
mapex                    the map's frontiers                   ensemble variance of    variance / distance (castacks/MapEx
                                                               the predicted map in    visvarprob, :mod:`.mapex`)
                                                               sight, still unknown
frontiernet-mapex        the model on the image, anchored      predicted (class),      gain^e / distance
                                                               blended with the        (:mod:`.predicted_space`)
                                                               predicted unseen space
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

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..registry import Registry
from .ablations import discontinuity_frontiers, uniform_gain
from .mapex import make_mapex
from .nbvp import make_nbvp
from .omniscient import make_omniscient
from .perception import Perception, PerceptionResult
from .predicted import check_predictor
from .predicted_space import predicted_space_gain
from .seer import make_seer
from .sources import GOAL_RULES, FrontierSource, ImageSource, MapSource, Method
from .vacuum import VacuumMoves


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
        score: the run's :class:`~frontiernet.exploration.score.GroundTruthScore`, which the explorer
            keeps and only a reference that knows the truth reads (``omniscient``); None: built on
            first use (:meth:`ground_truth`).
        traversed: where the robot has been (:class:`~frontiernet.planning.traversed.TraversedCells`),
            open to the planner, the move check and the methods that plan their own free space
            (``nbvp``, ``omniscient``), which read it each time; set by the explorer
            (``planner.traversed_is_free``, or ``planner.monocular_traversed_is_free`` with a depth
            source with flying pixels; map mode only); None: off.
    """

    conf: Any
    sim_conf: Any
    model: str | Path | None = None
    scene: Any = None
    voxels: Any = None
    rng: np.random.Generator | None = None
    map: Any = None
    score: Any = None
    traversed: Any = None

    def __post_init__(self) -> None:
        if self.rng is None:
            self.rng = np.random.default_rng(int(self.conf.run.seed))
        if self.map is None and self.voxels is not None:
            from ..mapping import OccupancyMap

            self.map = OccupancyMap.like(self.voxels, self.conf.map)

    def ground_truth(self):
        """The run's :class:`~frontiernet.exploration.score.GroundTruthScore` over `scene` and
        `voxels` (built on first use: one per run, shared by the explorer and the methods)."""
        if self.score is None:
            from .score import GroundTruthScore

            self.score = GroundTruthScore(self.scene, self.voxels, self.conf)
        return self.score


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


# factories whose method runs the model file (--model), read by uses_model before a run's setup; a
# plugin factory marks itself the same way (an attribute, set where it is defined: datagen/oracle.py)
_frontiernet.uses_model = _df_uniform.uses_model = _discontinuity_gain.uses_model = True


def _frontiernet_mapex(context: MethodContext) -> Method:
    method = image_method("frontiernet-mapex", model_perception(context), context, uses_model=True)
    return replace(method, source=predicted_space_gain(method.source, context))


_frontiernet_mapex.uses_model = True  # --model names its FrontierNet model (the predictor: mapex.predictor)
_frontiernet_mapex.check = check_predictor("mapex", model_is_predictor=False)  # before the scene loads (check_method)
_frontiernet_mapex.topdown_prediction = True  # its source's `topdown`, which explore --show-prediction alone draws
_frontiernet_mapex.needs_map = "counts the predicted space behind a frontier from the robot's map"


def _discontinuity_uniform(context: MethodContext) -> Method:
    perception = uniform_gain(discontinuity_frontiers(None, context.conf), context.conf)
    return image_method("discontinuity-uniform", perception, context)


def _map_method(name: str):
    """The factory of map method `name` (:data:`MAP_METHODS`)."""
    gain, goal = MAP_METHODS[name]

    def make(context: MethodContext) -> Method:
        return Method(name, MapSource(gain, context.map, context.conf), goal, fresh_frontiers=True, map_regions=True)

    make.needs_map = "takes its frontiers from the robot's map"
    return make


def _vacuum(context: MethodContext) -> Method:
    return Method("vacuum", None, "vacuum", moves=VacuumMoves(context.rng))


_vacuum.needs_map = "plans no route (it drives until it bumps, then turns)"


METHODS = Registry("exploration method", "frontiernet.methods", {
    "frontiernet": _frontiernet, "df-uniform": _df_uniform, "discontinuity-gain": _discontinuity_gain,
    "discontinuity-uniform": _discontinuity_uniform, **{name: _map_method(name) for name in MAP_METHODS},
    "vacuum": _vacuum, "omniscient": make_omniscient, "nbvp": make_nbvp, "seer": make_seer, "mapex": make_mapex,
    "frontiernet-mapex": _frontiernet_mapex})
"""Every exploration method: name -> factory ``make(context: MethodContext) -> Method``. Built in:
the paper's system and its Fig. 9 ablations (:mod:`.ablations`; only ``discontinuity-uniform``
loads no model), the map methods, ``vacuum``, ``omniscient``, ``nbvp``, ``seer`` and ``mapex``
(the last two run a map predictor: ``--model`` names its file); other packages register under the
entry point group ``frontiernet.methods`` (``datagen``: ``oracle`` and its hybrids)."""


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


def uses_model(name: str) -> bool:
    """Whether method `name` runs the model file (its factory has ``uses_model = True``);
    InputError for an unknown name (the valid ones listed)."""
    return bool(getattr(METHODS.get(name), "uses_model", False))


def runs_frontiernet_model(name: str) -> bool:
    """Whether method `name` runs a FrontierNet model file (:func:`uses_model`, not a map predictor:
    ``seer`` and ``mapex`` mark theirs with ``model_kind``): the methods the benchmark's ``--model``
    goes to."""
    return uses_model(name) and getattr(METHODS.get(name), "model_kind", "frontiernet") == "frontiernet"


def owns_topdown_prediction(name: str) -> bool:
    """Whether method `name`'s source keeps a :class:`~.predicted.TopdownPrediction` as ``source.topdown``
    (its factory has ``topdown_prediction = True``: mapex, frontiernet-mapex), which ``explore
    --show-prediction`` alone draws instead of predicting again."""
    return bool(getattr(METHODS.get(name), "topdown_prediction", False))


def check_method(name: str, model=None, conf=None) -> None:
    """Before a run's setup: InputError for an unknown method `name` (the valid ones listed), or a
    `model` (``--model``) given to a method that runs none (:func:`uses_model`); with the run config
    `conf`, the factory's own ``check(conf, model)`` where it has one (``seer``, ``mapex``: their
    predictor file loads and fits the run's map), and map-free mode (``planner.mode: map_free``,
    ``--map-free``) for a method that plans in the robot's map (its factory's ``needs_map``: why)."""
    needs_map = getattr(METHODS.get(name), "needs_map", None)
    if conf is not None and needs_map and str(conf.planner.mode) == "map_free":
        free = [other for other in METHODS.names() if not getattr(METHODS.get(other), "needs_map", None)]
        raise InputError(f"--map-free (planner.mode=map_free): method {name} {needs_map}, so map-free mode does "
                         f"not apply to it; leave it out (the methods that run map-free: {', '.join(sorted(free))})")
    if not uses_model(name) and model is not None:
        users = [other for other in METHODS.names() if uses_model(other)]
        raise InputError(f"--model {model}: method {name} runs no model, so --model would be ignored; leave it "
                         f"out (the methods that run one: {', '.join(users)})")
    check = getattr(METHODS.get(name), "check", None)
    if conf is not None and check is not None:
        check(conf, model)


def make_method(name: str, context: MethodContext) -> Method:
    """Build the method `name` of :data:`METHODS` for a run (`context`).

    Raises:
        InputError: an unknown name (the valid ones are listed) or a model that does not load.
    """
    return METHODS.get(name)(context)


__all__ = ["FrontierSource", "ImageSource", "MapSource", "Method", "MethodContext", "METHODS", "check_method",
           "make_method", "uses_model", "runs_frontiernet_model",
           "method_names", "image_method", "ModelPerception", "model_perception", "GOAL_RULES", "DRAW_FREE_METHODS",
           "repeats_identically"]
