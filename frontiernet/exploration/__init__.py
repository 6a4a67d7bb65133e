"""Closed-loop exploration in the simulator (paper III-E, III-F; DESIGN.md items 4 to 7).

:func:`~frontiernet.exploration.run.main` runs one exploration from a config;
:class:`~frontiernet.exploration.explorer.Explorer` is the loop; perceptions
(:mod:`.perception`) turn frames into frontier pixels; :mod:`.outputs` writes the metrics.
"""

from .explorer import ExplorationResult, Explorer, StepRecord
from .perception import ModelPerception, Perception, PerceptionResult, make_perception

__all__ = ["ExplorationResult", "Explorer", "ModelPerception", "Perception", "PerceptionResult", "StepRecord",
           "make_perception"]
