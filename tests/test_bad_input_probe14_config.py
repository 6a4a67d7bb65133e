"""Bad input of the fourteenth probe of issue 55 (docs/bad_input.md, "Probe 14") to configs, their ranges and the
JSON files the commands read and write: ``map.voxel_size=1000`` blamed planner.clearance_m twice (P10); ``evaluate
--json ds/dataset.json`` and ``datagen consistency --json`` wrote over existing files without --force, the first over
the dataset's own description (P11); a cut-short ``sequence`` cache entry was an internal error (P12); a corrupt
dataset.json or shard meta.json and a UTF-16 or random-bytes config quoted Python exception names (P13); ``run.seed=~``
said "got None" (P14); four keys took 1e9 or 1e30 (P17); ``explore --start x,y,z,yaw,pitch``, as docs/usage.md gives
it, was refused (P19). Each refusal one line on stderr naming the file or value, exit code 2, nothing written."""

from __future__ import annotations

import io
import json
import logging
import re
import shutil
import zipfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import folder_files

from frontiernet.cli.main import main
from frontiernet.errors import InputError

EXCEPTION_NAME = re.compile(r"\b[A-Z]\w*(Error|Exception)\b")
EXPLORE = ["explore", "--scene", "procedural:3", "--max-steps", "2", "--no-video", "--method", "classic"]


def refused(one_line_error, args) -> str:
    """The one line with which ``frontiernet ARGS`` is refused (exit 2), with no Python exception name in it."""
    assert main(args) == 2
    line = one_line_error()
    assert not EXCEPTION_NAME.search(line) and "None" not in line, line
    return line


# ----------------------------------------------------------------------------- P10: map.voxel_size named

def test_a_map_voxel_size_of_1000_is_named_not_the_clearance(tmp_path, one_line_error):
    line = refused(one_line_error, [*EXPLORE, "map.voxel_size=1000", "--out", str(tmp_path / "ex")])
    assert line.endswith("error: map.voxel_size must be a number in (0, 1], got 1000") and "clearance" not in line
    line = refused(one_line_error, [*EXPLORE, "map.voxel_size=0.5", "--out", str(tmp_path / "ex")])
    assert ("map.voxel_size == sim.voxels.voxel_size must hold (the map lies over the scene's voxel grid, cell for "
            "cell: set both), got map.voxel_size=0.5, sim.voxels.voxel_size=0.1") in line
    assert not (tmp_path / "ex").exists()


def test_the_map_and_the_scene_grid_of_one_voxel_size_are_taken():
    from frontiernet.exploration.run import load_run_config

    load_run_config(overrides=["map.voxel_size=0.05", "sim.voxels.voxel_size=0.05"])
    load_run_config(overrides=["map.voxel_size=1", "sim.voxels.voxel_size=1"])


# ----------------------------------------------------------------------------- P17: upper bounds

@pytest.mark.parametrize("override, message", [
    ("depth.emulated.edge_band_px=1e9", "depth.emulated.edge_band_px must be a number in [0, 4096], got 1000000000.0"),
    ("depth.emulated.fill_depth=1e30", "depth.emulated.fill_depth must be a number in [1e-06, 100], got 1e+30"),
    ("planner.min_distance_m=1e30", "planner.min_distance_m must be a number in (0, 100], got 1e+30"),
])
def test_run_settings_past_any_scene_are_refused(override, message, tmp_path, one_line_error):
    line = refused(one_line_error, [*EXPLORE, "--depth", "emulated", override, "--out", str(tmp_path / "ex")])
    assert line.endswith(f"error: {message}")
    assert not (tmp_path / "ex").exists()


def test_a_floor_headroom_taller_than_any_storey_is_refused(tmp_path, one_line_error):
    config = tmp_path / "headroom.yaml"
    config.write_text("voxels:\n  floor_headroom_m: 1.0e+30\n")
    line = refused(one_line_error, ["scene", "info", "procedural:3", "--config", str(config)])
    assert line.endswith("error: voxels.floor_headroom_m must be a number in (0, 10], got 1e+30")


def test_the_new_bounds_take_the_shipped_values_and_their_edges():
    from frontiernet.exploration.run import load_run_config

    load_run_config()
    load_run_config(overrides=["depth.emulated.edge_band_px=4096", "depth.emulated.fill_depth=100",
                               "planner.min_distance_m=100", "sim.voxels.floor_headroom_m=10"])


# ----------------------------------------------------------------------------- P14: null, not None

@pytest.mark.parametrize("override, message", [
    ("run.seed=~", "run.seed must be an integer in [0, 4294967295], got null"),
    ("planner.clearance_m=null", "planner.clearance_m must be a number > 0, got null"),
    ("run.depth=null", "depth source 'null' (--depth, run.depth) is unknown"),
])
def test_a_null_setting_is_echoed_as_null(override, message, tmp_path, one_line_error):
    assert message in refused(one_line_error, [*EXPLORE, override, "--out", str(tmp_path / "ex")])


def test_a_null_step_budget_is_echoed_as_null(tmp_path, one_line_error):
    line = refused(one_line_error, ["explore", "--scene", "procedural:3", "--no-video", "--method", "classic",
                                    "run.max_steps=~", "--out", str(tmp_path / "ex")])
    assert line.endswith("run.max_steps must be an integer in [1, 100000], got null")


def test_the_shared_checks_write_null_for_none():
    from frontiernet.config import check_ranges
    from frontiernet.errors import fraction_or_null, number_range, positive_number, whole_number

    for check, args in ((positive_number, ()), (whole_number, ()), (number_range, ())):
        with pytest.raises(InputError, match="got null$"):
            check(None, "a.key", *args)
    with pytest.raises(InputError, match=r"got \[1, null\]$"):
        number_range([1, None], "a.key")
    assert fraction_or_null(None, "a.key") is None
    with pytest.raises(InputError, match=r"got \[0.1, null, 0.3\]"):
        check_ranges({"tracking": {"unknown_cap_yaw_offsets_deg": [0.1, None, 0.3]}}, {"": "explore"})


# ----------------------------------------------------------------------------- P13: decoding errors in words

def test_a_utf16_or_random_bytes_config_is_not_utf8_text(tmp_path, one_line_error):
    utf16 = tmp_path / "utf16.yaml"
    utf16.write_bytes("camera:\n  width: 64\n".encode("utf-16"))
    line = refused(one_line_error, ["render", "procedural:3", "--pose", "3,3,1.2,0", "--config", str(utf16),
                                    "--out", str(tmp_path / "o")])
    assert line.endswith(f"error: {utf16}: not a readable YAML config: not UTF-8 text (byte 0xff at offset 0; a "
                         "UTF-16 file? save it as UTF-8)")
    noise = tmp_path / "rand.yaml"
    noise.write_bytes(bytes(np.random.default_rng(0).integers(128, 256, 3000, dtype=np.uint8)))
    line = refused(one_line_error, ["render", "procedural:3", "--pose", "3,3,1.2,0", "--config", str(noise),
                                    "--out", str(tmp_path / "o")])
    assert f"{noise}: not a readable YAML config: not UTF-8 text (byte 0x" in line
    assert not (tmp_path / "o").exists()


def test_a_corrupt_dataset_description_or_shard_meta_is_named_in_words(two_scenes, tmp_path):
    from datagen.shards import read_dataset_info, read_shard_meta

    data = tmp_path / "data"
    shutil.copytree(two_scenes, data)
    (data / "dataset.json").write_text('{"version": 1, ')
    with pytest.raises(InputError) as error:
        read_dataset_info(data)
    assert str(error.value) == (f"{data / 'dataset.json'}: not a readable JSON file: not valid JSON at line 1 column "
                                "16 (Expecting property name enclosed in double quotes)")
    (data / "dataset.json").write_bytes('{"format": 1}'.encode("utf-16"))
    with pytest.raises(InputError, match="dataset.json: not a readable JSON file: not UTF-8 text .byte 0xff at offset "
                                         "0; a UTF-16 file"):
        read_dataset_info(data)
    shard = sorted((data / "shards").glob("*.zip"))[0]
    with zipfile.ZipFile(shard) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    members["meta.json"] = b'{"broken'
    with zipfile.ZipFile(shard, "w") as archive:
        for name, payload in members.items():
            archive.writestr(name, payload)
    with pytest.raises(InputError) as error:
        read_shard_meta(shard)
    assert "corrupt shard (unreadable meta.json: not valid JSON at line 1 column 2 (Unterminated string" \
        in str(error.value)
    assert not EXCEPTION_NAME.search(str(error.value))


# ----------------------------------------------------------------------------- P11: --json over a file

def test_evaluate_json_never_writes_over_the_dataset_nor_a_file_without_force(two_scenes, tmp_path, one_line_error):
    from frontiernet.model import default_model_path

    data = tmp_path / "data"
    shutil.copytree(two_scenes, data)
    kept = folder_files(data)
    model = str(default_model_path())
    for extra in ([], ["--force"]):  # the dataset's own description: never, --force or not
        line = refused(one_line_error, ["evaluate", model, "--data", str(data), "--all", "--max-samples", "1",
                                        "--json", str(data / "dataset.json"), *extra])
        assert line.endswith(f"error: --json {data / 'dataset.json'}: is a file of the dataset (--data) {data}, which "
                             "this command reads; writing its results there would destroy it: choose another file")
    other = tmp_path / "keep.json"
    other.write_text('{"keep": 9}')
    line = refused(one_line_error, ["evaluate", model, "--data", str(data), "--all", "--json", str(other)])
    assert line.endswith(f"error: {other}: exists; pass --force to replace it, or choose another output")
    assert folder_files(data) == kept and other.read_text() == '{"keep": 9}'


def test_consistency_and_mapeval_json_refuse_an_existing_file_without_force(tmp_path, one_line_error):
    keep = tmp_path / "keep9.json"
    keep.write_text('{"keep": 9}')
    line = refused(one_line_error, ["datagen", "consistency", "--scenes", "procedural:3", "--views-per-scene", "1",
                                    "--json", str(keep), "--set", "consistency.resampled_labelings=1"])
    assert line.endswith(f"error: {keep}: exists; pass --force to replace it, or choose another output")
    config = tmp_path / "mine.yaml"
    config.write_text("consistency:\n  resampled_labelings: 1\n")
    line = refused(one_line_error, ["datagen", "consistency", "--scenes", "procedural:3", "--views-per-scene", "1",
                                    "--config", str(config), "--json", str(config), "--force"])
    assert f"--json {config}: is the config file {config}, which this command reads" in line
    line = refused(one_line_error, ["mapeval", str(tmp_path / "none.safetensors"), "--data", str(tmp_path),
                                    "--json", str(keep)])
    assert f"--json {keep}: is a file of the dataset (--data) {tmp_path}" in line  # (an input folder holds it)
    (tmp_path / "maps").mkdir()
    line = refused(one_line_error, ["mapeval", str(tmp_path / "none.safetensors"), "--data", str(tmp_path / "maps"),
                                    "--json", str(keep)])
    assert line.endswith(f"error: {keep}: exists; pass --force to replace it, or choose another output")
    assert keep.read_text() == '{"keep": 9}' and config.read_text() == "consistency:\n  resampled_labelings: 1\n"


# ----------------------------------------------------------------------------- P12: a damaged cache entry

class FakeStream:
    """What :func:`frontiernet.sequences.perceive.perceive_frames` uses of a FrontierStream: it counts the frames
    it perceives."""

    def __init__(self):
        self.depth_source, self.conf, self.perceived = None, SimpleNamespace(
            network={"size": 64, "crop": True, "fill_invalid_depth": False}), []

    def perceive(self, rgb, depth, K, name="frame"):
        self.perceived.append(name)
        return {"rgb": rgb, "depth": depth, "K": K, "distance_field": np.zeros((4, 4), np.float16),
                "gain_class": np.zeros((4, 4), np.uint8), "full_depth": depth.astype(np.float16)}


def fake_frames(count: int) -> list:
    camera = SimpleNamespace(K=np.diag([50.0, 50.0, 1.0]))
    return [SimpleNamespace(index=index, name=f"{index:05d}", camera=camera, rgb=lambda: np.zeros((4, 4, 3), np.uint8),
                            depth=lambda: np.ones((4, 4), np.float32)) for index in range(count)]


@pytest.mark.parametrize("damage", ["cut", "crc"])
def test_a_damaged_sequence_cache_entry_is_computed_again_with_a_warning(damage, tmp_path, caplog):
    from frontiernet.sequences.perceive import load_cached, perceive_frames

    frames, cache = fake_frames(3), tmp_path / "cache"
    first = FakeStream()
    paths = perceive_frames(frames, first, cache, "model", progress=False)
    assert first.perceived == ["00000", "00001", "00002"]
    whole = paths[1].read_bytes()
    if damage == "cut":  # head -c 1000 of the entry, as a full disk or a killed copy leaves it
        paths[1].write_bytes(whole[:len(whole) // 3])
    else:  # a flipped byte inside a compressed member: the zip's CRC check fails as it is read
        with zipfile.ZipFile(io.BytesIO(whole)) as archive:
            info = archive.getinfo("full_depth.npy")
        at = info.header_offset + 30 + len(info.filename) + len(info.extra) + info.compress_size // 2
        paths[1].write_bytes(whole[:at] + bytes([whole[at] ^ 0xFF]) + whole[at + 1:])
    with caplog.at_level(logging.WARNING):
        assert load_cached(paths[1]) is None
        again = FakeStream()
        perceive_frames(frames, again, cache, "model", progress=False)
    assert again.perceived == ["00001"]  # (was: internal error, BadZipFile)
    warnings = [record.getMessage() for record in caplog.records if record.levelno == logging.WARNING]
    assert warnings and all(text.startswith(f"{paths[1]}: a damaged cache entry (") and text.endswith(
        "); computed again") and not EXCEPTION_NAME.search(text) for text in warnings)
    assert load_cached(paths[1]) is not None


# ----------------------------------------------------------------------------- P19: --start's pitch

def test_explore_start_takes_a_pitch_as_the_runs_camera_tilt(tmp_path, capsys):
    from omegaconf import OmegaConf

    from frontiernet.exploration.run import check_run, load_run_config, start_pitch_deg

    assert start_pitch_deg("3,3,1.2,0") is None and start_pitch_deg(None) is None
    assert start_pitch_deg("3,3,1.2,0,10") == 10.0 and start_pitch_deg("3,3,1.2,0,-0.1rad") == pytest.approx(-5.729578)
    check_run(load_run_config(), method="classic", start="3,3,1.2,0,10", video=False)
    out = tmp_path / "st1"
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "1", "--no-video", "--method", "classic",
                 "--start", "3,3,1.2,0,10", "--out", str(out)]) == 0
    assert OmegaConf.load(out / "config.yaml").motion.pitch_deg == 10.0
    start = np.array(json.loads((out / "metrics.json").read_text())["start"])
    assert np.degrees(np.arcsin(start[2, 2])) == pytest.approx(10.0, abs=1e-3)  # the optical axis looks up 10 deg
    assert "x,y,z,yaw[,pitch]" in Path(__file__).resolve().parents[1].joinpath("docs", "exploration.md").read_text()


@pytest.mark.parametrize("start, extra, message", [
    ("3,3,1.2,0,10", ["motion.pitch_deg=5"], "--start 3,3,1.2,0,10 (pitch 10 degrees) contradicts motion.pitch_deg=5: "
                                             "give one of them"),
    ("3,3,1.2,0,90", [], "--start '3,3,1.2,0,90': pitch must lie strictly between -90 and 90 degrees"),
    ("3,3,1.2,0,10,1", [], "--start '3,3,1.2,0,10,1': expected x,y,z,yaw[,pitch]"),
])
def test_explore_start_refuses_a_pitch_it_cannot_take(start, extra, message, tmp_path, one_line_error):
    line = refused(one_line_error, [*EXPLORE, "--start", start, *extra, "--out", str(tmp_path / "st")])
    assert message in line and not (tmp_path / "st").exists()


def test_a_start_pitch_the_same_as_motion_pitch_deg_is_no_contradiction():
    from frontiernet.cli.explore import refuse_pitch_contradiction

    refuse_pitch_contradiction("3,3,1.2,0,10", ["motion.pitch_deg=10"])
    refuse_pitch_contradiction("3,3,1.2,0", ["motion.pitch_deg=5"])
