"""Image-space labels: depth discontinuities F_d, the distance field D and gain classes.

All four are defined in the library and re-exported here: F_d (:func:`discontinuity_mask`)
and D (:func:`distance_field`) in :mod:`frontiernet.frontiers.discontinuity`, the gain
classes (:func:`gain_classes`, :func:`class_lower_bounds`) in :mod:`frontiernet.frontiers.gain`.

docs/design.md section 3, paper section III-D. All images are (H, W) in pixel coordinates
(row v, column u); depth is metric z-depth in metres with NaN where invalid, as the
simulator renders it.
"""

from __future__ import annotations

# The label helpers live in the library (anchoring decodes what datagen encodes, the Fig. 9
# ablations take F_d and D of the robot's depth); re-exported.
from frontiernet.frontiers.discontinuity import discontinuity_mask, distance_field
from frontiernet.frontiers.gain import class_lower_bounds, gain_classes, gain_definition

__all__ = ["class_lower_bounds", "discontinuity_mask", "distance_field", "gain_classes", "gain_definition"]
