"""Mapping: the 3D log-odds occupancy map and the voxel traversals it shares with the ground truth.

:class:`OccupancyMap` integrates depth frames (world frame Z-up, metres) and answers
state queries (:data:`UNKNOWN`, :data:`FREE`, :data:`OCCUPIED`), the known volume a
virtual camera sees and 2D planning slices. Its numbers come from the ``map`` section
of ``configs/explore.yaml`` (:class:`MapSettings`).
"""

from .checks import MapSettings, depth_edges
from .occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyMap
from .traversal import frustum_volume, mark_depth_rays, mark_traversed

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "MapSettings", "OccupancyMap", "depth_edges", "frustum_volume",
           "mark_depth_rays", "mark_traversed"]
