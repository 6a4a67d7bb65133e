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
