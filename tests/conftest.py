"""Shared fixtures: the shared real data folder and a small synthetic two-room scene."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from frontiernet.scenes import Scene, SceneMetadata
from frontiernet.scenes.builder import MeshBuilder
from frontiernet.scenes.scene import Material

REPO_ROOT = Path(__file__).resolve().parents[1]
needs_git = pytest.mark.skipif(shutil.which("git") is None or not (REPO_ROOT / ".git").exists(),
                               reason="needs git and a git checkout")
"""For a test that reads the checkout's history or its list of tracked files."""

# Two-room box (see two_room_scene): interior [0, 6] x [0, 4] x [0, 2.5] m, walls 0.2 m
# thick outside it, a 0.2 m partition at x in [2.9, 3.1] with a door y in [1.5, 2.4],
# z in [0, 2.0] (lintel above).
TWO_ROOM = {
    "interior": (np.array([0.0, 0.0, 0.0]), np.array([6.0, 4.0, 2.5])),
    "partition_x": (2.9, 3.1),
    "door_y": (1.5, 2.4),
    "door_height": 2.0,
    "wall": 0.2,
}
TWO_ROOM_FREE_VOLUME = 6.0 * 4.0 * 2.5 - (0.2 * 4.0 * 2.5 - 0.2 * 0.9 * 2.0)  # 58.36 m^3


def folder_files(folder: Path) -> dict:
    """Relative path -> bytes of every file under `folder` (to assert that a refused run changed nothing)."""
    return {path.relative_to(folder): path.read_bytes() for path in sorted(Path(folder).rglob("*")) if path.is_file()}


def python_in_subprocess(code: str, timeout: float = 240):
    """``python -c CODE`` in its own process (a read of a pipe would wait for ever): its CompletedProcess; a run
    past `timeout` fails the test."""
    import subprocess
    import sys

    try:
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"still running after {timeout} s (blocked on a pipe?)")


def copy_tracked(folder: str, target: Path) -> Path:
    """Copy the git-tracked files of repository `folder` (e.g. a small published benchmark) to `target`, never
    writing to the original; returns `target`. Skips the test without git or a repository."""
    import subprocess

    if shutil.which("git") is None or not (REPO_ROOT / ".git").exists():
        pytest.skip("needs git and the repository's history")
    listed = subprocess.run(["git", "ls-files", folder], cwd=REPO_ROOT, capture_output=True, text=True,
                            check=True).stdout.split()
    for name in listed:
        copied = target / (REPO_ROOT / name).relative_to(REPO_ROOT / folder)
        copied.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(REPO_ROOT / name, copied)
    return target


@pytest.fixture(scope="session", autouse=True)
def raycast_engine() -> str:
    """The shipped sim.yaml's ray-cast engine, selected for the tests that cast without a world
    (a command's build_world selects its own config's)."""
    from frontiernet.config import load_config
    from frontiernet.simulator.raycast import select_backend

    return select_backend(load_config("sim").raycast.backend)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of the shared real data (``../shared/data`` or ``$FRONTIERNET_SHARED_DATA``); skips if absent."""
    path = Path(os.environ.get("FRONTIERNET_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))
    if not path.is_dir():
        pytest.skip(f"shared data not found at {path} (set FRONTIERNET_SHARED_DATA)")
    return path


def box_scene(lower, upper, name: str = "boxes") -> Scene:
    """A scene made of axis-aligned boxes: (N, 3) lower and upper corners in metres."""
    builder = MeshBuilder()
    mid = builder.material(Material("grey", (150, 150, 150)))
    builder.add_boxes(np.asarray(lower, float), np.asarray(upper, float), mid)
    return builder.build(SceneMetadata(name=name, source="procedural", spec=f"test:{name}"))


def room_boxes(x1: float, y1: float, height: float, wall: float = 0.2, ceiling: bool = True,
               door: tuple[float, float] | None = None, door_height: float = 2.0):
    """Boxes of a closed room with interior [0, x1] x [0, y1] x [0, height].

    `door` = (y0, y1) cuts a door into the wall at x = x1 (from the floor to `door_height`).
    Returns (lower, upper) lists.
    """
    w = wall
    lower = [(-w, -w, -w), (-w, -w, 0), (-w, y1, 0), (-w, -w, 0)]
    upper = [(x1 + w, y1 + w, 0), (x1 + w, 0, height), (x1 + w, y1 + w, height), (0, y1 + w, height)]
    if ceiling:
        lower.append((-w, -w, height))
        upper.append((x1 + w, y1 + w, height + w))
    if door is None:
        lower.append((x1, -w, 0))
        upper.append((x1 + w, y1 + w, height))
    else:
        lower += [(x1, 0, 0), (x1, door[1], 0), (x1, door[0], door_height)]
        upper += [(x1 + w, door[0], height), (x1 + w, y1, height), (x1 + w, door[1], height)]
    return lower, upper


@pytest.fixture(scope="session")
def two_room_scene() -> Scene:
    """A closed box (floor, ceiling, 4 walls) split into two rooms joined by a door; see TWO_ROOM."""
    lower, upper = room_boxes(6.0, 4.0, 2.5)
    (px0, px1), (dy0, dy1) = TWO_ROOM["partition_x"], TWO_ROOM["door_y"]
    lower += [(px0, 0, 0), (px0, dy1, 0), (px0, dy0, TWO_ROOM["door_height"])]
    upper += [(px1, dy0, 2.5), (px1, 4.0, 2.5), (px1, dy1, 2.5)]
    return box_scene(lower, upper, "two-room")


def seal_the_door(context, frames: int = 6) -> None:
    """Integrate into ``context.map`` `frames` looks at the two-room partition from the first room,
    rendered with the door closed: the map's door is then occupied, as a noisy depth source's walls
    shut a doorway the robot came through (issue 54)."""
    from frontiernet.config import load_config
    from frontiernet.geometry import pose_from_heading
    from frontiernet.simulator.camera import PinholeCamera, Renderer

    lower, upper = room_boxes(6.0, 4.0, 2.5)
    (px0, px1) = TWO_ROOM["partition_x"]
    sealed = box_scene(lower + [(px0, 0, 0)], upper + [(px1, 4.0, 2.5)], "two-room-sealed")
    sim = load_config("sim")
    renderer = Renderer(sealed, PinholeCamera.from_config(sim.camera), (0, 0, 0))
    for _ in range(frames):
        T = pose_from_heading(1.5, 2.0, 1.2, 0.0, np.radians(float(context.conf.motion.pitch_deg)))
        frame = renderer.render(T)
        context.map.integrate(frame.depth, frame.K, T)


@pytest.fixture(scope="session")
def two_room_voxels(two_room_scene):
    """The two-room scene voxelised with the shipped config."""
    from frontiernet.simulator.voxels import voxelize_scene

    return voxelize_scene(two_room_scene, sim_section("voxels"))


@pytest.fixture(scope="module")
def two_scenes(tmp_path_factory) -> Path:
    """A tiny datagen dataset: 2 procedural scenes x 2 views of 64 x 64 px, one shard a scene (one per test
    module: some tests change it)."""
    from datagen.config import load_datagen_config
    from datagen.generate import generate

    out = tmp_path_factory.mktemp("data") / "two"
    conf = load_datagen_config(overrides=["camera.width=64", "camera.height=64", "camera.focal_px=40",
                                          "writer.shard_size=2"])
    generate(["procedural:3", "procedural:4"], 2, out, conf, seed=0, workers=1, progress=False)
    return out


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    """A tiny datagen dataset: 3 procedural scenes x 8 views of 96 x 96 px (for training tests)."""
    from datagen.config import load_datagen_config
    from datagen.generate import generate

    out = tmp_path_factory.mktemp("data") / "tiny"
    conf = load_datagen_config(overrides=["camera.width=96", "camera.height=96", "camera.focal_px=60",
                                          "writer.shard_size=4"])
    generate(["procedural:11", "procedural:12", "procedural:13"], 8, out, conf, seed=0, workers=1, progress=False)
    return out


def explore_section(name: str, **changes) -> dict:
    """A section of ``configs/explore.yaml`` as a dict, with `changes` applied."""
    from frontiernet.config import load_config

    conf = dict(load_config("explore")[name])
    conf.update(changes)
    return conf


def scenes_config(**changes):
    """``configs/scenes.yaml`` (DictConfig), with `changes` merged on top: the scenes section a
    command passes to ``load_scene``."""
    from omegaconf import OmegaConf

    from frontiernet.config import load_config

    return OmegaConf.merge(load_config("scenes"), changes)


def sim_section(name: str, **changes):
    """A section of ``configs/sim.yaml`` (DictConfig), with `changes` merged on top."""
    from omegaconf import OmegaConf

    from frontiernet.config import load_config

    return OmegaConf.merge(load_config("sim")[name], changes)


def floorplan_spec(folder: Path, name: str, plan: np.ndarray) -> str:
    """Save an (H, W) uint8 plan image (0 = wall, 254 = free) and return its spec at 0.05 m/px."""
    from PIL import Image

    Image.fromarray(plan).save(folder / f"{name}.png")
    return f"floorplan:{folder / f'{name}.png'}?resolution=0.05"


@pytest.fixture(scope="session")
def plan_spec(tmp_path_factory) -> str:
    """Two 3 x 4 m rooms joined by a 1 m door, as a floor-plan image (0.05 m/px)."""
    plan = np.full((100, 160), 254, np.uint8)
    plan[10:90, 10:16] = plan[10:90, 144:150] = 0
    plan[10:16, 10:150] = plan[84:90, 10:150] = 0
    plan[10:90, 77:83] = 0
    plan[40:60, 77:83] = 254  # the door
    return floorplan_spec(tmp_path_factory.mktemp("plan"), "plan", plan)


@pytest.fixture(scope="session")
def closet_spec(tmp_path_factory) -> str:
    """One closed room of 1.9 x 1.9 m (a floor plan): a look-around sees every wall, then nothing is left."""
    plan = np.full((60, 60), 254, np.uint8)
    plan[5:55, 5:11] = plan[5:55, 49:55] = 0
    plan[5:11, 5:55] = plan[49:55, 5:55] = 0
    return floorplan_spec(tmp_path_factory.mktemp("closet"), "closet", plan)


@pytest.fixture
def one_line_error(capsys):
    """Reads what a command printed to stderr and checks it is one line, no traceback."""
    def read() -> str:
        err = capsys.readouterr().err.strip()
        assert err and "\n" not in err and "Traceback" not in err, err
        return err
    return read


def _process_stat(pid: int) -> list[str] | None:
    """The fields of /proc/<pid>/stat after the command name (state, parent pid, ...); None if gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def _spawned_children(pid: int) -> list[int]:
    """Worker processes (multiprocessing spawn) whose parent is `pid`, from /proc."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or (fields := _process_stat(int(entry.name))) is None or int(fields[1]) != pid:
            continue
        try:
            if b"spawn_main" in (entry / "cmdline").read_bytes():
                found.append(int(entry.name))
        except OSError:
            continue
    return found


def _alive(pids: list[int]) -> list[int]:
    """The processes of `pids` that still run (neither gone nor zombies)."""
    return [pid for pid in pids if (fields := _process_stat(pid)) is not None and fields[0] != "Z"]


def check_sigterm_ends_workers(args: list[str], workers: int = 2, *, command: list[str] | None = None) -> None:
    """Run ``frontiernet ARGS`` (or `command`) until it has `workers` spawned worker processes, send
    SIGTERM to the command's own process (as ``kill PID`` does), and check it exits 130
    ("interrupted") and no worker is left running. Linux only (reads /proc); kills whatever it
    started if a check fails."""
    import signal
    import subprocess
    import sys
    import time

    process = subprocess.Popen(command or [sys.executable, "-m", "frontiernet.cli.main", *args],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    found = []
    try:
        deadline = time.monotonic() + 240
        while len(found := _spawned_children(process.pid)) < workers and time.monotonic() < deadline:
            assert process.poll() is None, process.communicate()[1][-2000:]
            time.sleep(0.5)
        assert len(found) >= workers, "the command started no workers"
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=120)
        assert process.returncode == 130 and "interrupted" in err, err[-2000:]
        deadline = time.monotonic() + 30
        while _alive(found) and time.monotonic() < deadline:
            time.sleep(0.5)
        assert not _alive(found), f"workers still running after the command stopped: {_alive(found)}"
    finally:  # a failed check leaves nothing running
        if process.poll() is None:
            process.kill()
        for pid in _alive(found):
            os.kill(pid, signal.SIGKILL)


@pytest.fixture(scope="session")
def tiny_depth_anything(tmp_path_factory):
    """A tiny random metric DepthAnything + DPT processor saved as a local weights folder: the real
    loading and inference code of ``depth_anything_v2`` without the real weights (not downloadable here).
    Its depth range is 0-6 m (the indoor models' is 0-20 m): its random outputs, about 3 m, fall inside
    the 3.5 m the network reads."""
    transformers = pytest.importorskip("transformers")
    backbone = transformers.Dinov2Config(
        image_size=56, patch_size=14, hidden_size=32, num_hidden_layers=4, num_attention_heads=2,
        intermediate_size=64, out_indices=[1, 2, 3, 4], reshape_hidden_states=False,
    )
    config = transformers.DepthAnythingConfig(
        backbone_config=backbone, reassemble_hidden_size=32, neck_hidden_sizes=[8, 16, 32, 32],
        fusion_hidden_size=16, head_hidden_size=8, depth_estimation_type="metric", max_depth=6,
    )
    processor = transformers.DPTImageProcessor(
        do_resize=True, size={"height": 56, "width": 56}, keep_aspect_ratio=True, ensure_multiple_of=14,
        do_pad=False, image_mean=[0.485, 0.456, 0.406], image_std=[0.229, 0.224, 0.225],
    )
    folder = tmp_path_factory.mktemp("da_v2")
    transformers.DepthAnythingForDepthEstimation(config).save_pretrained(folder)
    processor.save_pretrained(folder)
    return folder
