"""Real captured data: posed image sequences from disk (issue "Real captured data").

* :mod:`.frames`: the :class:`Sequence` type (frames with images, optional depth, intrinsics,
  ``T_world_cam``) every reader returns.
* :mod:`.images`: image and depth files, with the depth encodings of TUM, NYU, SUN, Redwood.
"""

from .frames import Camera, Sequence, SequenceFrame
from .images import DEPTH_ENCODINGS, read_depth, read_rgb

__all__ = ["Camera", "Sequence", "SequenceFrame", "DEPTH_ENCODINGS", "read_depth", "read_rgb"]
