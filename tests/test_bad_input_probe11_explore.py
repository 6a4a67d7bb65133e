"""Bad input of the eleventh probe of issue 55 (runs/probe11_report.md Q1, Q2, Q6 and the MapEx note): explore keys
each within its range whose product made one native scoring call that SIGTERM could not interrupt (minutes of a
run deaf to the signal), and candidate radii that overflowed the map's voxel indices. Each refusal is one line,
exit code 2, before the scene is built (a missing scene is given: the old code, which let the values through, named
that instead) and before any folder is made."""

from __future__ import annotations

import pytest
from test_bad_input_probe6 import refused  # exit 2, one line, no --out

from frontiernet.config_ranges import parse_relation
from frontiernet.errors import InputError
from frontiernet.exploration.run import load_run_config

MISSING = "/nonexistent-probe11/none.glb"
TC = ["sim.camera.width=64", "sim.camera.height=64", "sim.camera.focal_px=40"]


def explore_refuses(method: str, overrides: list[str], message: str, tmp_path, one_line_error) -> str:
    out = tmp_path / "out"
    return refused(["explore", "--scene", MISSING, "--max-steps", "6", "--no-video", "--method", method,
                    "--out", out, *overrides, *TC], message, one_line_error, out)


def accepted(*overrides: str) -> None:
    load_run_config(overrides=list(overrides))  # InputError if refused


def test_the_shipped_run_config_keeps_the_new_relations():
    accepted()
    accepted("seer.candidate_rnum=3", "seer.candidate_dphi_deg=15", "seer.view_width_px=64")  # SEER's ring, finer
    accepted("mapex.num_rays=250", "mapex.visibility_range_m=20")  # MapEx's own lidar


# ----------------------------------------------------------------------------- Q1: seer's ring of views

def test_seer_rings_of_more_rays_than_a_call_can_cast_in_seconds_are_refused(tmp_path, one_line_error):
    # b11: 101 radii x 360 views x 6 headings of 1024^2 rays in one numba call, SIGTERM unanswered for 13 minutes
    line = explore_refuses("seer", ["seer.candidate_rnum=100", "seer.candidate_dphi_deg=1", "seer.view_width_px=1024"],
                           "must hold (the rays seer casts scoring a cluster's ring of views", tmp_path, one_line_error)
    assert line.startswith("frontiernet explore: error: seer.candidate_rnum * 360 / seer.candidate_dphi_deg")
    for named in ("seer.candidate_rnum=100", "seer.candidate_dphi_deg=1", "seer.view_width_px=1024",
                  "len(seer.yaw_offsets_deg)"):
        assert named in line
    assert line.endswith(": 228,757,340,160 > 10,000,000")  # the rays asked for and the bound


@pytest.mark.parametrize("width, ok", [(131, True), (132, False)])
def test_the_seer_ray_bound_sits_where_it_says(width, ok):
    # 4 radii x 24 views x 6 headings x width^2 <= 1e7: 131 px casts 9,884,736 rays, 132 px 10,036,224
    if ok:
        accepted(f"seer.view_width_px={width}")
    else:
        with pytest.raises(InputError, match="10,036,224 > 10,000,000"):
            accepted(f"seer.view_width_px={width}")


def test_fewer_headings_leave_room_for_more_views():
    accepted("seer.yaw_offsets_deg=[0]", "seer.view_width_px=256")  # 4 x 24 x 1 x 65,536 = 6.3e6
    with pytest.raises(InputError, match="seer.yaw_offsets_deg="):
        accepted("seer.view_width_px=256")


# ----------------------------------------------------------------------------- Q2: omniscient's lattice of views

@pytest.mark.parametrize("overrides, computed", [
    (["omniscient.yaw_count=360", "omniscient.view_width_px=1024"], ": 770,382,367 > 100,000"),  # b25r
    (["omniscient.yaw_count=360", "omniscient.view_width_px=1024", "omniscient.candidate_spacing_m=0.05"],
     ": 150,994,944,000 > 100,000"),  # b25
])
def test_omniscient_views_of_more_rays_than_a_call_can_cast_in_seconds_are_refused(overrides, computed, tmp_path,
                                                                                   one_line_error):
    line = explore_refuses("omniscient", overrides, "must hold (rays a square metre of reachable floor", tmp_path,
                           one_line_error)
    assert line.startswith("frontiernet explore: error: omniscient.yaw_count * omniscient.view_width_px")
    assert "omniscient.candidate_spacing_m=" in line and line.endswith(computed)


def test_omniscient_keeps_finer_views_at_its_spacing():
    accepted("omniscient.view_width_px=64")  # 8 x 4096 / 0.49 = 66,873 rays a m^2
    accepted("omniscient.yaw_count=36", "omniscient.view_width_px=32", "omniscient.candidate_spacing_m=1.2")
    accepted("omniscient.max_candidates=100000")  # proposals kept, not views scored: not part of the bound
    with pytest.raises(InputError, match="omniscient.candidate_spacing_m=0.1: 204,800 > 100,000"):
        accepted("omniscient.candidate_spacing_m=0.1")  # a view every voxel


# ----------------------------------------------------------------------------- Q6: seer's candidate radii

@pytest.mark.parametrize("override, message", [
    ("seer.candidate_rmax_m=3e38", "seer.candidate_rmax_m must be a number in (0, 100], got 3e+38"),  # b18r
    ("seer.candidate_rmin_m=1e9", "seer.candidate_rmin_m must be a number in (0, 100], got 1000000000.0"),
    ("seer.candidate_rmax_m=100.5", "seer.candidate_rmax_m must be a number in (0, 100], got 100.5"),
])
def test_seer_candidate_radii_past_100_m_are_refused(override, message, tmp_path, one_line_error):
    # 3e38 m: 6 lines of numpy's "invalid value encountered in cast" (int64 voxel indices), then a run
    explore_refuses("seer", [override], message, tmp_path, one_line_error)


def test_seer_candidate_radii_up_to_100_m_are_taken():
    accepted("seer.candidate_rmin_m=1.2e-38", "seer.candidate_rmax_m=100")


# ----------------------------------------------------------------------------- MapEx: rays x range a frontier

def test_mapex_casts_past_a_second_and_200_mb_a_frontier_are_refused(tmp_path, one_line_error):
    # b5: both at their maxima, 1e7 ray cells: 5.4 s and 1.3 GB of NumPy temporaries a frontier, 6.5 s a step
    line = explore_refuses("mapex", ["mapex.num_rays=10000", "mapex.visibility_range_m=100"],
                           "mapex.num_rays * mapex.visibility_range_m / map.voxel_size <= 1000000 must hold (ray cells",
                           tmp_path, one_line_error)
    assert line.endswith("map.voxel_size=0.1: 10,000,000 > 1,000,000")


def test_mapex_ray_cells_follow_the_map_cell():
    accepted("mapex.num_rays=10000", "mapex.visibility_range_m=10")  # 1e6 at 0.1 m cells: the edge
    with pytest.raises(InputError, match="map.voxel_size=0.05: 2,000,000 > 1,000,000"):
        accepted("mapex.num_rays=10000", "mapex.visibility_range_m=10", "map.voxel_size=0.05")


# ----------------------------------------------------------------------------- the relation grammar's division

@pytest.mark.parametrize("values, holds", [
    ({"a": 3, "b": 15}, True), ({"a": 3, "b": 1}, False),
    ({"a": 3, "b": 0}, None),  # a zero divisor: the key's own range refuses it
])
def test_a_relation_divides_by_a_key(values, holds):
    relation = parse_relation("a * 360 / b <= 100", "why", "test")
    assert relation.holds(values) is holds
    assert relation.broken(values) == ("" if holds is not False else "1,080 > 100")
    assert relation.renamed({"a": "s.a", "b": "s.b"}).text() == "s.a * 360 / s.b <= 100"


def test_a_relation_of_keys_alone_shows_no_computed_numbers():
    assert parse_relation("a <= b", "why", "test").broken({"a": 2, "b": 1}) == ""
