"""Scene-sized step budgets, the paper's protocol (issue 54): each scene's budget from its explorable
floor area, Vox@25 / @50 where the methods on average reach 25 / 50 % coverage, and benchmark
folders of the fixed-budget protocol kept apart."""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from conftest import TWO_ROOM
from frontiernet.benchmark.budget import BudgetRule, explorable_floor_m2
from frontiernet.benchmark.report import add_shared_vox, first_step_at
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.exploration.run import load_run_config
from test_benchmark import bench


def test_the_rule_scales_with_the_floor_area_within_the_papers_range():
    rule = BudgetRule.from_conf(load_config("bench").budget)
    assert (rule.min_steps, rule.max_steps) == (500, 3000)  # the paper's 500 to 3,000 steps a scene
    assert rule.steps(1.0) == 500 and rule.steps(1e6) == 3000
    middle = (rule.min_steps + rule.max_steps) / 2 / rule.steps_per_m2  # an area inside the range
    assert rule.steps(middle) % rule.round_to == 0 and rule.steps(2 * middle) > rule.steps(middle)
    with pytest.raises(InputError, match="budget.min_steps .* is above budget.max_steps"):
        BudgetRule.from_conf(OmegaConf.create({"steps_per_m2": 5, "min_steps": 900, "max_steps": 800, "round_to": 50}))
    with pytest.raises(InputError, match="budget.steps_per_m2"):
        BudgetRule.from_conf(OmegaConf.create({"steps_per_m2": -1, "min_steps": 5, "max_steps": 8, "round_to": 1}))


def test_the_floor_area_is_the_explorable_layer_at_camera_height(two_room_scene, two_room_voxels):
    area = explorable_floor_m2(two_room_scene, two_room_voxels, load_run_config())
    walls = (TWO_ROOM["partition_x"][1] - TWO_ROOM["partition_x"][0]) * 4.0  # the partition, above the door
    assert 6.0 * 4.0 - walls - 1.5 <= area <= 6.0 * 4.0  # the two rooms' floor, less what the voxels round off


def test_vox_at_25_and_50_are_taken_where_the_runs_reach_them_on_average():
    slow = np.concatenate([np.linspace(0.0, 0.6, 61), np.full(40, 0.6)])  # 25 % at step 25, 50 % at step 50
    fast = np.concatenate([np.linspace(0.0, 0.8, 21), np.full(80, 0.8)])  # 25 % at step 7, 50 % at step 13
    never = np.full(101, 0.1)  # never reaches either: counts its last step (100)
    assert (first_step_at(slow, 0.25), first_step_at(fast, 0.5), first_step_at(never, 0.25)) == (25, 13, 100)
    rows = [{"scene": "s", "start": 0, "repeat": 0, "method": m} for m in ("slow", "fast")]
    add_shared_vox(rows, {0: slow, 1: fast}, "coverage")
    assert rows[0]["vox25_shared"] == pytest.approx(slow[16]) and rows[1]["vox25_shared"] == pytest.approx(fast[16])
    assert rows[0]["vox50_shared"] == pytest.approx(slow[32])  # the mean of 50 and 13, rounded up
    add_shared_vox(rows, {0: slow, 1: fast}, "budget")  # the fixed-budget benchmarks: a quarter of the run
    assert rows[0]["vox25_shared"] == pytest.approx(slow[25])


@pytest.mark.slow
def test_bench_gives_each_scene_its_budget_and_keeps_the_protocols_apart(plan_spec, tmp_path):
    out = tmp_path / "scene_sized"
    args = ["--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "1"]
    code, stdout, stderr = bench(*args, "--out", out)
    assert code == 0, stderr
    plan = json.loads((out / "plan.json").read_text())
    rule = BudgetRule.from_conf(load_config("bench").budget)
    assert plan["settings"]["budget"] == rule.as_dict() and plan["settings"]["vox_steps"] == "coverage"
    assert plan["budgets"] == {plan_spec: 500}  # two small rooms: the paper's smallest budget
    [run] = plan["runs"]
    metrics = json.loads((out / "runs" / run["key"] / "metrics.json").read_text())
    assert run["max_steps"] == 500 and metrics["max_steps"] == 500
    # a fixed budget is another protocol: its runs are not mixed into this folder, and the other way round
    code, _, stderr = bench(*args, "--max-steps", "500", "--out", out)
    assert code == 2 and "another protocol (scene-sized budgets)" in stderr and "leave out --max-steps" in stderr
    fixed = tmp_path / "fixed"
    assert bench(*args, "--max-steps", "30", "--out", fixed)[0] == 0
    assert "max_steps" not in json.loads((fixed / "plan.json").read_text())["runs"][0]  # plans as before
    code, _, stderr = bench(*args, "--out", fixed)
    assert code == 2 and "a fixed budget of 30 steps a scene" in stderr and "--max-steps 30 resumes it" in stderr
