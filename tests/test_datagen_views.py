"""datagen.views (trajectory view sampling) and datagen.preview (sample contact sheets)."""

from __future__ import annotations

import numpy as np
import pytest
from omegaconf import OmegaConf

from conftest import scenes_config
from datagen.preview import (
    FRONTIER_COLOUR,
    GAIN_PALETTE,
    preview_indices,
    sample_contact_sheet,
    write_previews,
)
from datagen.config import load_datagen_config
from datagen.views import sample_trajectory_poses
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.simulator.raycast import distance_to_surface


@pytest.fixture(scope="module")
def confs():
    return load_config("datagen").sampling.trajectory, load_config("sim").poses


def _with(conf, **values):
    out = OmegaConf.create(OmegaConf.to_container(conf))
    for key, value in values.items():
        out[key] = value
    return out


def _steps(T: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)


# ----------------------------------------------------------------------------- trajectories


def test_trajectory_poses_valid(two_room_scene, two_room_voxels, confs):
    conf, poses_conf = confs
    T = sample_trajectory_poses(two_room_scene, two_room_voxels, 32, np.random.default_rng(0), conf, poses_conf)
    assert T.shape == (32, 4, 4) and T.dtype == np.float64
    R, p = T[:, :3, :3], T[:, :3, 3]
    assert np.allclose(np.einsum("nji,njk->nik", R, R), np.eye(3), atol=1e-9)
    assert np.allclose(T[:, 3], [0, 0, 0, 1])
    assert two_room_voxels.is_explorable(p).all()
    assert (distance_to_surface(two_room_scene, p) >= poses_conf.min_clearance_m).all()
    assert np.allclose(R[:, 2, 0], 0.0, atol=1e-9)  # camera x (right) horizontal: no roll
    pitch = np.degrees(np.arcsin(R[:, 2, 2]))  # optical axis elevation
    lo, hi = poses_conf.pitch_range_deg
    assert ((pitch >= lo - 1e-6) & (pitch <= hi + 1e-6)).all()
    heights = p[:, 2]  # floor at z = 0
    assert ((heights >= conf.camera_height_m[0] - 1e-6) & (heights <= conf.camera_height_m[1] + 1e-6)).all()


def test_trajectory_poses_deterministic(two_room_scene, two_room_voxels, confs):
    a = sample_trajectory_poses(two_room_scene, two_room_voxels, 20, np.random.default_rng(5), *confs)
    b = sample_trajectory_poses(two_room_scene, two_room_voxels, 20, np.random.default_rng(5), *confs)
    c = sample_trajectory_poses(two_room_scene, two_room_voxels, 20, np.random.default_rng(6), *confs)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    assert sample_trajectory_poses(two_room_scene, two_room_voxels, 0, 0, *confs).shape == (0, 4, 4)


def test_trajectory_spacing_and_headings(two_room_scene, two_room_voxels, confs):
    conf, poses_conf = confs
    T = sample_trajectory_poses(two_room_scene, two_room_voxels, 96, np.random.default_rng(1), conf, poses_conf)
    steps = _steps(T)
    along = np.abs(steps - conf.spacing_m) < 0.02
    assert along.mean() > 0.7  # the rest: path changes and dropped poses
    # the camera looks where the path goes, within the yaw jitter (plus slack for bends)
    move = np.diff(T[:, :2, 3], axis=0)[along]
    path_yaw = np.arctan2(move[:, 1], move[:, 0])
    forward = T[:-1, :3, 2][along]
    cam_yaw = np.arctan2(forward[:, 1], forward[:, 0])
    diff = np.degrees(np.abs((cam_yaw - path_yaw + np.pi) % (2 * np.pi) - np.pi))
    assert (diff <= conf.yaw_jitter_deg + 30.0).mean() > 0.85
    # without jitter the headings follow the path closely
    still = _with(conf, yaw_jitter_deg=0.0)
    T = sample_trajectory_poses(two_room_scene, two_room_voxels, 64, np.random.default_rng(2), still, poses_conf)
    along = np.abs(_steps(T) - conf.spacing_m) < 0.02
    move = np.diff(T[:, :2, 3], axis=0)[along]
    forward = T[:-1, :3, 2][along]
    diff = np.abs(np.arctan2(forward[:, 1], forward[:, 0]) - np.arctan2(move[:, 1], move[:, 0]))
    diff = np.degrees(np.abs((diff + np.pi) % (2 * np.pi) - np.pi))
    assert np.median(diff) < 10.0 and (diff < 30.0).mean() > 0.85


def test_trajectory_paths_long_enough(two_room_scene, two_room_voxels, confs):
    conf, poses_conf = confs
    T = sample_trajectory_poses(two_room_scene, two_room_voxels, 64, np.random.default_rng(3), conf, poses_conf)
    breaks = np.flatnonzero(_steps(T) > conf.spacing_m + 0.3)
    first_path = T[: breaks[0] + 1] if len(breaks) else T
    assert _steps(first_path).sum() >= conf.min_path_m - 2 * conf.spacing_m


@pytest.mark.parametrize("key, value", [("spacing_m", -0.3), ("spacing_m", 0.0), ("yaw_jitter_deg", "a"),
                                        ("camera_height_m", [1.8, 0.5]), ("lookahead_m", float("nan"))])
def test_trajectory_bad_config(two_room_scene, two_room_voxels, confs, key, value):
    conf, poses_conf = confs
    with pytest.raises(InputError, match=key):
        sample_trajectory_poses(two_room_scene, two_room_voxels, 4, np.random.default_rng(0),
                                _with(conf, **{key: value}), poses_conf)


def test_trajectory_bad_n_and_impossible(two_room_scene, two_room_voxels, confs):
    conf, poses_conf = confs
    with pytest.raises(InputError, match="number of poses"):
        sample_trajectory_poses(two_room_scene, two_room_voxels, -1, 0, conf, poses_conf)
    with pytest.raises(InputError, match="test:two-room"):  # no path this long fits the rooms
        sample_trajectory_poses(two_room_scene, two_room_voxels, 4, 0, _with(conf, min_path_m=50.0), poses_conf)


def test_trajectory_two_storeys(confs):
    from frontiernet.scenes import load_scene
    from frontiernet.simulator.voxels import voxelize_scene

    scene = load_scene("procedural:3?floors=2", scenes_config())
    voxels = voxelize_scene(scene, load_datagen_config().voxels)  # datagen's: every storey (configs/datagen.yaml)
    T = sample_trajectory_poses(scene, voxels, 200, np.random.default_rng(1), *confs)
    p = T[:, :3, 3]
    assert voxels.is_explorable(p).all()
    assert (distance_to_surface(scene, p) >= confs[1].min_clearance_m).all()
    storey = scene.metadata.extra["storey_height"]
    assert (p[:, 2] < storey).any() and (p[:, 2] > storey).any()  # paths on both floors


# ----------------------------------------------------------------------------- previews


def _sample(h: int = 40, w: int = 48, index: int = 0) -> dict:
    rng = np.random.default_rng(index)
    depth = rng.uniform(0.5, 4.0, (h, w)).astype(np.float32)
    depth[:5] = np.nan
    mask = np.zeros((h, w), bool)
    mask[10:20, 20:30] = True
    gain = np.where(mask, 3.0, 0.0).astype(np.float32)
    return {"rgb": rng.integers(0, 256, (h, w, 3), dtype=np.uint8), "depth": depth,
            "frontier_projected": mask.copy(), "discontinuity": np.roll(mask, 3, axis=1), "frontier_mask": mask,
            "distance_field": np.full((h, w), 10.0, np.float32), "gain": gain,
            "gain_class": np.where(mask, 5, 0).astype(np.int64), "scene": "test:synthetic", "index": index}


def _tile(sheet: np.ndarray, sample: dict, column: int) -> np.ndarray:
    """Tile `column` of the sheet's row (layout of frontiernet.simulator.preview.contact_sheet under a 26 px title)."""
    h, w = sample["rgb"].shape[:2]
    y0, x0 = 26 + 25, column * (w + 10) + 5
    return sheet[y0:y0 + h, x0:x0 + w]


def test_contact_sheet_shape_and_tiles():
    sample = _sample()
    sheet = sample_contact_sheet(sample)
    assert sheet.dtype == np.uint8 and sheet.ndim == 3 and sheet.shape[2] == 3
    assert sheet.shape[1] == 7 * (48 + 10) and sheet.shape[0] > 40
    assert np.array_equal(_tile(sheet, sample, 0), sample["rgb"])
    frontier = _tile(sheet, sample, 4)
    assert (frontier[sample["frontier_mask"]] == FRONTIER_COLOUR).all()
    assert not (frontier[~sample["frontier_mask"]] == FRONTIER_COLOUR).all(axis=-1).any()
    gain = _tile(sheet, sample, 6)
    assert (gain[sample["gain_class"] == 5] == GAIN_PALETTE[5]).all()
    assert (_tile(sheet, sample, 1)[:5] == 0).all()  # invalid depth black


def test_contact_sheet_rejects_bad_sample():
    sample = _sample()
    del sample["gain_class"]
    with pytest.raises(InputError, match="gain_class"):
        sample_contact_sheet(sample)
    sample = _sample()
    sample["distance_field"] = sample["distance_field"][:-1]
    with pytest.raises(InputError, match="distance_field"):
        sample_contact_sheet(sample)


def test_write_previews(tmp_path):
    dataset = [_sample(16, 20, i) for i in range(10)]
    paths = write_previews(dataset, tmp_path / "previews", n=4, seed=0)
    assert len(paths) == 4 and all(p.is_file() and p.suffix == ".png" for p in paths)
    assert len({p.name for p in paths}) == 4
    assert paths == write_previews(dataset, tmp_path / "previews", n=4, seed=0)
    assert len(write_previews(dataset[:3], tmp_path / "few", n=16)) == 3
    index = preview_indices(100, 16, seed=3)
    assert len(np.unique(index)) == 16 and index.min() >= 0 and index.max() < 100
    assert (np.diff(index) >= 6).all()  # spread out, one per stretch of ~6
