"""The map predictor a ``seer`` or ``mapex`` run uses (docs/mapprediction.md, "Exploring with the
predictors"): which file, loaded and checked before any scene work.

The file is ``--model FILE`` when given, else the config key ``seer.predictor`` / ``mapex.predictor``
of ``configs/explore.yaml`` (null: the shipped ``frontiernet/weights/mappredictor_<kind>.safetensors``,
:data:`~frontiernet.mapprediction.predictor.SHIPPED`). A missing file, a file of another kind or
architecture, or a predictor trained on another voxel size than the run's map (``map.voxel_size``) is
an :class:`~frontiernet.errors.InputError` naming the file: one line and exit 2 from the command line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..mapprediction import MapPredictor, load_predictor


def predictor_file(conf, kind: str, model=None) -> Path | None:
    """The predictor file of a `kind` run: `model` (``--model``), else ``<kind>.predictor`` of the run
    config `conf`; None: the shipped one."""
    if model is not None:
        return Path(model)
    section = conf.get(kind) if hasattr(conf, "get") else None
    if section is None or "predictor" not in section:
        raise InputError(f"{kind}.predictor is missing from the explore config")
    value = section.get("predictor")
    return None if value in (None, "") else Path(str(value))


def open_predictor(conf, kind: str, model=None) -> MapPredictor:
    """The loaded predictor of a `kind` run (:func:`predictor_file`), checked against the run's map.

    Raises:
        InputError naming the file: missing, not a predictor, of another kind or architecture
            (:func:`~frontiernet.mapprediction.load_predictor`), or trained on other voxels than
            ``map.voxel_size``.
    """
    predictor = load_predictor(predictor_file(conf, kind, model), kind)
    voxel = float(conf.map.voxel_size)
    if not np.isclose(predictor.spec.voxel_size, voxel, rtol=1e-6, atol=0.0):
        raise InputError(f"{predictor.path}: a predictor of {predictor.spec.voxel_size} m voxels, but the run's map "
                         f"has {voxel} m (map.voxel_size)")
    return predictor


def check_predictor(kind: str):
    """``check(conf, model)``: what :func:`~frontiernet.exploration.methods.check_method` runs before a
    `kind` run's setup (loads the predictor once and drops it; a few milliseconds)."""
    def check(conf, model=None) -> None:
        open_predictor(conf, kind, model)
    return check


__all__ = ["check_predictor", "open_predictor", "predictor_file"]
