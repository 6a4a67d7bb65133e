"""Declared ranges: every number and switch of every shipped config has one (configs/ranges/), the shipped
values are in them, and a value outside is refused in one line naming the key, before any work."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
import yaml

from frontiernet.cli.main import main
from frontiernet.config import check_ranges, load_config
from frontiernet.config_ranges import declared, declared_relations, parse_range, parse_relation
from frontiernet.errors import InputError

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
USER_FILES = {"train_tiny"}
"""Shipped configs that are user files over another (``train --config configs/train_tiny.yaml``):
their keys are the other's, checked by its ranges."""


def _leaves(tree, prefix=""):
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from _leaves(value, f"{name}.")
        else:
            yield name, value


def _is_declared(value) -> bool:
    """Numbers, lists of numbers and switches (true / false) must be declared."""
    numeric = (int, float)
    return isinstance(value, numeric) or (
        isinstance(value, list) and bool(value) and all(isinstance(v, numeric) and not isinstance(v, bool)
                                                         for v in value))


CONFIG_NAMES = sorted(path.stem for path in CONFIGS.glob("*.yaml") if path.stem not in USER_FILES)


@pytest.mark.parametrize("name", CONFIG_NAMES)
def test_every_number_of_a_shipped_config_has_a_range_its_value_is_in(name):
    leaves = dict(_leaves(yaml.safe_load((CONFIGS / f"{name}.yaml").read_text()) or {}))
    ranges = declared(name)
    undeclared = [key for key, value in leaves.items() if _is_declared(value) and key not in ranges]
    assert not undeclared, f"configs/ranges/{name}.yaml lacks {undeclared}"
    stale = [key for key in ranges if key not in leaves]
    assert not stale, f"configs/ranges/{name}.yaml declares keys configs/{name}.yaml does not have: {stale}"
    load_config(name)  # the shipped values are in their ranges (InputError otherwise)


def test_the_user_file_configs_hold_only_values_in_range():
    for name in USER_FILES:
        tree = yaml.safe_load((CONFIGS / f"{name}.yaml").read_text())
        check_ranges(tree, {"": "train", "model": "model"})


@pytest.mark.parametrize("spec, good, bad, words", [
    # numbers are computed in float32 and int64: past them a value overflowed (1e300: an internal error in
    # train, RuntimeWarnings in render) or vanished to 0 (an rgb_std of 1e-300 divided by 0); 10**400 crashed
    ("(0, inf)", [0.1, 3, 3e38, 1.2e-38], [0, -1, math.inf, True, "1", 1e300, 1e-300, 10 ** 400], "a number > 0"),
    ("int [1, inf)", [1, 40, 2 ** 63 - 1], [0, 1.0, 2.5, 2 ** 63, 10 ** 400], "an integer >= 1"),
    ("[0, 1] or null", [0, 1, None, 0.5], [1.5, -0.1], "a number in [0, 1] (or null)"),
    ("pair [-inf, inf]", [[-1, 2], [3, 3]], [[2, 1], [1], [1, 2, 3], 4],
     "a [min, max] pair of numbers with min <= max"),
    ("box [-50, 50]", [[[-1, -1, 0], [1, 1, 3]]], [[[1, -1, 0], [-1, 1, 3]], [[0, 0], [1, 1]], [[0, 0, 0]]],
     "a [[min x, y, z], [max x, y, z]] box of numbers in [-50, 50] with min < max on each axis"),
    ("increasing list int [1, inf)", [[1, 50, 150]], [[1, 0], [1, 1], [0, 5], [1.5, 2]],
     "a list of integers >= 1 in increasing order"),
    ("list length 3 [0, 255]", [[0, 1, 255]], [[0, 1], [0, 1, 256]], "a list of 3 numbers in [0, 255]"),
    (["free", "skip"], ["free", "skip"], ["bogus", 1, None], "one of free, skip"),
    (["rgb", None], ["rgb", None], ["depth"], "one of rgb (or null)"),
    ([6, 26], [6, 26], [18, 6.0, True, "6", None], "one of 6, 26"),  # integer choices (frontier connectivity)
    ("int [0, 256] or auto or null", [0, "auto", None], ["many", -1, 0.5], "an integer in [0, 256] (or auto or null)"),
])
def test_range_specs_admit_what_they_say(spec, good, bad, words):
    declared_range = parse_range(spec, "test")
    assert all(declared_range.admits(value) for value in good)
    assert not any(declared_range.admits(value) for value in bad)
    assert declared_range.describe() == words


@pytest.mark.parametrize("spec", ["0, 1", "[0, 1", "between [0, 1]", "length [0, 1]", []])
def test_a_malformed_declaration_names_itself(spec):
    with pytest.raises(ValueError, match="test"):
        parse_range(spec, "test")


@pytest.mark.parametrize("argv, message", [  # the fourth bad-input probe's accepted nonsense (issue 55)
    (["explore", "--scene", "procedural:0", "planner.gain_exponent=-2"], "planner.gain_exponent must be"),
    (["explore", "--scene", "procedural:0", "tracking.merge_distance_m=-1"], "tracking.merge_distance_m must be"),
    (["explore", "--scene", "procedural:0", "run.start_clearance_m=-1"], "run.start_clearance_m must be"),
    (["explore", "--scene", "procedural:0", "run.video_every_steps=0"], "run.video_every_steps must be an integer"),
    (["explore", "--scene", "procedural:0", "ground_truth.truncation_px=0"], "ground_truth.truncation_px must be"),
    (["explore", "--scene", "procedural:0", "map.invalid_depth=bogus"], "map.invalid_depth must be one of free, skip"),
    (["explore", "--scene", "procedural:0", "scenes.procedural.rooms_max=1000000000"], "scenes.procedural.rooms_max"),
    (["datagen", "--scenes", "procedural:0", "--views-per-scene", "1", "--set", "writer.jpg_quality=500"],
     "writer.jpg_quality must be an integer in"),
    (["datagen", "--scenes", "procedural:0", "--views-per-scene", "1", "--set", "ground_truth.gain.bin_edges=[1,0]"],
     "ground_truth.gain.bin_edges must be a list of integers"),
    (["train", "data.path=x", "trainer.gradient_clip_val=-1"], "trainer.gradient_clip_val must be"),
    (["train", "data.path=x", "trainer.log_every_n_steps=0"], "trainer.log_every_n_steps must be an integer >= 1"),
    (["train", "data.path=x", "optim.warmup_steps=-1"], "optim.warmup_steps must be an integer >= 0"),
    # numpy's "Maximum allowed size exceeded", reported as the scene's failure (the seventh probe's D16)
    (["datagen", "--scenes", "procedural:0", "--views-per-scene", "1", "--set", "sampling.mode=trajectory",
      "sampling.trajectory.spacing_m=1e-9"], "sampling.trajectory.spacing_m must be a number >= 0.01, got 1e-09"),
    (["explore", "--scene", "procedural:0", "sim.camera.max_depth=1e300"],
     "sim.camera.max_depth must be a number in (0, 100], got 1e+300: beyond the 32-bit floats it is computed in"),
    # YAML reads 1e400 as inf: "must be a number > 0, got inf" alone (the seventh probe's D24)
    (["explore", "--scene", "procedural:0", "planner.clearance_m=1e400"], "planner.clearance_m must be a number > 0, "
     "got inf: not a finite number (a number past 1.8e308, such as 1e400, overflows a float to infinity)"),
    (["explore", "--scene", "procedural:0", "run.max_steps=1e400"], "run.max_steps must be an integer in [1, 100000], "
     "got inf: not a finite number"),
    (["explore", "--scene", "procedural:0", "planner.clearance_m=.nan"], "planner.clearance_m must be a number > 0, "
     "got nan: not a number (NaN)"),
    (["explore", "--scene", "procedural:0", "anchoring.max_pixels=" + "9" * 30],
     "anchoring.max_pixels must be an integer >= 2, got 999999999999999999999999999999: beyond the 64-bit integers"),
])
def test_a_value_outside_its_range_is_one_line_before_any_work(argv, message, tmp_path, one_line_error):
    out = tmp_path / "out"
    argv = argv[:1] + ["--out", str(out)] + argv[1:] if argv[0] != "train" else argv + [f"out={out}"]
    assert main(argv) == 2
    assert message in one_line_error()
    assert not out.exists()


def test_a_library_caller_gets_the_same_check():
    with pytest.raises(InputError, match=r"map.voxel_size must be a number in \(0, 1\], got -0.1"):
        load_config("explore", overrides=["map.voxel_size=-0.1"])


@pytest.mark.parametrize("spec, message", [
    ("procedural:0?rooms_max=1000000000",
     "procedural option rooms_max must be an integer in [1, 1000], got 1000000000"),
    ("procedural:0?texture_pixels=13", "option texture_pixels must be a multiple of 4, got 13"),  # was an IndexError
])
def test_a_scene_spec_option_keeps_to_the_same_ranges(spec, message):
    from frontiernet.scenes.spec import load_scene
    from frontiernet.simulator.world import load_world_config

    with pytest.raises(InputError, match=re.escape(message)):
        load_scene(spec, load_world_config().scenes)


@pytest.mark.parametrize("text, values, holds", [
    ("a <= b < c", {"a": -2, "b": 0.0, "c": 3.5}, True),
    ("a <= b < c", {"a": -2, "b": 3.5, "c": 3.5}, False),
    ("a + b <= 1", {"a": 0.6, "b": 0.5}, False),
    ("a >= 2 * b + 0.5", {"a": 3.5, "b": 1.5}, True),
    ("a >= 2 * b + 0.5", {"a": 3.0, "b": 1.5}, False),
    ("a == len(b)", {"a": 11, "b": list(range(11))}, True),
    ("a == len(b)", {"a": 5, "b": list(range(11))}, False),
    ("a <= b", {"a": 1, "b": None}, None),   # null turns the rule off
    ("a <= b", {"a": 1}, None),              # a key the config lacks
    ("a <= b", {"a": "auto", "b": 1}, None),  # no number: its own range says so
])
def test_a_relation_holds_where_it_says(text, values, holds):
    assert parse_relation(text, "why", "test").holds(values) is holds


@pytest.mark.parametrize("text, reason", [("a", "why"), ("a <=", "why"), ("a <= b c", "why"), ("a <= b", "")])
def test_a_malformed_relation_names_itself(text, reason):
    with pytest.raises(ValueError, match="test"):
        parse_relation(text, reason, "test")


@pytest.mark.parametrize("name", CONFIG_NAMES)
def test_every_relation_reads_declared_keys(name):
    for relation in declared_relations(name):
        for key in relation.keys():
            other, colon, other_key = key.partition(":")
            assert (other_key in declared(other)) if colon else (key in declared(name)), \
                f"configs/ranges/{name}.yaml: {relation.text()} reads {key}, which no range declares"


def test_the_shipped_run_config_keeps_its_cross_file_relations():
    from frontiernet.exploration.run import load_run_config

    load_run_config()  # explore's relation with sim.camera.max_depth holds for the shipped values
    with pytest.raises(InputError, match=re.escape("map.max_range_m <= sim.camera.max_depth must hold")):
        load_run_config(overrides=["map.max_range_m=5"])
    load_config("explore", overrides=["map.max_range_m=5"])  # without a camera there is nothing to compare


@pytest.mark.parametrize("argv, message", [  # the sixth bad-input probe's cross-key nonsense (issue 55)
    (["explore", "--scene", "procedural:0", "map.occupied_threshold=4"],
     "map.log_odds_min <= map.occupied_threshold < map.log_odds_max must hold"),
    (["explore", "--scene", "procedural:0", "sim.camera.max_depth=2"], "map.max_range_m <= sim.camera.max_depth"),
    (["explore", "--scene", "procedural:0", "planner.traversed_is_free=null"],
     "planner.traversed_is_free must be true or false, got null"),
    (["explore", "--scene", "procedural:0", "scenes.procedural.l_shape_probability=0.9"],
     "scenes.procedural.l_shape_probability + scenes.procedural.u_shape_probability <= 1 must hold"),
    (["datagen", "--scenes", "procedural:0", "--views-per-scene", "1", "--set", "ground_truth.gain.min_samples=64"],
     "ground_truth.gain.min_samples <= ground_truth.gain.max_samples must hold"),
    (["train", "data.path=x", "model.labels.num_classes=5"], "model.labels.num_classes == len(model.labels.bin_edges)"),
    (["train", "data.path=x", "model.labels.frontier_threshold_px=20"],
     "model.labels.frontier_threshold_px < model.labels.truncation_px"),
    # refused only after a scene was labelled, as a failure of the scene (the seventh probe's D15)
    (["datagen", "--scenes", "procedural:0", "--views-per-scene", "1", "--set",
      f"ground_truth.gain.bin_edges=[{','.join(map(str, range(300)))}]"],
     "len(ground_truth.gain.bin_edges) <= 256 must hold (a gain class an edge, stored as an 8-bit class index "
     "(0-255), as model.labels.num_classes), got ground_truth.gain.bin_edges=[0, 1, 2, ..., 299] (300 items)"),
])
def test_a_broken_relation_is_one_line_before_any_work(argv, message, tmp_path, one_line_error):
    test_a_value_outside_its_range_is_one_line_before_any_work(argv, message, tmp_path, one_line_error)


def test_a_scene_spec_option_keeps_to_the_relations():
    from frontiernet.scenes.spec import load_scene
    from frontiernet.simulator.world import load_world_config

    with pytest.raises(InputError, match=re.escape("procedural option footprint_short_min <= footprint_max must "
                                                   "hold (the short side is at most the long one)")):
        load_scene("procedural:0?footprint_short_min=40", load_world_config().scenes)
