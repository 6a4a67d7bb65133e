"""Bad input to the data commands (issue 55's third probe, second batch): mapgen's snapshot keys, mapeval's
options and dataset, datagen's actions, sequence's network size and TUM / Redwood folders, predict's depth
decoding. One line naming the file, key or value and what is wrong, exit code 2, nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from frontiernet.cli.main import main
from frontiernet.errors import InputError
from test_sequence_readers import write_depth, write_image, write_redwood, write_tum


# ----------------------------------------------------------------------------- mapgen, mapeval

def test_a_first_snapshot_at_or_past_the_step_budget_is_refused(tmp_path, one_line_error):
    # issue 55's third probe: max_steps=5 with first_snapshot_step=500 wrote a dataset of 0 snapshots
    for first in (500, 5):
        assert main(["mapgen", "--scenes", "procedural:3", "--out", str(tmp_path / "m"), "--no-progress", "--set",
                     "mapgen.max_steps=5", f"mapgen.first_snapshot_step={first}"]) == 2
        assert (f"mapgen.first_snapshot_step {first} must be below mapgen.max_steps 5 (each run's step budget): the "
                "runs would end before (or at) their first snapshot") in one_line_error()
        assert not (tmp_path / "m").exists()


def random_predictor(path: Path, kind: str) -> Path:
    """A tiny map predictor file of `kind` with random weights."""
    from frontiernet.mapprediction import save_predictor
    from frontiernet.mapprediction.networks import NetworkSettings, PredictorSpec

    spec = PredictorSpec(kind, NetworkSettings((4, 8), (1,), 3 if kind == "seer" else 2), crop_shape=(16, 16, 8))
    return save_predictor(path, spec, spec.build().state_dict())


def test_mapeval_refuses_crops_per_snapshot_for_a_mapex_predictor(tmp_path, one_line_error):
    # issue 55's third probe: --crops-per-snapshot (seer only) was ignored for a mapex predictor
    mapex = random_predictor(tmp_path / "mapex.safetensors", "mapex")
    report = tmp_path / "scores.json"
    assert main(["mapeval", str(mapex), "--data", str(tmp_path / "maps"), "--crops-per-snapshot", "3",
                 "--json", str(report)]) == 2
    assert (f"--crops-per-snapshot applies to seer predictors, and {mapex} is a mapex predictor (scored over the "
            "whole top-down map): leave it out") in one_line_error()
    assert not report.exists()


def test_a_file_given_as_a_map_dataset_says_it_is_a_file(tmp_path, one_line_error):
    # issue 55's third probe: "rgb.png/dataset.json: not found (not a map dataset folder ...)"
    from datagen.mapshards import read_map_dataset_info

    seer = random_predictor(tmp_path / "seer.safetensors", "seer")
    image = tmp_path / "rgb.png"
    write_image(image, 8, 8)
    assert main(["mapeval", str(seer), "--data", str(image)]) == 2
    assert f"{image}: is a file, expected a folder (map dataset)" in one_line_error()
    with pytest.raises(InputError, match="rgb.png: is a file, expected a folder"):
        read_map_dataset_info(image)


# ----------------------------------------------------------------------------- datagen's actions

@pytest.mark.parametrize("argv, message", [
    # issue 55's third probe: datagen's own options before an action were dropped without a word
    (["--scenes", "procedural:3", "--views-per-scene", "5", "preview", "{tmp}/ds", "--out", "{tmp}/pv"],
     "--scenes/--views-per-scene apply to `frontiernet datagen` itself, not to `datagen preview`"),
    (["--out", "{tmp}/pv", "preview", "{tmp}/ds"],
     "--out applies to `frontiernet datagen` itself, not to `datagen preview` (give --out after `preview`)"),
    (["--seed", "3", "consistency", "--scenes", "procedural:3", "--views-per-scene", "1"],
     "--seed applies to `frontiernet datagen` itself, not to `datagen consistency` (give --seed after"),
    (["--no-progress", "bench", "--scene", "procedural:3", "--views", "1"],
     "--no-progress applies to `frontiernet datagen` itself, not to `datagen bench`"),
    # ... and datagen bench timed an engine against itself
    (["bench", "--scene", "procedural:3", "--views", "1", "--raycast", "open3d", "open3d"],
     "--raycast names open3d twice: each engine is timed once"),
])
def test_datagen_actions_refuse_what_they_would_ignore(argv, message, tmp_path, one_line_error):
    assert main(["datagen", *(arg.format(tmp=tmp_path) for arg in argv)]) == 2
    assert message in one_line_error()
    assert not (tmp_path / "pv").exists()


def test_preview_of_a_dataset_whose_shards_are_gone_says_they_are_missing(tmp_path, one_line_error):
    # eighth probe (E28): "the dataset has no samples yet", of shards that were deleted, not yet to come
    out = tmp_path / "ds"
    assert main(["datagen", "--scenes", "procedural:3", "--views-per-scene", "1", "--out", str(out), "--no-progress",
                 "--set", "camera.width=32", "camera.height=32", "camera.focal_px=20"]) == 0
    for shard in (out / "shards").glob("*.zip"):
        shard.unlink()
    assert main(["datagen", "preview", str(out), "--n", "1", "--out", str(tmp_path / "pv")]) == 2
    assert one_line_error() == (f"frontiernet datagen: error: {out}: the dataset has no samples: the 1 shard(s) its "
                                f"dataset.json plans are not in {out / 'shards'} (deleted, or a run that has made none "
                                "yet)")
    assert not (tmp_path / "pv").exists()


@pytest.mark.parametrize("argv, message", [
    # eighth probe (E20): "argument ACTION: invalid choice: '1' (choose from ...)", --n's value named as the action
    (["datagen", "--scenes", "procedural:3", "preview", "ds1", "--n", "1", "--out", "pv7"],
     "frontiernet datagen: error: --scenes took 'preview' for one of its values, but 'preview' names the action: "
     "give it first, then its options (`frontiernet datagen preview ...`)"),
    (["bench", "--set", "run.seed=1", "render", "--repeats", "1"],
     "frontiernet bench: error: --set took 'render' for one of its values, but 'render' names the benchmark: give "
     "it first, then its options (`frontiernet bench render ...`)"),
])
def test_a_list_option_that_took_the_name_of_an_action_says_so(argv, message, one_line_error):
    with pytest.raises(SystemExit) as stop:  # (argparse's usage error)
        main(argv)
    assert stop.value.code == 2
    assert one_line_error() == message


# ----------------------------------------------------------------------------- sequence

def test_sequence_refuses_a_network_size_out_of_range(tmp_path, one_line_error):
    # issue 55's third probe: network.size=5 was accepted
    folder = write_redwood(tmp_path / "seq", count=2)
    (folder / "camera_intrinsic.json").write_text(json.dumps(
        {"width": 32, "height": 24, "intrinsic_matrix": [30, 0, 0, 0, 30, 0, 15.5, 11.5, 1]}))
    for size in (5, 0, 4096):
        assert main(["sequence", "--input", str(folder), "--out", str(tmp_path / "o"), "--no-video",
                     f"network.size={size}"]) == 2
        assert f"network.size must be an integer in [8, 2048] (or null), got {size}" in one_line_error()
        assert not (tmp_path / "o").exists()


def write_small_tum(root: Path, width: int, height: int) -> Path:
    """A TUM folder of two frames of `width` x `height` px (depth at 1 m, poses at the origin)."""
    for time in (1.0, 1.1):
        write_image(root / "rgb" / f"{time:.6f}.png", width, height)
        write_depth(root / "depth" / f"{time:.6f}.png", width, height, 5000)
    (root / "rgb.txt").write_text("".join(f"{t:.6f} rgb/{t:.6f}.png\n" for t in (1.0, 1.1)))
    (root / "depth.txt").write_text("".join(f"{t:.6f} depth/{t:.6f}.png\n" for t in (1.0, 1.1)))
    (root / "groundtruth.txt").write_text("".join(f"{t:.6f} 0 0 0 0 0 0 1\n" for t in (1.0, 1.1)))
    return root


def test_tum_default_intrinsics_need_640_by_480_frames(tmp_path, one_line_error):
    # issue 55's third probe: 64 x 48 frames took the 640 x 480 default K ("principal point outside ...")
    from frontiernet.sequences import Camera, read_tum

    small = write_small_tum(tmp_path / "small", 64, 48)
    assert main(["sequence", "--input", str(small), "--out", str(tmp_path / "o"), "--no-video"]) == 2
    assert (f"{small}: TUM's default intrinsics are for 640 x 480 frames, these are 64 x 48: give --intrinsics "
            "FX,FY,CX,CY") in one_line_error()
    assert not (tmp_path / "o").exists()
    given = read_tum(small, Camera.pinhole(52.5, 52.5, 31.5, 23.5, 64, 48))  # with intrinsics: read
    assert given.frames[0].camera.K[0, 0] == 52.5
    full = read_tum(write_small_tum(tmp_path / "full", 640, 480))  # the default's own size: read
    np.testing.assert_array_equal(full.frames[0].camera.K, [[525, 0, 319.5], [0, 525, 239.5], [0, 0, 1]])


def test_a_tum_folder_read_as_redwood_names_the_tum_format(tmp_path, one_line_error):
    # issue 55's third probe: "the frames have no poses (use --format images to reconstruct them)"
    from frontiernet.sequences import read_redwood

    write_tum(tmp_path / "tum")
    assert main(["sequence", "--input", str(tmp_path / "tum"), "--format", "redwood", "--out", str(tmp_path / "o"),
                 "--no-video"]) == 2
    assert (f"{tmp_path / 'tum'}: not a Redwood folder (no color/ and .log trajectory); it looks like a TUM "
            "sequence: --format tum") in one_line_error()
    assert not (tmp_path / "o").exists()
    redwood = write_redwood(tmp_path / "redwood", count=2)  # a Redwood folder with an rgb.txt beside: still read
    (redwood / "rgb.txt").write_text("")
    assert len(read_redwood(redwood)) == 2


# ----------------------------------------------------------------------------- predict

@pytest.fixture
def rgb_and_depth(tmp_path) -> tuple[Path, Path]:
    """A 32 x 24 image and a 16-bit depth PNG at 2 m (millimetres)."""
    write_image(tmp_path / "rgb.png", 32, 24)
    write_depth(tmp_path / "depth16.png", 32, 24, 2000)
    return tmp_path / "rgb.png", tmp_path / "depth16.png"


@pytest.mark.parametrize("options, message", [
    # issue 55's third probe: the sun encoding ignored --depth-scale
    (["--depth", "{depth}", "--depth-encoding", "sun", "--depth-scale", "5000"],
     "--depth-scale (5000) applies to --depth-encoding scale only; the sun encoding sets its own unit: leave "
     "--depth-scale out"),
    (["--depth", "{depth}", "--depth-encoding", "nyu", "--depth-scale", "1000"], "the nyu encoding sets its own unit"),
    (["--depth-scale", "5000"], "--depth-scale decodes a depth file, and no --depth is given: leave it out"),
    (["--depth", "depth_anything_v2", "--depth-encoding", "sun"],
     "--depth-encoding sun decodes a depth file, and --depth depth_anything_v2 estimates the depth from the image"),
])
def test_predict_refuses_a_depth_decoding_it_would_ignore(options, message, rgb_and_depth, tmp_path, one_line_error):
    rgb, depth = rgb_and_depth
    argv = ["predict", "--image", str(rgb), *(arg.format(depth=depth) for arg in options), "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert message in one_line_error()
    assert not (tmp_path / "o").exists()


def test_implausible_float_depth_says_it_is_read_as_metres(rgb_and_depth, tmp_path, one_line_error):
    # issue 55's third probe: float millimetres were told to "check the depth scale", which float depth refuses
    from frontiernet.sequences.images import read_depth

    rgb, depth = rgb_and_depth
    millimetres = tmp_path / "depth_mm_float.npy"
    np.save(millimetres, cv2.imread(str(depth), cv2.IMREAD_UNCHANGED).astype(np.float32))
    assert main(["predict", "--image", str(rgb), "--depth", str(millimetres), "--out", str(tmp_path / "o")]) == 2
    assert (f"{millimetres}: median depth 2000 m is implausible (float depth is read as metres); the depth is in "
            "another unit: convert it to metres (divide by 1000 for millimetres) or save it as integer millimetres "
            "(uint16)") in one_line_error()
    assert not (tmp_path / "o").exists()
    with pytest.raises(InputError, match=r"is implausible \(read with depth scale 1 units per metre\)"):
        read_depth(depth, 1.0)  # integer depth keeps its advice: check the depth scale
    assert np.allclose(read_depth(depth), 2.0)


def test_a_file_given_to_map_training_as_its_dataset_says_it_is_a_file(tmp_path, one_line_error):
    (tmp_path / "maps.zip").write_bytes(b"not a folder")
    config = Path(__file__).resolve().parents[1] / "configs" / "train_seer.yaml"
    assert main(["train", "--config", str(config), f"data.path={tmp_path / 'maps.zip'}", f"out={tmp_path / 'runs'}"]) == 2
    assert "maps.zip: is a file, expected a folder (map dataset)" in one_line_error()
