"""Bad input of the fifteenth probe of issue 55 (docs/bad_input.md, "The fifteenth probe") to the map predictors'
evaluation: ``mapeval --radius-m`` below one map cell scored no cell and printed a table of NaN, exit 0 (Q4). Each
refusal: one line on stderr naming the value, exit code 2, nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest

from frontiernet.cli.main import main
from test_bad_input_probe12_data import MAP_SCENES, MAPGEN_SET


@pytest.fixture(scope="module")
def map_data(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("maps") / "mg"
    assert main(["mapgen", "--scenes", *MAP_SCENES, "--no-progress", "--out", str(out), "--set", *MAPGEN_SET]) == 0
    return out


@pytest.mark.parametrize("kind, radius", [("seer", "1e-9"), ("mapex", "0.09")])
def test_a_radius_below_one_map_cell_is_refused(kind, radius, map_data, tmp_path, one_line_error):
    from frontiernet.mapprediction import shipped_predictor_path

    report = tmp_path / "scores.json"
    assert main(["mapeval", str(shipped_predictor_path(kind)), "--data", str(map_data), "--radius-m", radius,
                 "--json", str(report)]) == 2
    assert one_line_error().endswith(f"--radius-m {float(radius):g}: less than one map cell (0.1 m), so no unknown "
                                     "cell is that near a frontier; give at least 0.1")
    assert not report.exists()
