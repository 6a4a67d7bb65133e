"""What a change of settings does to a stored benchmark (frontiernet/benchmark/changes.py): a plan made
before a key existed resumes under the key's old value, and --redo-changed reruns only the runs a change
reaches (those of some depth sources, some methods, or those that collided)."""

from __future__ import annotations

import json

import pytest

from test_benchmark import OLD_ROBOT, bench


def test_a_change_only_monocular_runs_read_redoes_those_runs_and_keeps_the_others(plan_spec, tmp_path, caplog):
    """A map key of the monocular sensor model changes only the emulated-depth runs: resuming with it is
    refused unless --redo-changed, which discards those runs (packed or not) and runs them again under
    the new value, the ground-truth runs kept byte for byte; any other change stays refused."""
    from frontiernet.benchmark.store import read_pack, read_plan

    out = tmp_path / "bench"
    args = ["--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "1", "--max-steps", "4",
            "--depth", "gt,emulated", "--out", out]
    assert bench(*args)[0] == 0
    runs = {run["depth"]: run["key"] for run in read_plan(out)["runs"]}
    assert bench("--pack", "--out", out)[0] == 0
    packs = {depth: out / "runs" / (key.rsplit("/", 1)[0] + ".jsonl.gz") for depth, key in runs.items()}
    before = {depth: path.read_bytes() for depth, path in packs.items()}
    change = ["--set", "map.monocular_log_odds_miss=-1.2"]
    code, _, stderr = bench(*args, *change)
    assert code == 2 and "conf.map.monocular_log_odds_miss: -0.85 in the plan, -1.2 now" in stderr
    assert "only its emulated-depth runs read: --redo-changed" in stderr
    code, _, stderr = bench(*args, *change, "--redo-changed")
    assert code == 0 and "1 finished runs of them discarded" in caplog.text and "bench 1/1" in stderr
    assert packs["ground_truth"].read_bytes() == before["ground_truth"]
    assert not packs["emulated"].exists() or runs["emulated"] not in read_pack(packs["emulated"])
    redone = out / "runs" / runs["emulated"]
    assert "monocular_log_odds_miss: -1.2" in (redone / "config.yaml").read_text()
    assert read_plan(out)["settings"]["conf"]["map"]["monocular_log_odds_miss"] == -1.2
    code, _, stderr = bench(*args, *change)  # the plan has the new value: a plain resume, nothing to run
    assert code == 0 and "bench 1/" not in stderr
    code, _, stderr = bench(*args, *change, "planner.clearance_m=0.35", "--redo-changed")
    assert code == 2 and "conf.planner.clearance_m: 0.2 in the plan, 0.35 now" in stderr and "--redo-changed" not in stderr


def test_redo_changed_on_a_folder_without_a_benchmark_says_it_starts_one(plan_spec, tmp_path):
    # eighth probe (E15): a new benchmark began without a word (datagen --resume says so of an empty folder)
    out = tmp_path / "new"
    code, stdout, stderr = bench("--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "1",
                                 "--max-steps", "4", "--out", out, "--redo-changed")
    assert code == 0, stderr
    assert stdout.splitlines()[0] == (f"bench: note: --redo-changed: {out} holds no benchmark yet (no plan.json), so "
                                      "there is nothing to redo; starting a new one")


def test_monocular_keys_change_only_monocular_runs_and_a_methods_section_only_its_runs():
    """What --redo-changed may redo: a ``monocular_*`` key of the map or the planner (read only with a
    depth source that has flying pixels) changes a gt,emulated plan's emulated runs only;
    ``planner.traversed_is_free`` its ground-truth runs only while ``monocular_traversed_is_free`` holds;
    a method's own section (``nbvp``) its runs only; any other key, its every run."""
    from omegaconf import OmegaConf

    from frontiernet.benchmark.changes import runs_changed
    from frontiernet.exploration.run import load_run_config

    stored = {"depth": "gt,emulated", "conf": OmegaConf.to_container(load_run_config(), resolve=True)}
    runs = [{"key": f"{method}@{depth}", "method": method, "depth": depth}
            for method in ("classic", "nbvp") for depth in ("ground_truth", "emulated")]
    plan = {"settings": stored, "runs": runs}

    def changed(key: str, value, plan=plan) -> list | None:
        conf = OmegaConf.create(plan["settings"]["conf"])
        OmegaConf.update(conf, key, value)
        found = runs_changed(plan, {**plan["settings"], "conf": OmegaConf.to_container(conf)})
        return None if found is None else found[0]

    flipped = not stored["conf"]["planner"]["monocular_traversed_is_free"]
    assert changed("planner.monocular_traversed_is_free", flipped) == ["classic@emulated", "nbvp@emulated"]
    assert changed("map.monocular_log_odds_miss", -1.2) == ["classic@emulated", "nbvp@emulated"]
    assert changed("nbvp.degressive_coeff", 0.25) == ["nbvp@ground_truth", "nbvp@emulated"]
    assert changed("omniscient.yaw_count", 4) == []  # a method the plan does not run
    # the way back kept open: monocular sources keep it whatever traversed_is_free says, while
    # monocular_traversed_is_free holds; without that, every run reads it
    flipped_all = not stored["conf"]["planner"]["traversed_is_free"]
    assert stored["conf"]["planner"]["monocular_traversed_is_free"]
    assert changed("planner.traversed_is_free", flipped_all) == ["classic@ground_truth", "nbvp@ground_truth"]
    without = OmegaConf.create(stored["conf"])
    OmegaConf.update(without, "planner.monocular_traversed_is_free", False)
    no_monocular = {"settings": {**stored, "conf": OmegaConf.to_container(without)}, "runs": runs}
    assert changed("planner.traversed_is_free", flipped_all, no_monocular) is None
    assert changed("planner.clearance_m", 0.35) is None
    gt_only = {"settings": {**stored, "depth": "gt"}, "runs": [{"key": "nbvp", "method": "nbvp"}]}
    assert changed("map.monocular_log_odds_miss", -1.2, gt_only) == []
    assert changed("nbvp.extension_m", 0.5, gt_only) == ["nbvp"]


def test_a_plan_made_before_a_key_existed_resumes_while_the_key_keeps_the_old_behaviour(tmp_path):
    """docs/benchmark/published was planned before planner.approach_radius_m existed (its default,
    0, is the code of then: KEYS_ADDED_AFTER_PLANS): its protocol command resumes with today's code;
    setting the key, or a plan that lacks a key not listed there, is a change of settings."""
    from omegaconf import OmegaConf

    from conftest import REPO_ROOT
    from frontiernet.benchmark.main import resumable_plan
    from frontiernet.benchmark.store import read_plan
    from frontiernet.errors import InputError
    from frontiernet.exploration.run import load_run_config

    published = REPO_ROOT / "docs" / "benchmark" / "published"
    stored = read_plan(published)  # packed (plan.json.gz)
    assert "approach_radius_m" not in stored["settings"]["conf"]["planner"]

    def protocol(*overrides) -> dict:  # the settings `frontiernet bench` makes of resume.sh's command
        # (docs/benchmark/published/resume.sh adds --set planner.gain_exponent=1: the plan ran with 1,
        # the default since 2026-11-27 is 2)
        overrides = ("planner.gain_exponent=1", "planner.forgive_before_stop=false", "planner.approach_radius_m=0",
                     "planner.traversed_is_free=false", "planner.bumps_are_obstacles=false",
                     "map_frontiers.min_cells_before_stop=null", "tracking.bury_visited=false", *OLD_ROBOT, *overrides)
        return {"budget": 500, "seed": 0, "model": "runs/shipped.onnx", "depth": None, "scene_starts": True,
                "conf": OmegaConf.to_container(load_run_config(None, list(overrides)), resolve=True)}

    assert resumable_plan(published, protocol())["start_poses"] == stored["start_poses"]
    # today's default exponent is a change of settings for this plan: refused, naming the key
    with pytest.raises(InputError, match=r"\(conf.planner.gain_exponent: 1.0 in the plan, 2.0 now\)"):
        resumable_plan(published, {**protocol(), "conf": OmegaConf.to_container(load_run_config(
            None, ["planner.forgive_before_stop=false", "planner.approach_radius_m=0", "planner.traversed_is_free=false",
                   "planner.bumps_are_obstacles=false", "map_frontiers.min_cells_before_stop=null",
                   "tracking.bury_visited=false", *OLD_ROBOT]),
            resolve=True)})
    assert "--set planner.forgive_before_stop=false planner.approach_radius_m=0 \\\n    planner.traversed_is_free=false " \
        "planner.bumps_are_obstacles=false \\\n    map_frontiers.min_cells_before_stop=null tracking.bury_visited=false " + \
        " ".join(OLD_ROBOT) + " $SETTINGS" in \
        (published / "resume.sh").read_text()
    assert "SETTINGS=${SETTINGS-planner.gain_exponent=1}" in (published / "resume.sh").read_text()
    with pytest.raises(InputError, match=r"\(conf.planner.approach_radius_m: 0.0 in the plan, 1.5 now\)"):
        resumable_plan(published, protocol("planner.approach_radius_m=1.5"))
    with pytest.raises(InputError, match=r"\(conf.planner.clearance_m: 0.3 in the plan, 0.35 now\)"):
        resumable_plan(published, protocol("planner.clearance_m=0.35"))
    # a plan made after runs had a sim section but before the explorable-space rule (sim.voxels.explorable
    # and its four settings) ran the enclosed rule: it resumes when the run asks for that rule
    between = json.loads(json.dumps(stored))
    between["settings"]["conf"]["sim"] = protocol()["conf"]["sim"]
    for key in ("explorable", "wall_gap_m", "floor_headroom_m", "floor_clearance_m", "seed_search_m"):
        del between["settings"]["conf"]["sim"]["voxels"][key]
    (tmp_path / "plan.json").write_text(json.dumps(between))
    assert resumable_plan(tmp_path, protocol("sim.voxels.explorable=enclosed"))["start_poses"] == stored["start_poses"]
    with pytest.raises(InputError, match=r"\(conf.sim.voxels.explorable: 'enclosed' in the plan, 'reachable' now\)"):
        resumable_plan(tmp_path, protocol())
    # the published plan (ground truth only) predates map.depth_edge_rtol, which changes no ground-truth
    # run: it resumes with any value; the same plan on emulated depth would run differently: refused
    assert "depth_edge_rtol" not in stored["settings"]["conf"]["map"]
    assert resumable_plan(published, protocol("map.depth_edge_rtol=0.2"))["start_poses"] == stored["start_poses"]
    emulated = json.loads(json.dumps(stored))
    emulated["settings"]["depth"] = "emulated"
    (tmp_path / "plan.json").write_text(json.dumps(emulated))
    with pytest.raises(InputError, match=r"\(conf.map.depth_edge_rtol: absent in the plan, 0.1 now\)"):
        resumable_plan(tmp_path, {**protocol(), "depth": "emulated"})
    # planner.obstacle_memory_frames (10 since 2026-11-27; before the key map-free mode had none)
    # changes no map-mode run: the published plan resumes with any value; the same plan in map-free
    # mode ran without the memory, so it resumes only with 0
    assert "obstacle_memory_frames" not in stored["settings"]["conf"]["planner"]
    assert resumable_plan(published, protocol("planner.obstacle_memory_frames=3"))["start_poses"] == stored["start_poses"]
    map_free = json.loads(json.dumps(stored))
    map_free["settings"]["conf"]["planner"]["mode"] = "map_free"
    (tmp_path / "plan.json").write_text(json.dumps(map_free))
    with pytest.raises(InputError, match=r"\(conf.planner.obstacle_memory_frames: 0 in the plan, 10 now\)"):
        resumable_plan(tmp_path, protocol("planner.mode=map_free"))
    assert resumable_plan(tmp_path, protocol("planner.mode=map_free", "planner.obstacle_memory_frames=0"))
    del stored["settings"]["conf"]["planner"]["clearance_m"]
    (tmp_path / "plan.json").write_text(json.dumps(stored))
    with pytest.raises(InputError, match=r"\(conf.planner.clearance_m: absent in the plan, 0.3 now\)"):
        resumable_plan(tmp_path, protocol())


def test_the_two_regime_plan_resumes_as_the_record_it_is():
    """docs/benchmark/regimes ran the published protocol in both depth regimes under the defaults of
    its time: a default that changes what its runs do refuses it (the storey rule of 2026-12-06
    changes procedural_1005's), and its resume.sh sets the rule it was made under, as the exponent-1
    record's sets its exponent; both resume only so."""
    from omegaconf import OmegaConf

    from conftest import REPO_ROOT
    from frontiernet.benchmark.main import resumable_plan
    from frontiernet.errors import InputError
    from frontiernet.exploration.run import load_run_config

    def protocol(*overrides) -> dict:  # the settings `frontiernet bench` makes of resume.sh's command
        overrides = ("planner.forgive_before_stop=false", "planner.approach_radius_m=0", "planner.traversed_is_free=false",
                     "planner.bumps_are_obstacles=false", "map_frontiers.min_cells_before_stop=null",
                     "tracking.bury_visited=false", *OLD_ROBOT, *overrides)  # published/resume.sh sets these for all
        return {"budget": 500, "seed": 0, "model": "runs/shipped.onnx", "depth": "gt,emulated", "scene_starts": True,
                "conf": OmegaConf.to_container(load_run_config(None, list(overrides)), resolve=True)}

    folders = REPO_ROOT / "docs" / "benchmark"
    regimes, record = folders / "regimes", folders / "regimes_exponent1"
    # the rules they were made under: one storey's keys null (issue 55), and the monocular map's (issue 54:
    # the symmetric miss, oblique pixels and the way back kept open, default since 2026-12-06, change their
    # emulated-depth runs)
    one_rule = ("sim.voxels.storey_floor_share=null", "sim.voxels.storey_slab_share=null",
                "map.monocular_log_odds_miss=null", "map.monocular_max_incidence_deg=null",
                "planner.monocular_traversed_is_free=false")
    with pytest.raises(InputError, match=r"\(conf.sim.voxels.storey_floor_share: null in the plan, 0.5 now\)"):
        resumable_plan(regimes, protocol())
    assert resumable_plan(regimes, protocol(*one_rule))["start_poses"] == resumable_plan(
        record, protocol("planner.gain_exponent=1.0", *one_rule))["start_poses"]  # the same starts: they pair
    with pytest.raises(InputError, match=r"\(conf.planner.gain_exponent: 1.0 in the plan, 2.0 now\)"):
        resumable_plan(record, protocol(*one_rule))
    assert f'SETTINGS="{" ".join(one_rule)}"' in (regimes / "resume.sh").read_text()
    assert 'SETTINGS="planner.gain_exponent=1 map.monocular_log_odds_miss=null map.monocular_max_incidence_deg=null ' \
        'planner.monocular_traversed_is_free=false"' in (record / "resume.sh").read_text()


def test_a_setting_that_acts_only_on_a_collision_redoes_only_the_runs_that_collided():
    # planner.bumps_are_obstacles (issue 54): a run without a collision is the same to the step either way
    from frontiernet.benchmark.changes import runs_changed

    runs = [{"key": f"s/{method}/start0_repeat0", "method": method} for method in ("classic", "nbvp", "oracle")]
    conf = {"planner": {"bumps_are_obstacles": False}}
    plan = {"settings": {"depth": "gt", "conf": conf}, "runs": runs}
    finished = {"s/classic/start0_repeat0": {"collisions": 36}, "s/nbvp/start0_repeat0": {"collisions": 0}}
    records = type("Finished", (), {"metrics": staticmethod(finished.get)})()
    settings = {"depth": "gt", "conf": {"planner": {"bumps_are_obstacles": True}}}
    keys, readers = runs_changed(plan, settings, records)
    assert keys == ["s/classic/start0_repeat0"] and [str(reader) for reader in readers] == ["collided runs"]
    assert runs_changed(plan, settings)[0] == [run["key"] for run in runs]  # without the records: every run


def test_small_frontiers_before_a_stop_redo_only_the_map_methods_runs_that_stopped():
    # map_frontiers.min_cells_before_stop (issue 54) acts only where a map-frontier method would stop with no frontier
    # left: every other run is the same to the step either way
    from frontiernet.benchmark.changes import runs_changed

    stops = {"classic": "no frontiers left", "random-frontier": "step budget spent", "frontiernet": "no frontiers left"}
    runs = [{"key": f"s/{method}/start0_repeat0", "method": method} for method in stops]
    plan = {"settings": {"depth": "gt", "conf": {"map_frontiers": {"min_cells_before_stop": None}}}, "runs": runs}
    finished = {f"s/{method}/start0_repeat0": {"stop_reason": reason} for method, reason in stops.items()}
    records = type("Finished", (), {"metrics": staticmethod(finished.get)})()
    settings = {"depth": "gt", "conf": {"map_frontiers": {"min_cells_before_stop": 1}}}
    keys, (reader,) = runs_changed(plan, settings, records)
    assert keys == ["s/classic/start0_repeat0"] and str(reader).endswith("runs that stopped with no frontier left")
    assert runs_changed(plan, settings)[0] == ["s/classic/start0_repeat0", "s/random-frontier/start0_repeat0"]


def test_burying_visited_frontiers_redoes_only_the_runs_of_methods_of_map_frontier_regions():
    # tracking.bury_visited (issue 54) acts only where the frontiers are regions of the map's frontier cells: the
    # image methods' and the view methods' runs are the same to the step either way
    from frontiernet.benchmark.changes import runs_changed

    methods = ("classic", "random-frontier", "nbvp", "omniscient", "seer", "mapex", "frontiernet", "oracle",
               "frontiernet-mapex")
    runs = [{"key": f"s/{method}/start0_repeat0", "method": method} for method in methods]
    plan = {"settings": {"depth": "gt", "conf": {"tracking": {"bury_visited": False}}}, "runs": runs}
    keys, (reader,) = runs_changed(plan, {"depth": "gt", "conf": {"tracking": {"bury_visited": True}}})
    assert keys == [f"s/{method}/start0_repeat0" for method in ("classic", "random-frontier", "mapex")]
