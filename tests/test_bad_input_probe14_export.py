"""Probe 14: ``export`` with ``--out`` the model it exports (the file itself, or a link to it) and
``--force`` wrote the model over its own input (the shipped weights, 25 MB float16, became 50 MB float32);
refused now, the file kept byte for byte."""

from __future__ import annotations

import shutil

import pytest

from frontiernet.cli.main import main
from frontiernet.model import default_model_path


@pytest.mark.parametrize("as_link", [False, True])
def test_export_onto_the_model_it_reads_is_refused_and_the_model_kept(tmp_path, one_line_error, as_link):
    model = tmp_path / "model.safetensors"
    shutil.copyfile(default_model_path(), model)
    before = model.read_bytes()
    out = tmp_path / "same.safetensors"
    if as_link:
        out.symlink_to(model)
    else:
        out = model
    assert main(["export", str(model), "--format", "safetensors", "--out", str(out), "--force"]) == 2
    assert one_line_error().endswith(f"--out {out}: is the model being exported {model}, which this command reads; "
                                     "writing its results there would destroy it: choose another file")
    assert model.read_bytes() == before
