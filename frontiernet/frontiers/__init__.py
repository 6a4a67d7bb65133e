"""Frontiers: from per-pixel network outputs to 3D frontiers, and their bookkeeping.

docs/design.md items 4 and 5, paper III-E and III-F. :func:`anchor_prediction` takes a distance
field and gain classes (from the network or the ground truth) and returns
:class:`FrontierObservation` s; :mod:`.gain` holds the gain-class encoding shared with the
data generation; :class:`FrontierTracker` (:mod:`.tracking`) folds observations over frames.
"""

from .anchoring import FrontierObservation, anchor_frontiers, anchor_prediction
from .gain import class_lower_bounds, class_midpoints, class_values, decode_gain, gain_classes
from .settings import AnchoringSettings
from .tracking import Frontier, FrontierTracker

__all__ = [
    "AnchoringSettings", "Frontier", "FrontierObservation", "FrontierTracker", "anchor_frontiers",
    "anchor_prediction", "class_lower_bounds", "class_midpoints", "class_values", "decode_gain", "gain_classes",
]
