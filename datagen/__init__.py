"""datagen: ground truth for FrontierNet from any scene (DESIGN.md section 3, paper III-D).

- :class:`~datagen.ground_truth.GroundTruthGenerator`: per-view labels (F_p, F_d, F,
  the distance field, gain and gain classes) for a voxelised scene and a camera pose.
- :func:`~datagen.generate.generate`: a sharded dataset from many scenes
  (``frontiernet datagen``), on processes or Ray, resumable and deterministic.
- :func:`open_dataset`: read a dataset (``open_dataset(path)[i]`` is a dict of arrays).
"""

from .dataset import FrontierDataset, open_dataset
from .shards import DatasetError

__all__ = ["open_dataset", "FrontierDataset", "DatasetError"]
