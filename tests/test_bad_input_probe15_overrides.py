"""Bad input of the fifteenth probe of issue 55 (docs/bad_input.md, "The fifteenth probe") to ``key=value``
overrides: a value that is no YAML (an unclosed list or quote, a reserved character, a tab, a directive, an
undefined alias, an unknown tag) was an internal error (exit 1) on every command that takes overrides (Q1). Each
refusal: one line on stderr naming the override and what is wrong, exit code 2, nothing written."""

from __future__ import annotations

import pytest

from frontiernet.cli.main import main

EXPLORE = ["explore", "--scene", "procedural:3", "--max-steps", "2", "--no-video", "--method", "classic"]


@pytest.mark.parametrize("value, problem", [
    ("[1,", "while parsing a flow node: expected the node content, but found '<stream end>'"),
    ('"abc', "while scanning a quoted scalar: found unexpected end of stream"),
    ("@x", "found character '@' that cannot start any token"),
    ("\t0.3", "found character '\\t' that cannot start any token"),
    ("%YAML 1.2", "expected '<document start>', but found '<stream end>'"),
    ("*a", "found undefined alias 'a'"),
    ("!foo 0.3", "could not determine a constructor for the tag '!foo'"),
])
def test_an_override_value_that_is_no_yaml_is_named(value, problem, tmp_path, one_line_error):
    out = tmp_path / "ex"
    assert main([*EXPLORE, f"planner.clearance_m={value}", "--out", str(out)]) == 2
    line = one_line_error()
    assert "override 'planner.clearance_m=" in line and "its value is not valid YAML" in line and problem in line, line
    assert "internal error" not in line and not out.exists()


def test_the_same_holds_for_train_datagen_and_bench_overrides(tmp_path, one_line_error):
    for args in (["train", f"data.path={tmp_path}", "freeze=[layers.2"],
                 ["datagen", "--scenes", "procedural:3", "--views-per-scene", "1", "--out", str(tmp_path / "d"),
                  "--set", "writer.shard_size=!x 3"],
                 ["bench", "--scenes", "procedural:3", "--methods", "classic", "--max-steps", "4", "--out",
                  str(tmp_path / "b"), "--set", "planner.clearance_m=*a"]):
        assert main(args) == 2, args
        line = one_line_error()
        assert "its value is not valid YAML" in line, line
    assert not (tmp_path / "d").exists() and not (tmp_path / "b").exists()


def test_a_valid_yaml_value_still_reads_as_its_type():
    from frontiernet.exploration.run import load_run_config

    conf = load_run_config(overrides=["planner.clearance_m=0.3", "tracking.unknown_cap_yaw_offsets_deg=[-30, 0, 30]",
                                      "run.depth=gt"])
    assert conf.planner.clearance_m == 0.3 and list(conf.tracking.unknown_cap_yaw_offsets_deg) == [-30, 0, 30]


# ----------------------------------------------------------------------------- Q12: YAML 1.1's base-60 numbers

@pytest.mark.parametrize("override, message", [
    ("run.max_steps=1:00", "config key 'run.max_steps' takes a number (default 500), got '1:00'"),
    ("run.seed=1:00", "got '1:00'"),
    ("planner.clearance_m=1:30", "config key 'planner.clearance_m' takes a number (default 0.2), got '1:30'"),
    ("planner.clearance_m=1:30.5", "got '1:30.5'"),
])
def test_an_override_yaml_would_read_as_a_base_60_number_is_the_text_typed(override, message, tmp_path,
                                                                           one_line_error):
    out = tmp_path / "ex"
    args = [arg for arg in EXPLORE if arg not in ("--max-steps", "2")] if override.startswith("run.max_steps") else EXPLORE
    assert main([*args, override, "--out", str(out)]) == 2  # (1:00 ran 60 steps; 1:30 was "90 m" of clearance)
    line = one_line_error()
    assert message in line and "60" not in line.split("got")[-1].replace("1:00", ""), line
    assert not out.exists()


def test_a_config_file_with_a_base_60_number_names_its_line(tmp_path, one_line_error):
    config = tmp_path / "c.yaml"
    config.write_text("run:\n  seed: 4\n  max_steps: 1:00\n")
    out = tmp_path / "ex"
    assert main([*EXPLORE[:-2], "--method", "classic", "--config", str(config), "--out", str(out)]) == 2
    assert one_line_error().endswith(f"{config}: line 3: YAML reads 1:00 as the base-60 number 60; write 60 if that "
                                     "is meant, or quote '1:00' as text")
    assert not out.exists()
    config.write_text("run:\n  max_steps: 60\nmotion:\n  pitch_deg: -5.0\n")  # numbers as numbers still read
    from frontiernet.exploration.run import load_run_config

    assert load_run_config(config).run.max_steps == 60


def test_a_training_time_limit_is_the_text_typed():
    from train.config import check_max_time

    check_max_time("1:00:00:00")  # one day, as typed (YAML had made it 216000)
    with pytest.raises(Exception, match=r"got '1:00'"):
        check_max_time("1:00")


# ----------------------------------------------------------------------------- Q16: empty config files

@pytest.mark.parametrize("text, said", [("", "is an empty file (0 bytes)"),
                                        ("# only a comment\n\n", "holds no settings (blank lines and comments only)")])
def test_an_empty_or_comment_only_config_is_refused(text, said, tmp_path, one_line_error):
    config = tmp_path / "c.yaml"
    config.write_text(text)
    out = tmp_path / "o"
    assert main(["render", "procedural:3", "--pose", "3,3,1.2,0", "--config", str(config), "--out", str(out)]) == 2
    assert one_line_error().endswith(f"{config}: {said}; a config is a YAML mapping of settings (key: value lines)")
    assert not out.exists()


# ----------------------------------------------------------------------------- Q13: an option given twice

def test_a_single_option_given_twice_is_refused_and_a_list_option_takes_both(tmp_path, one_line_error):
    out = tmp_path / "ex"
    for args, message in ((["explore", "--scene", "procedural:3", "--scene", "procedural:4", "--max-steps", "2",
                            "--no-video", "--out", str(out)], "--scene given twice (procedural:3, then procedural:4)"),
                          (["export", "--format", "onnx", "--format", "torchscript", "--out", str(tmp_path / "m.pt")],
                           "--format given twice (onnx, then torchscript)")):
        with pytest.raises(SystemExit) as stop:  # (a usage error: argparse's exit)
            main(args)
        assert stop.value.code == 2 and one_line_error().endswith(f"{message}: give one")
    assert not out.exists()
    from frontiernet.cli.main import build_parser

    args = build_parser().parse_args(["bench", "--scenes", "procedural:3", "procedural:5", "--scenes", "procedural:4",
                                      "--out", str(tmp_path / "b")])
    assert args.scenes == ["procedural:3", "procedural:5", "procedural:4"]  # (was procedural:4 alone)
