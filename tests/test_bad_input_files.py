"""Files of the wrong kind given to commands (issue 55's probes, docs/bad_input.md): a folder for a file and a
file for a folder, a file of another format under a suffix, an array that is no depth map; each one line
naming the file and what it is, exit code 2, nothing written."""

from __future__ import annotations

import numpy as np
import pytest

from frontiernet.cli.main import main


@pytest.fixture
def files(tmp_path):
    """A folder, an image, a float depth map, a PNG renamed .npy, an empty .glb, a (fake) ONNX file."""
    import cv2

    (tmp_path / "adir").mkdir()
    cv2.imwrite(str(tmp_path / "rgb.png"), np.full((48, 64, 3), 128, np.uint8))
    np.save(tmp_path / "depth.npy", np.full((48, 64), 2.0, np.float32))
    (tmp_path / "fake.npy").write_bytes((tmp_path / "rgb.png").read_bytes())
    (tmp_path / "empty.glb").write_bytes(b"")
    (tmp_path / "model.onnx").write_bytes(b"\x08\x07")  # what matters is the suffix: an export
    return tmp_path


@pytest.mark.parametrize("argv, message", [
    # a folder where a file is expected was "not found"
    (["render", "procedural:3", "--pose", "3,3,1.2,0", "--config", "{d}/adir", "--out", "{d}/o"],
     "adir: is a folder, expected a file (config file)"),
    (["explore", "--scene", "procedural:3", "--model", "{d}/adir", "--out", "{d}/o"],
     "adir: is a folder, expected a file (model file)"),
    (["predict", "--image", "{d}/adir", "--depth", "{d}/depth.npy", "--out", "{d}/o"],
     "adir: is a folder, expected a file (image)"),
    (["predict", "--image", "{d}/rgb.png", "--depth", "{d}/adir", "--out", "{d}/o"],
     "adir: is a folder, expected a file (depth file)"),
    (["export", "{d}/adir", "--format", "onnx", "--out", "{d}/o.onnx"],
     "adir: is a folder, expected a file (model file)"),
    # and a file where a folder is expected
    (["sequence", "--input", "{d}/rgb.png", "--format", "tum", "--out", "{d}/o"],
     "rgb.png: is a file, expected a folder (TUM sequence)"),
    (["evaluate", "{d}/model.onnx", "--data", "{d}/depth.npy", "--all"],
     "model.onnx: an exported model (.onnx); this needs the model file (.safetensors)"),
    (["export", "{d}/model.onnx", "--format", "safetensors", "--out", "{d}/o.safetensors"],
     "model.onnx: an exported model (.onnx)"),
    # misleading messages
    (["evaluate", "MODEL", "--data", "{d}/depth.npy", "--all"],
     "depth.npy: is a file, expected a dataset folder (made by frontiernet datagen)"),  # was "corrupt shard, delete it"
    (["predict", "--image", "{d}/rgb.png", "--depth", "{d}/depth.npy", "--depth-scale", "5000", "--out", "{d}/o"],
     "depth.npy: holds float32 depth, read as metres; the depth scale (5000, --depth-scale) applies to integer"),
    (["predict", "--image", "{d}/rgb.png", "--depth", "{d}/fake.npy", "--out", "{d}/o"],
     "fake.npy: not a readable .npy array (the file is a PNG image, named .npy)"),  # was numpy's "allow_pickle"
    (["scene", "info", "{d}/empty.glb"], "empty.glb: empty file (0 bytes), expected a mesh file"),  # was IndexError
    (["sequence", "--input", "{d}/adir", "--depth", "sonar", "--out", "{d}/o"],
     "--depth sonar: not a depth source; valid: sensor (the sequence's depth images, the default), gt, "),
    (["sequence", "--input", "{d}/adir", "--stride", "0", "--out", "{d}/o"],
     "frames.stride (--stride) must be an integer >= 1, got 0"),
    # issue 55's third probe: refused after the pictures were written, which stayed in o/
    (["predict", "--image", "{d}/rgb.png", "--depth", "{d}/depth.npy", "--intrinsics", "30,30,32,24", "--out", "{d}/o",
      "anchoring.hdbscan.min_cluster_size=0"], "anchoring.hdbscan.min_cluster_size must be an integer >= 2, got 0"),
    (["export", "MODEL", "--format", "onnx", "--out", "{d}/" + "x" * 300 + ".onnx"],  # was OSError, exit 1
     "a name of 305 bytes in the output path; file systems take at most 255"),
])
def test_wrong_kinds_of_file_are_named_for_what_they_are(files, argv, message, one_line_error):
    from frontiernet.model import default_model_path

    before = sorted(path.name for path in files.iterdir())
    argv = [str(default_model_path()) if word == "MODEL" else word.format(d=files) for word in argv]
    assert main(argv) == 2
    assert message in one_line_error()
    assert sorted(path.name for path in files.iterdir()) == before  # nothing written, no empty --out


def test_a_corrupt_shard_outside_a_dataset_gets_no_advice_to_delete_it(tmp_path):
    from datagen.dataset import DatasetError, open_dataset

    (tmp_path / "mine.zip").write_bytes(b"not a zip")
    with pytest.raises(DatasetError) as error:
        open_dataset(tmp_path / "mine.zip")
    assert "corrupt shard (bad zip file)" in str(error.value) and "delete" not in str(error.value)


def test_a_model_file_under_another_suffix_and_files_for_folders(tmp_path, capsys, one_line_error):
    # issue 55's second probe: a model file named .bin was "not a PyTorch zip archive"; a folder as the top
    # view's --out was "not an image file name", a file as bench --report's --out "no benchmark here"
    import shutil

    from frontiernet.model import default_model_path

    shutil.copy(default_model_path(), tmp_path / "model.bin")
    assert main(["export", str(tmp_path / "model.bin"), "--format", "safetensors", "--half",
                 "--out", str(tmp_path / "m.safetensors")]) == 0
    capsys.readouterr()
    assert main(["scene", "topdown", "procedural:3", "--out", str(tmp_path)]) == 2
    assert "is a folder; give the output's file name" in one_line_error()
    assert main(["bench", "--report", "--out", str(tmp_path / "model.bin")]) == 2
    assert "model.bin: is a file; a benchmark is a folder" in one_line_error()


def test_a_boolean_array_is_no_depth_map(tmp_path, one_line_error):
    # issue 55's second probe: a bool .npy was read as metres (0 and 1 m)
    import cv2

    cv2.imwrite(str(tmp_path / "rgb.png"), np.full((48, 64, 3), 128, np.uint8))
    np.save(tmp_path / "mask.npy", np.ones((48, 64), bool))
    assert main(["predict", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "mask.npy"),
                 "--out", str(tmp_path / "p")]) == 2
    assert "mask.npy: holds bool values, not depth (integer units or float metres)" in one_line_error()
    assert not (tmp_path / "p").exists()


def test_a_truncated_jpeg_is_one_line_of_ours_not_libjpegs_too(files, capfd):
    """libjpeg prints "Premature end of JPEG file" to the file descriptor itself (issue 55's 8th probe, E16):
    refused before OpenCV decodes, so ours is the only line; a whole JPEG (with a thumbnail's end marker
    early, as EXIF adds one) still reads."""
    import cv2

    image = np.random.default_rng(0).integers(0, 255, (48, 64, 3), np.uint8)
    whole = cv2.imencode(".jpg", image)[1].tobytes()
    (files / "cut.jpg").write_bytes(whole[: len(whole) // 3])
    thumbnail = cv2.imencode(".jpg", image[::4, ::4])[1].tobytes()  # in an APP1 segment, as EXIF holds one
    app1 = b"Exif\0\0" + thumbnail
    (files / "thumb.jpg").write_bytes(whole[:2] + b"\xff\xe1" + (len(app1) + 2).to_bytes(2, "big") + app1 + whole[2:])
    argv = ["predict", "--image", str(files / "cut.jpg"), "--depth", str(files / "depth.npy"), "--out", str(files / "o")]
    assert main(argv) == 2
    err = capfd.readouterr().err.strip()
    assert err.endswith("cut.jpg: a truncated JPEG (the file ends inside its image data) (image)") and "\n" not in err
    from frontiernet.array_files import read_image

    assert read_image(files / "thumb.jpg", cv2.IMREAD_COLOR).shape == (48, 64, 3)
    assert capfd.readouterr().err == ""
