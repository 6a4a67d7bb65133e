"""Where the steps go (frontiernet/exploration/steps.py): every step of a run in one category, the
budget left unused split by whether the stop was premature, the account in metrics.json, and the
report's section per method (frontiernet/benchmark/steps_report.py)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from frontiernet.benchmark.report import table_markdown, write_report
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.exploration.explorer import StepRecord
from frontiernet.exploration.steps import (CATEGORIES, AccountSettings, classify, counted_steps, dilated_columns,
                                           run_account, step_account)

CONF = load_config("explore")
SETTINGS = AccountSettings.from_config(CONF.steps)
EXPLORABLE_M3 = 100.0
TURN = np.radians(11.0)  # one turn increment (motion.rotation_deg)
MOVE = 0.11  # one move increment (motion.translation_m)
GAIN = 10 * SETTINGS.new_volume_m3 / EXPLORABLE_M3  # coverage a step that sees new volume adds


class Walk:
    """Builds a synthetic record list: each call appends records of one counted step each."""

    def __init__(self, frontiers: int = 3) -> None:
        self.records = [self._record(0, (0.25, 0.25), 0.0, 0.1, None, frontiers)]

    @staticmethod
    def _record(step, xy, yaw, coverage, goal, frontiers) -> StepRecord:
        return StepRecord(step, step, [float(xy[0]), float(xy[1]), 1.2], float(yaw), float(coverage), 0.0, 0.0,
                          frontiers, goal, False, {})

    @property
    def last(self) -> StepRecord:
        return self.records[-1]

    def turn(self, count: int, goal=None, frontiers: int = 3) -> Walk:
        for _ in range(count):
            self.records.append(self._record(self.last.step + 1, self.last.position, self.last.yaw + TURN,
                                             self.last.coverage, goal, frontiers))
        return self

    def move(self, count: int, direction=(1.0, 0.0), gain: float = 0.0, goal=7, frontiers: int = 3) -> Walk:
        for _ in range(count):
            xy = np.asarray(self.last.position[:2]) + MOVE * np.asarray(direction)
            self.records.append(self._record(self.last.step + 1, xy, self.last.yaw, self.last.coverage + gain,
                                             goal, frontiers))
        return self


def names(path: Walk, start_turn_deg: float = 0.0) -> list[str]:
    steps = counted_steps(path.records, EXPLORABLE_M3)
    return classify(steps, np.asarray(path.records[0].position[:2]), start_turn_deg, SETTINGS).tolist()


# -- one category at a time ----------------------------------------------------------------------


def test_the_start_turn_is_the_leading_turn_on_the_spot_up_to_start_turn_deg():
    path = Walk().turn(34)  # 374 degrees: the last two steps turn beyond the start turn
    assert names(path, 360.0) == ["start_turn"] * 32 + ["look_around"] * 2
    assert names(path, 0.0) == ["look_around"] * 34  # no start turn configured
    # a turn with a goal ends it
    assert names(Walk().turn(3).turn(2, goal=4), 360.0) == ["start_turn"] * 3 + ["turn"] * 2


def test_turns_on_the_spot_are_look_arounds_without_a_goal_and_turns_with_one():
    assert names(Walk().turn(3).turn(4, goal=2)) == ["look_around"] * 3 + ["turn"] * 4


def test_translations_see_new_volume_none_or_revisit_cells_left_before():
    path = Walk().move(4, gain=GAIN).move(20)  # 2.6 m east: new volume, then nothing new
    path.move(20, direction=(-1.0, 0.0))  # back west over the cells it crossed
    labels = names(path)
    assert labels[:4] == ["move_new"] * 4 and labels[4:24] == ["move_none"] * 20
    back = labels[24:]
    # the first steps back are in cells it left fewer than revisit_after_steps steps before
    assert set(back[:5]) == {"move_none"} and back[-10:] == ["revisit"] * 10
    assert "revisit" not in labels[:24]


def test_wavering_along_a_cell_border_is_no_revisit():
    path = Walk()
    path.records[0].position[:2] = [0.48, 0.25]
    for index in range(12):  # zig-zags across x = 0.5 m while going north
        path.move(1, direction=(0.4 if index % 2 == 0 else -0.4, 0.9))
    assert names(path) == ["move_none"] * 12


def test_a_window_without_gain_in_a_small_area_with_frontiers_listed_is_a_livelock():
    width, big = SETTINGS.livelock_window_steps, 2 * SETTINGS.livelock_gain_m3 / EXPLORABLE_M3
    path = Walk().move(5, gain=big)
    for _ in range(4):  # back and forth over 1.1 m for 120 steps, turning round each time
        path.move(10).turn(5, goal=3).move(10, direction=(-1.0, 0.0)).turn(5, goal=3)
    path.move(5, gain=big)
    labels = names(path)
    assert labels[:5] == ["move_new"] * 5 and labels[-5:] == ["move_new"] * 5
    assert labels[5:-5] == ["livelock"] * 120 and 120 >= width
    # the same with no frontier listed is not one: the robot had nowhere to go
    quiet = Walk(frontiers=0).move(5, gain=big, frontiers=0)
    for _ in range(4):
        quiet.move(10, frontiers=0).turn(5, goal=3, frontiers=0).move(10, (-1.0, 0.0), frontiers=0)
        quiet.turn(5, goal=3, frontiers=0)
    assert "livelock" not in names(quiet) and "revisit" in names(quiet)
    # turning on the spot for a whole window with frontiers listed is one too
    spin = names(Walk().move(3, gain=big).turn(width + 10, goal=3))
    assert spin == ["move_new"] * 3 + ["livelock"] * (width + 10)


def test_a_transit_without_gain_is_no_livelock_however_bent():
    width = SETTINGS.livelock_window_steps
    assert set(names(Walk().move(width + 10))) == {"move_none"}
    bent = Walk()
    for direction in ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)):  # three legs round a corner and back, turning
        bent.move(12, direction=direction).turn(8, goal=3)
    assert len(bent.records) - 1 >= width and set(names(bent)) == {"move_none", "turn"}


def test_records_that_did_not_count_as_steps_are_folded_into_the_next_step():
    path = Walk().move(2, gain=GAIN)
    extra = Walk._record(2, path.last.position, path.last.yaw + 0.05, path.last.coverage + GAIN, 7, 3)
    path.records.append(extra)  # a small turn that did not count: same step
    path.move(1)  # counted: moved since step 2, and the uncounted record's gain is its own
    steps = counted_steps(path.records, EXPLORABLE_M3)
    assert len(steps) == 3 and steps.moved_m[-1] == pytest.approx(MOVE)
    assert steps.gain_m3[-1] == pytest.approx(GAIN * EXPLORABLE_M3)


# -- the whole account -----------------------------------------------------------------------------


def test_the_account_sums_to_the_budget_and_splits_the_unused_steps_by_the_premature_flag():
    path = Walk().turn(32).move(10, gain=GAIN).turn(3, goal=1).move(5)
    budget = 80
    done = step_account(path.records, budget, EXPLORABLE_M3, 352.0, SETTINGS, premature=False)
    assert list(done) == list(CATEGORIES) and sum(done.values()) == budget
    assert done["start_turn"] == 32 and done["move_new"] == 10 and done["turn"] == 3 and done["move_none"] == 5
    assert done["unused_done"] == budget - 50 and done["unused_premature"] == 0
    early = run_account(path.records, budget, "no frontiers left", EXPLORABLE_M3, 0.25, CONF)
    assert early["premature_stop"] and early["unseen_reachable"] == 0.25
    assert early["step_account"]["unused_premature"] == budget - 50 and early["step_account"]["unused_done"] == 0
    seen = run_account(path.records, budget, "no frontiers left", EXPLORABLE_M3, SETTINGS.premature_unseen, CONF)
    spent = run_account(path.records, budget, "iteration limit", EXPLORABLE_M3, 0.5, CONF)
    for account in (seen, spent):  # at the threshold, or another stop reason: not premature
        assert not account["premature_stop"] and account["step_account"]["unused_done"] == budget - 50


def test_an_empty_run_leaves_the_whole_budget_unused():
    account = step_account(Walk().records, 10, EXPLORABLE_M3, 360.0, SETTINGS, premature=False)
    assert account["unused_done"] == 10 and sum(account.values()) == 10


def test_bad_settings_fail_with_the_key_named():
    with pytest.raises(InputError, match="steps.livelock_window_steps"):
        AccountSettings.from_config({**CONF.steps, "livelock_window_steps": 0})


def test_reachable_columns_grow_by_a_disk():
    columns = np.zeros((9, 9), bool)
    columns[4, 4] = True
    grown = dilated_columns(columns, 0.1, 0.2)
    assert grown.sum() == 13 and grown[4, 2] and not grown[2, 2]  # radius 2 cells
    assert dilated_columns(columns, 0.1, 0.0).sum() == 1


# -- a real run ---------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("scene, budget", [("two rooms", 40), ("closet", 80)])
def test_a_runs_metrics_hold_its_account(plan_spec, closet_spec, tmp_path, scene, budget):
    """The oracle spends its budget in the two rooms (the start turn first) and stops in the closed
    room with nothing left to see: its unused steps are done, not premature."""
    from frontiernet.cli.main import main

    out = tmp_path / "run"
    assert main(["explore", "--scene", plan_spec if scene == "two rooms" else closet_spec, "--method", "oracle",
                 "--max-steps", str(budget), "--out", str(out), "--no-video"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    account = metrics["step_account"]
    assert list(account) == list(CATEGORIES) and sum(account.values()) == budget
    assert sum(account[name] for name in CATEGORIES[:-2]) == metrics["steps"]
    assert account["start_turn"] == 32  # 360 degrees in 11 degree steps: the 33rd's 8 degrees count later
    assert 0.0 <= metrics["unseen_reachable"] <= 1.0 - metrics["coverage"] + 1e-5
    if scene == "two rooms":
        assert metrics["stop_reason"] == "step budget spent" and not metrics["premature_stop"]
        assert account["unused_done"] == account["unused_premature"] == 0
    else:
        assert metrics["stop_reason"] == "no frontiers left" and not metrics["premature_stop"]
        assert metrics["unseen_reachable"] < 0.1 and account["unused_done"] == budget - metrics["steps"] > 0


# -- the report -------------------------------------------------------------------------------------


def _account(**steps) -> dict:
    return {name: steps.get(name, 0) for name in CATEGORIES}


def test_the_report_says_where_the_steps_go_and_counts_runs_without_an_account(tmp_path):
    interval = load_config("bench").report.interval
    records = {  # classic: one premature stop, one run from an older pack without an account
        "classic/start0_repeat0": {"step_account": _account(start_turn=10, move_new=50, unused_premature=40),
                                   "unseen_reachable": 0.3, "premature_stop": True},
        "classic/start1_repeat0": {"step_account": _account(start_turn=10, move_new=70, livelock=20),
                                   "unseen_reachable": 0.1, "premature_stop": False},
        "classic/start2_repeat0": {},
        "ours/start0_repeat0": {"step_account": _account(start_turn=10, revisit=90), "unseen_reachable": 0.2,
                                "premature_stop": False},
    }
    rows = []
    for key, extra in records.items():
        (tmp_path / "runs" / key).mkdir(parents=True)
        record = {"coverage_per_step": [0.0, 0.1, 0.2], **extra}
        (tmp_path / "runs" / key / "metrics.json").write_text(json.dumps(record))
        method, run = key.split("/")
        rows.append({"scene": "procedural:1", "method": method, "start": int(run[5]), "repeat": 0, "key": key,
                     "status": "done", "max_steps": 100, "vox100": 0.2, "success": False})
    write_report(tmp_path, rows, ["procedural:1"], ["classic", "ours"], interval=interval)
    table = (tmp_path / "table.md").read_text()
    section = next(b for b in table.split("### ") if b.startswith("Where the steps go"))
    # classic: start turn 10 %, move new (50 + 70) / 2 = 60 %, livelock 10 %, unused premature 20 %
    assert "| classic | 3 | 1 | 10.0 | 0.0 | 0.0 | 60.0 | 0.0 | 0.0 | 10.0 | 20.0 | 0.0 | 1 | 20.0 |" in section
    assert "| ours | 1 | 0 | 10.0 | 0.0 | 0.0 | 0.0 | 0.0 | 90.0 | 0.0 | 0.0 | 0.0 | 0 | 20.0 |" in section
    assert table.index("Where the steps go") < table.index("### Vox@25 (%)")
    written = list(csv.DictReader(open(tmp_path / "results.csv")))
    assert [row["steps_move_new"] for row in written] == ["50", "70", "", "0"]
    assert [row["premature_stop"] for row in written] == ["True", "False", "", "False"]
    # a report of records without any account reads as before: no section, no columns
    old = [dict(row) for row in rows if row["key"] == "classic/start2_repeat0"]
    write_report(tmp_path, old, ["procedural:1"], ["classic"], interval=interval)
    assert "Where the steps go" not in (tmp_path / "table.md").read_text()
    assert "steps_move_new" not in (tmp_path / "results.csv").read_text()


def test_a_method_whose_runs_all_lack_an_account_gets_dashes():
    interval = load_config("bench").report.interval
    with_account = {"steps_" + name: 0 for name in CATEGORIES}
    rows = [{"scene": "procedural:1", "method": "ours", "start": 0, "repeat": 0, "status": "done", "vox25_shared": 0.1,
             "vox50_shared": 0.2, "vox100": 0.3, "success": False, **with_account, "steps_move_new": 5,
             "premature_stop": False, "unseen_reachable": 0.5},
            {"scene": "procedural:1", "method": "old", "start": 0, "repeat": 0, "status": "done", "vox25_shared": 0.1,
             "vox50_shared": 0.2, "vox100": 0.3, "success": False}]
    table = table_markdown(rows, ["procedural:1"], ["ours", "old"], interval=interval)
    assert "| old | 1 | 1 | " + " | ".join(["--"] * (len(CATEGORIES) + 2)) + " |" in table
    assert "| ours | 1 | 0 | 0.0 | 0.0 | 0.0 | 100.0 |" in table


def test_unseen_reachable_counts_the_columns_the_camera_never_saw_at_its_height():
    from types import SimpleNamespace

    from frontiernet.exploration.score import GroundTruthScore

    explorable = np.ones((4, 1, 6), bool)  # four columns of six layers; the camera band is layers 2 and 3
    observed = np.zeros_like(explorable)
    observed[0, 0, 2:4] = True  # column 0: seen at the camera's height, not its floor and ceiling
    observed[1, 0, 0] = True  # column 1: its floor seen from afar, never at the camera's height
    score = GroundTruthScore.__new__(GroundTruthScore)
    score.voxels = SimpleNamespace(explorable=explorable, num_explorable=explorable.sum())
    score.coverage_map = SimpleNamespace(observed=observed)
    columns = np.array([[True], [True], [True], [False]])  # column 3 is not reachable
    # column 1: 5 unseen voxels, column 2: 6; column 0's 4 unseen are looked over, column 3's not reachable
    assert score.unseen_in(columns, slice(2, 4)) == pytest.approx(11 / 24)


def test_benchmarks_planned_before_the_account_read_its_settings_as_shipped():
    """The account changes no run: a plan made before the ``steps`` section resumes with it."""
    from omegaconf import OmegaConf

    from frontiernet.benchmark.changes import KEYS_ADDED_AFTER_PLANS

    assert KEYS_ADDED_AFTER_PLANS["steps"] == OmegaConf.to_container(CONF.steps)


def test_coverage_kept_frame_by_frame_equals_a_count_over_the_whole_map(two_room_scene, two_room_voxels):
    from frontiernet.exploration.score import GroundTruthScore
    from frontiernet.geometry import pose_from_heading
    from frontiernet.simulator.camera import PinholeCamera, Renderer

    camera = PinholeCamera(64, 48, 40.0, 40.0, 31.5, 23.5, 3.5)
    renderer = Renderer(two_room_scene, camera, (0, 0, 0))
    score = GroundTruthScore(two_room_scene, two_room_voxels, CONF)
    explorable = two_room_voxels.explorable
    seen = []
    for x, yaw in [(1.0, 0), (1.0, 90), (2.0, 200), (4.5, 0), (4.5, 135), (1.0, 0)]:  # the last one again
        T = pose_from_heading(x, 2.0, 1.2, yaw=np.deg2rad(yaw), pitch=-0.3)
        frame = renderer.render(T)
        score.observe(frame.depth, frame.K, T)
        whole = np.count_nonzero(score.coverage_map.observed & explorable) / explorable.sum()
        assert score.coverage() == pytest.approx(whole, abs=1e-12)
        seen.append(score.coverage())
    assert 0 < seen[0] < seen[-2] == seen[-1]  # both rooms add; the first view again adds nothing
