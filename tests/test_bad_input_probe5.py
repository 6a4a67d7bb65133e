"""Bad input of the fifth probe of issue 55 (docs/bad_input.md): one line naming the file, option or value
and what is wrong, exit code 2, no traceback, refused before any setup and before any folder is made.
Each test failed before its fix (a run that took the value, another message, or a second line)."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from frontiernet.cli.main import main
from frontiernet.errors import InputError

HUGE_SEED = str(10**20)


# ----------------------------------------------------------------------------- seeds (items 1 and 3)

@pytest.mark.parametrize("argv, message", [
    (["explore", "--scene", "procedural:3", "--seed", HUGE_SEED, "--out", "{out}"],
     f"the seed (--seed, run.seed) must be an integer in [0, 4294967295], got {HUGE_SEED} (numpy's seed range)"),
    (["bench", "--scenes", "procedural:3", "--methods", "classic", "--seed", HUGE_SEED, "--out", "{out}"],
     "the seed (--seed, run.seed) must be an integer in [0, 4294967293]"),
    # the runs of a benchmark are seeded seed .. seed + repeats - 1: the last must be in range too
    (["bench", "--scenes", "procedural:3", "--methods", "classic", "--seed", "4294967295", "--out", "{out}"],
     "the runs' seeds are --seed to --seed + 2 (--repeats 3)"),
    (["datagen", "--scenes", "procedural:3", "--views-per-scene", "1", "--seed", "4294967296", "--out", "{out}"],
     "--seed must be an integer in [0, 4294967295], got 4294967296 (numpy's seed range)"),
    (["mapgen", "--scenes", "procedural:3", "--seed", HUGE_SEED, "--out", "{out}"],
     f"--seed must be an integer in [0, 4294967295], got {HUGE_SEED}"),
])
def test_a_seed_past_numpys_range_is_refused_before_anything(argv, message, tmp_path, one_line_error):
    # fifth probe: --seed 100000000000000000000 ran (explore, bench) or made a dataset (datagen, mapgen)
    out = tmp_path / "o"
    assert main([arg.format(out=out) for arg in argv]) == 2
    assert message in one_line_error()
    assert not out.exists()


@pytest.mark.parametrize("seed", ["-1", "4294967296"])
def test_datagen_consistency_refuses_a_seed_out_of_range(seed, tmp_path, one_line_error):
    # fifth probe: `datagen consistency --seed=-1` labelled views with a seed of its own hash (no such
    # scene file: the old code got past the seed to fail on the scene)
    assert main(["datagen", "consistency", "--scenes", str(tmp_path / "none.glb"), "--views-per-scene", "1",
                 f"--seed={seed}"]) == 2
    assert f"--seed must be an integer in [0, 4294967295], got {seed}" in one_line_error()


def test_a_training_seed_past_lightnings_range_is_refused_by_the_library():
    from frontiernet.errors import MAX_SEED, check_seed

    assert check_seed(MAX_SEED, "seed") == MAX_SEED
    with pytest.raises(InputError, match=r"seed must be an integer in \[0, 4294967295\], got 4294967296"):
        check_seed(MAX_SEED + 1, "seed")


# ----------------------------------------------------------------------------- bench's benchmarks (item 2)

@pytest.mark.parametrize("argv, message", [
    # --methods was dropped: bench explore timed its own --method (frontiernet)
    (["--methods", "classic", "explore", "--steps", "0"],
     "--methods applies to `frontiernet bench` itself, not to `bench explore` (give --method (not --methods) "
     "after `explore`)"),
    (["--methods", "classic", "map", "--frames", "0"], "--methods applies to `frontiernet bench` itself, not to "
                                                       "`bench map`"),
    # --depth emulated was dropped for bench explore's own --depth (default: ground truth)
    (["--depth", "emulated", "explore", "--steps", "0"], "(give --depth after `explore`)"),
    (["--seed", "3", "--starts", "2", "render", "--repeats", "0"],
     "--starts/--seed apply to `frontiernet bench` itself, not to `bench render`"),
])
def test_exploration_benchmark_options_before_a_hot_path_benchmark_are_refused(argv, message, one_line_error):
    # (the benchmarks' own counts of 0 end the old code at once: it got past the dropped option)
    with pytest.raises(SystemExit) as stop:
        main(["bench", *argv])
    assert stop.value.code == 2
    assert message in one_line_error()


# ----------------------------------------------------------------------------- --resume (item 4)

def test_datagen_resume_with_nothing_to_resume_says_so_then_starts(tmp_path, capsys):
    out = tmp_path / "new"
    assert main(["datagen", "--scenes", "procedural:3", "--views-per-scene", "1", "--out", str(out), "--resume",
                 "--no-progress", "--set", "camera.width=32", "camera.height=32", "camera.focal_px=20"]) == 0
    printed = capsys.readouterr()
    assert (f"datagen: note: --resume: {out} holds no dataset yet (no dataset.json), so there is nothing to "
            "resume; starting a new one") in printed.out
    assert printed.err == "" and (out / "dataset.json").is_file()


def test_mapgen_resume_with_nothing_to_resume_says_so(tmp_path, capsys, monkeypatch):
    import datagen.mapgen as mapgen

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):  # after the output is prepared: the runs themselves are not this test's
        raise Stop

    monkeypatch.setattr(mapgen, "plan_map_tasks", stop)
    out = tmp_path / "maps"
    with pytest.raises(Stop):
        mapgen.generate_maps(["procedural:3"], out, mapgen.load_mapgen_config(), resume=True, progress=False)
    assert f"mapgen: note: --resume: {out} holds no dataset yet" in capsys.readouterr().out


# ----------------------------------------------------------------------------- depth images (item 5)

def test_an_8_bit_depth_image_is_refused_naming_the_file(tmp_path, one_line_error):
    from frontiernet.sequences.images import read_depth

    image, depth = tmp_path / "rgb.png", tmp_path / "depth8.png"
    cv2.imwrite(str(image), np.full((48, 64, 3), 128, np.uint8))
    cv2.imwrite(str(depth), np.full((48, 64), 200, np.uint8))  # 200 "mm": was read as 0.2 m of depth
    out = tmp_path / "p"
    assert main(["predict", "--image", str(image), "--depth", str(depth), "--out", str(out)]) == 2
    assert f"{depth}: an 8-bit image; depth images must be 16-bit" in one_line_error()
    assert not out.exists()
    with pytest.raises(InputError, match="an 8-bit image"):  # sequence's frames read depth the same way
        read_depth(depth)
    cv2.imwrite(str(depth), np.full((48, 64), 2000, np.uint16))
    assert np.allclose(read_depth(depth), 2.0)


# ----------------------------------------------------------------------------- export (item 6)

@pytest.mark.parametrize("threshold", ["1e9", "10.5", "10"])  # 10, the truncation (eighth probe, E10): 100 % frontier
def test_export_refuses_a_frontier_threshold_past_the_truncation(threshold, tmp_path, one_line_error):
    from frontiernet.model import default_model_path

    out = tmp_path / "m.safetensors"
    assert main(["export", str(default_model_path()), "--format", "safetensors", "--out", str(out),
                 "--frontier-threshold", threshold]) == 2
    assert "--frontier-threshold must be in (0.1, 10) pixels" in one_line_error()
    assert not out.exists()


# ----------------------------------------------------------------------------- the command line (item 7)

@pytest.mark.parametrize("argv, message", [
    (["explor", "--scene", "x"], "frontiernet: error: unknown command 'explor' (did you mean explore?)"),
    (["-v", "bnech"], "unknown command 'bnech' (did you mean bench?)"),
    (["bench", "--seed", "3", "rendr"], "frontiernet bench: error: unknown benchmark 'rendr' (did you mean render?)"),
])
def test_a_misspelt_command_is_named_with_the_one_meant(argv, message, one_line_error):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    assert message in one_line_error()


def test_options_with_several_values_before_a_command_are_not_taken_for_one():
    from frontiernet.cli.main import build_parser

    args = build_parser().parse_args(["bench", "--scenes", "procedural:3", "procedural:4", "--out", "o"])
    assert args.scenes == ["procedural:3", "procedural:4"] and args.action is None


# ----------------------------------------------------------------------------- scene specs (items 8, 9, 11)

def test_a_scene_option_without_a_value_is_named(one_line_error):
    # fifth probe: default?bounds= was "default: no such file ... (use ... or 'default')"; procedural:3?floors=
    # dropped the option (read as null)
    from frontiernet.scenes.spec import parse_spec

    assert main(["scene", "info", "default?bounds="]) == 2
    assert "option bounds= has no value; give bounds=VALUE, or leave bounds out" in one_line_error()
    with pytest.raises(InputError, match="option floors= has no value"):
        parse_spec("procedural:3?floors=")
    assert parse_spec("default?bounds=-5,-5,0,20,15,4").argument == "0"


def test_a_negative_map_margin_of_sequence_is_one_line():
    # fifth probe: bounds_margin_m=-1 inverted the map's bounds: a two-line message (an array's repr)
    from frontiernet.mapping import OccupancyMap
    from frontiernet.sequences.main import check_outputs
    from frontiernet.sequences.stream import load_sequence_config

    conf = load_sequence_config()
    conf.bounds_margin_m = -1.0  # (as a library caller sets it: past the config's range check)
    with pytest.raises(InputError, match=r"bounds_margin_m must be a number in \[0, 20\], got -1.0"):
        check_outputs(conf)
    with pytest.raises(InputError) as error:
        OccupancyMap.from_bounds(np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]), load_sequence_config().map)
    assert "\n" not in str(error.value) and "[[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]" in str(error.value)


def test_a_mesh_of_1e30_metres_is_one_line_without_a_warning(tmp_path, one_line_error):
    import trimesh

    box = trimesh.creation.box(extents=(6.0, 4.0, 3.0))
    box.vertices *= 1e29
    box.export(tmp_path / "huge.ply")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # numpy's "invalid value encountered in cast"
        assert main(["scene", "info", str(tmp_path / "huge.ply")]) == 2
    assert "voxels > voxels.max_voxels" in one_line_error()


# ----------------------------------------------------------------------------- training (items 10, 12, 13, 15)

@pytest.mark.parametrize("overrides, message", [
    # stopped before its first step, left runs/tiny and said "last.ckpt: model file not found"
    (["trainer.max_time=00:00:00:00"], "trainer.max_time: 00:00:00:00 leaves no time to train"),
    (["trainer.max_time=1h"], "trainer.max_time: a wall-clock limit is DD:HH:MM:SS (e.g. 00:01:00:00), or null"),
    # refused only when the loaders started, after the trainer's setup
    (["data.num_workers=bad"], "data.num_workers must be an integer in [0, "),
    (["data.cache_workers=-1"], "data.cache_workers must be an integer in [0, "),
    # a blank run name trained into a folder named ' '
    (["name=' '"], "name: the run's folder name inside out= is blank (' '); give one, e.g. name=tiny"),
    (["seed=4294967296"], "seed must be an integer in [0, 4294967295], got 4294967296"),
])
def test_training_settings_are_refused_before_the_data_and_the_trainer(overrides, message, tmp_path,
                                                                        one_line_error):
    runs = tmp_path / "runs"  # (no dataset: the old code got past these settings to refuse the data)
    assert main(["train", "--no-progress", f"data.path={tmp_path / 'no_data'}", f"out={runs}", "name=tiny",
                 "trainer.accelerator=cpu", *overrides]) == 2
    assert message in one_line_error()
    assert not runs.exists()


def test_a_training_cache_under_a_missing_folder_is_refused_and_nothing_made(tmp_path, one_line_error):
    # fifth probe: data.cache=/nonexistent/dir made /nonexistent (as root) and built the cache there
    cache = tmp_path / "nonexistent" / "dir"
    assert main(["train", "--no-progress", f"data.path={tmp_path / 'no_data'}", f"out={tmp_path / 'runs'}",
                 f"data.cache={cache}"]) == 2
    assert f"data.cache={cache}: the folder it goes in, {cache.parent}, does not exist" in one_line_error()
    assert not cache.parent.exists() and not (tmp_path / "runs").exists()


@pytest.fixture(scope="module")
def two_scenes(tmp_path_factory):
    """A tiny datagen dataset: 2 procedural scenes x 2 views of 32 x 32 px."""
    from datagen.config import load_datagen_config
    from datagen.generate import generate

    out = tmp_path_factory.mktemp("data") / "two"
    conf = load_datagen_config(overrides=["camera.width=32", "camera.height=32", "camera.focal_px=20",
                                          "writer.shard_size=2"])
    generate(["procedural:3", "procedural:4"], 2, out, conf, seed=0, workers=1, progress=False)
    return out


@pytest.mark.parametrize("overrides, message", [
    (["data.batch_size=100"], "data.batch_size: 100 is more than the 2 training views"),
    # (a precision is checked before the data: probe6's; a strategy too since the eighth probe's E4)
    (["trainer.strategy=bogus"], "trainer.strategy=bogus: not one this training takes"),
])
def test_loop_and_trainer_settings_are_refused_before_the_training_cache(two_scenes, overrides, message, tmp_path,
                                                                         one_line_error):
    cache = tmp_path / "cache"  # (built before these refusals before)
    assert main(["train", "--no-progress", f"data.path={two_scenes}", f"out={tmp_path / 'runs'}", "data.image_size=32",
                 "augment.crop_size=null", "data.num_workers=0", f"data.cache={cache}", "trainer.accelerator=cpu",
                 "data.batch_size=2", *overrides]) == 2
    assert message in one_line_error()
    assert not cache.exists() and not (tmp_path / "runs").exists()


# ----------------------------------------------------------------------------- gain bins (item 14)

def test_gain_bin_edges_out_of_order_are_named_as_plain_numbers():
    from frontiernet.frontiers.gain import gain_classes

    with pytest.raises(InputError) as error:
        gain_classes(np.zeros(3), np.array([1, 0]), np.float64(0.01))
    assert "got [1, 0] x 0.01" in str(error.value) and "np." not in str(error.value)
