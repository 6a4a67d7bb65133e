"""datagen: ground truth for FrontierNet from any scene (docs/design.md section 3, paper III-D).

- :class:`~datagen.ground_truth.GroundTruthGenerator`: per-view labels (F_p, F_d, F,
  the distance field, gain and gain classes) for a voxelised scene and a camera pose.
- :func:`~datagen.generate.generate`: a sharded dataset from many scenes
  (``frontiernet datagen``), on processes or Ray, resumable and deterministic.
- :func:`open_dataset`: read a dataset (``open_dataset(path)[i]`` is a dict of arrays).
"""

import importlib

_EXPORTS = {"open_dataset": ".dataset", "FrontierDataset": ".dataset", "DatasetError": ".shards"}


def __getattr__(name: str):
    """Import on first use (PEP 562): ``frontiernet``'s CLI loads ``datagen.cli`` for every
    command, and the dataset's torch and HDBSCAN imports took seconds of each start."""
    if name not in _EXPORTS:
        raise AttributeError(f"module 'datagen' has no attribute {name!r}")
    return getattr(importlib.import_module(_EXPORTS[name], __name__), name)


__all__ = ["open_dataset", "FrontierDataset", "DatasetError"]
