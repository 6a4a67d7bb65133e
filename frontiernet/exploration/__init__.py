"""Closed-loop exploration in the simulator (paper III-E, III-F; docs/design.md items 4 to 7).

:func:`~frontiernet.exploration.run.main` runs one exploration from a config;
:class:`~frontiernet.exploration.explorer.Explorer` is the loop; methods (:mod:`.methods`,
registered in :data:`~.methods.METHODS`) choose where goal candidates come from and how the goal
is picked, image methods through a perception (the interface: :mod:`.perception`) that turns frames
into frontier pixels; :mod:`.outputs` writes the metrics.
"""

from .explorer import ExplorationResult, Explorer, StepRecord
from .methods import (METHODS, FrontierSource, ImageSource, MapSource, Method, MethodContext, ModelPerception,
                      make_method, method_names)
from .perception import Perception, PerceptionResult

__all__ = ["ExplorationResult", "Explorer", "FrontierSource", "ImageSource", "MapSource", "METHODS", "Method",
           "MethodContext", "ModelPerception", "Perception", "PerceptionResult", "StepRecord", "make_method",
           "method_names"]
