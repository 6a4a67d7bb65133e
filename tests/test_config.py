"""Configs: user files and ``key=value`` overrides merge over the shipped YAML, and a key the
shipped config does not have (a typo) is refused by name instead of being ignored."""

from __future__ import annotations

import pytest

from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.sequences.main import load_sequence_config
from train.config import load_train_config


def test_overrides_and_user_files_replace_defaults(tmp_path):
    user = tmp_path / "mine.yaml"
    user.write_text("planner:\n  mode: map_free\n")
    conf = load_config("explore", user, ["tracking.min_gain_m3=2.5"])
    assert conf.planner.mode == "map_free" and conf.tracking.min_gain_m3 == 2.5
    assert conf.planner.clearance_m == load_config("explore").planner.clearance_m  # the rest kept


def test_a_misspelt_override_is_refused_with_the_likely_key():
    with pytest.raises(InputError, match="unknown config key 'tracking.min_gain'; did you mean tracking.min_gain_m3"):
        load_config("explore", overrides=["tracking.min_gain=2"])
    with pytest.raises(InputError, match="unknown config key 'plannr'; did you mean planner"):
        load_config("explore", overrides=["plannr.mode=map"])
    with pytest.raises(InputError, match="did you mean anchoring.hdbscan.min_cluster_size"):  # one level down
        load_config("explore", overrides=["anchoring.min_cluster_size=9"])
    with pytest.raises(InputError, match="not of the form key=value"):
        load_config("explore", overrides=["planner.mode"])


def test_a_user_file_with_an_unknown_key_is_refused_naming_the_file(tmp_path):
    user = tmp_path / "mine.yaml"
    user.write_text("planner:\n  mode: map\n  gain_exponant: 2\n")
    with pytest.raises(InputError, match=r"mine.yaml: unknown config key 'planner.gain_exponant'; did you mean "
                                         r"planner.gain_exponent"):
        load_config("explore", user)


def test_a_value_of_another_kind_than_the_default_is_refused(tmp_path):
    with pytest.raises(InputError, match="'planner.clearance_m' takes a number \\(default 0.2\\), got 'abc'"):
        load_config("explore", overrides=["planner.clearance_m=abc"])
    with pytest.raises(InputError, match="'planner.unknown_is_obstacle' takes true or false"):
        load_config("explore", overrides=["planner.unknown_is_obstacle=1"])
    user = tmp_path / "flat.yaml"
    user.write_text("planner: 3\n")  # a whole section replaced by a number (was a traceback later)
    with pytest.raises(InputError, match="flat.yaml: config key 'planner' takes a section"):
        load_config("explore", user)
    # null is taken where the key's range has it (train_tiny.yaml sets data.image_size: null), integers for floats
    assert load_config("explore", overrides=["planner.clearance_m=1", "map.depth_edge_rtol=null"]).planner.clearance_m == 1
    with pytest.raises(InputError, match="run.max_steps must be an integer in \\[1, 100000\\], got null$"):
        load_config("explore", overrides=["run.max_steps=null"])  # (configs/ranges/explore.yaml)


def test_open_sections_and_other_configs_sections_are_accepted(tmp_path):
    # the sequence config's depth section is depth.yaml's; its anchoring section comes from explore.yaml
    conf = load_sequence_config(None, ["depth.depth_anything_v2.path=/weights/vits.pth",
                                       "anchoring.hdbscan.min_cluster_size=9"])
    assert conf.depth.depth_anything_v2.path == "/weights/vits.pth" and conf.anchoring.hdbscan.min_cluster_size == 9
    # a training file may set the model's keys (model.yaml under `model`) and a null default
    user = tmp_path / "train.yaml"
    user.write_text("model:\n  network:\n    encoder: resnet34\ndata:\n  val_scenes: [procedural:3]\n")
    conf = load_train_config(user, ["data.path=/data"])
    assert conf.model.network.encoder == "resnet34" and list(conf.data.val_scenes) == ["procedural:3"]
    with pytest.raises(InputError, match="unknown config key 'model.network.encodr'"):
        load_train_config(None, ["data.path=/data", "model.network.encodr=resnet34"])


def test_the_command_line_refuses_an_unknown_key_in_one_line(plan_spec, tmp_path, capsys):
    assert main(["explore", "--scene", plan_spec, "--max-steps", "2", "--out", str(tmp_path / "run"),
                 "planner.bogus=1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown config key 'planner.bogus'" in err and "\n" not in err
    assert not (tmp_path / "run").exists()
