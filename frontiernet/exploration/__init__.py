"""Closed-loop exploration in the simulator (paper III-E, III-F; docs/design.md items 4 to 7).

:func:`~frontiernet.exploration.run.main` runs one exploration from a config;
:class:`~frontiernet.exploration.explorer.Explorer` is the loop; perceptions
(:mod:`.perception`) turn frames into frontier pixels; methods (:mod:`.methods`) choose where
goal candidates come from and how the goal is picked; :mod:`.outputs` writes the metrics.
"""

from .explorer import ExplorationResult, Explorer, StepRecord
from .methods import FrontierSource, ImageSource, MapSource, Method, make_method, method_names
from .perception import ModelPerception, Perception, PerceptionResult, make_perception

__all__ = ["ExplorationResult", "Explorer", "FrontierSource", "ImageSource", "MapSource", "Method",
           "ModelPerception", "Perception", "PerceptionResult", "StepRecord", "make_method", "make_perception",
           "method_names"]
