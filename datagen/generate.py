"""Generate a dataset: scenes in, sharded ground-truth views out (``frontiernet datagen``).

The work is a list of shards, each a fixed number of views of one scene with its own
seed, derived from the run's seed and the scene spec (so adding a scene leaves the others'
shards unchanged). Shards are independent: they run in any order, on processes
(``local``) or Ray tasks (``ray``), and each is written atomically. ``resume`` skips the
shards already on disk, so a killed run continues without gaps or duplicates, and the
same seed gives the same bytes.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import shutil
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from frontiernet import __version__
from frontiernet.config import first_difference, setting_text
from frontiernet.errors import InputError, whole_number
from frontiernet.io import (LOCK_NAME, check_not_dangling, check_output_files, check_output_name, claim_output_folder,
                            input_folder, write_json)
from frontiernet.scenes.spec import checked_spec, expand_specs
from frontiernet.errors import check_seed
from frontiernet.simulator.raycast import resolve_backend
from frontiernet.workers import check_backend

from .config import config_hash, hashed_settings
from .shards import (CACHE_DIR, INFO_NAME, SHARDS_DIR, read_dataset_info, regular_file, remove_stale_temporaries,
                     shard_complete, write_dataset_info)

GENERATOR_VERSION = f"frontiernet-datagen/{__version__}/gt1"
"""Names the ground-truth algorithm; bump the ``gt`` number when the labels change."""
MAX_VIEWS = 10_000_000
"""The most views one run makes (scenes x ``--views-per-scene``): 500 times the paper's dataset; more
would take minutes only to plan."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ShardTask:
    """One shard to generate: `num_views` views of scene `spec`, seeded with `seed`."""

    spec: str
    scene_index: int
    shard_index: int
    num_views: int
    seed: int
    path: str

    @property
    def name(self) -> str:
        return Path(self.path).name


def _slug(spec: str) -> str:
    """A short, file-name-safe label for a scene spec."""
    text = re.sub(r"[^A-Za-z0-9]+", "-", Path(spec.split("?")[0]).name or spec).strip("-")
    return (text or "scene")[:40]


def shard_seed(seed: int, spec: str, shard_index: int) -> int:
    """A 63-bit seed for one shard, from the run seed, the scene spec and the shard index."""
    digest = hashlib.sha256(f"{seed}\0{spec}\0{shard_index}".encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 1


def plan_shards(specs: list[str], views_per_scene: int, shard_size: int, seed: int, out: Path) -> list[ShardTask]:
    """The shards of a run, in order (scene by scene)."""
    tasks = []
    for scene_index, spec in enumerate(specs):
        for shard_index, start in enumerate(range(0, views_per_scene, shard_size)):
            name = f"{scene_index:05d}-{_slug(spec)}-{shard_index:04d}.zip"
            tasks.append(ShardTask(spec, scene_index, shard_index, min(shard_size, views_per_scene - start),
                                   shard_seed(seed, spec, shard_index), str(out / SHARDS_DIR / name)))
    return tasks


def missing_shards(root: Path, info: dict) -> list[ShardTask]:
    """The shards the dataset.json `info` of the dataset folder `root` plans (:func:`plan_shards` of its
    ``scenes``, ``views_per_scene``, ``shard_size`` and ``seed``) that ``shards/`` lacks, less those of the
    scenes its last run reported failed (``failed_scenes`` of ``summary.json``: no view was made of them, and
    the run said so). What is left is a shard deleted or not made yet (an interrupted run): ``datagen
    --resume`` makes it. Empty for a description that does not say what it plans."""
    try:
        tasks = plan_shards([str(spec) for spec in info["scenes"]], int(info["views_per_scene"]),
                            int(info["shard_size"]), int(info["seed"]), Path(root))
    except (KeyError, TypeError, ValueError):
        return []
    failed = set()
    if (root / "summary.json").is_file():
        try:
            failed = {failure["scene"] for failure in json.loads((root / "summary.json").read_text())["failed_scenes"]}
        except (OSError, ValueError, KeyError, TypeError):
            pass
    return [task for task in tasks if task.spec not in failed and not Path(task.path).is_file()]


def _check_args(specs, views_per_scene, seed, conf: DictConfig) -> tuple[list[str], int]:
    if not specs:
        raise InputError("no scenes given (--scenes SPEC ...)")
    whole_number(views_per_scene, "--views-per-scene", 1, MAX_VIEWS)
    check_seed(seed, "--seed")
    resolve_backend(conf.raycast.backend)  # an unknown or absent ray-cast engine fails before any work
    shard_size = conf.writer.shard_size
    if not isinstance(shard_size, int) or shard_size < 1:
        raise InputError(f"writer.shard_size must be a positive integer, got {shard_size!r}")
    expanded = expand_specs(specs)
    if len(expanded) * views_per_scene > MAX_VIEWS:
        raise InputError(f"{len(expanded):,} scenes x {views_per_scene:,} views is more than {MAX_VIEWS:,} views "
                         "in one run; split the scenes over several datasets")
    for spec in expanded:
        checked_spec(spec)  # a malformed or missing scene fails before any work starts
    return expanded, shard_size


DATASET_KINDS = {"frontiernet-dataset": ("a FrontierNet dataset", "datagen"),
                 "frontiernet-map-dataset": ("a map dataset", "mapgen")}
"""The datasets' ``dataset.json`` formats: what each is, and the command that makes (and resumes) it."""


def check_dataset_kind(out: Path, read_info, command: str) -> None:
    """InputError naming `out` when its ``dataset.json`` is not one that `read_info` (`command`'s) reads: a
    dataset of the other command (``mapgen --out`` a datagen dataset advised ``--resume``, which was then refused
    as "not a map dataset"), or a damaged description (named as `read_info` names it)."""
    try:
        read_info(out)
    except InputError:
        if not (out / INFO_NAME).is_file():  # a folder, a pipe, a device (/dev/zero): refused as such by `read_info`,
            raise  # and never read here (a pipe blocked, /dev/zero filled the memory)
        try:
            found = json.loads((out / INFO_NAME).read_text()).get("format")
        except (OSError, ValueError, AttributeError):
            found = None
        if found not in DATASET_KINDS or DATASET_KINDS[found][1] == command:
            raise
        what, maker = DATASET_KINDS[found]
        mine = next((kind for kind, by in DATASET_KINDS.values() if by == command), f"a {command} dataset")
        raise InputError(f"{out}: holds {what} (frontiernet {maker}), not {mine}: {command} cannot add to it or "
                         "resume it; choose another --out") from None


def check_output_paths(out: Path, shard_kind: str) -> None:
    """Before any work or deletion: InputError naming the path when what a run writes in dataset folder `out` cannot
    go there: ``shards`` not a folder (a file, a dangling link: the refusal came per scene, after the work and after
    the training caches were removed), a ``*.zip`` there that is no regular file (a folder taken for no shard and the
    dataset declared complete, a pipe waited on for ever: :func:`~datagen.shards.regular_file`, `shard_kind` as its
    kind), or a folder or a device where ``summary.json`` goes (:func:`~frontiernet.io.check_output_files`)."""
    shards = out / SHARDS_DIR
    if os.path.lexists(shards):
        input_folder(shards, f"{shard_kind}s")
        for path in shards.glob("*.zip"):
            regular_file(path, shard_kind)
    check_output_files(out, ("summary.json",))


def _signatures(paths: list[Path]) -> list:
    """(size, mtime, inode) of each of `paths`, None for one that is not there."""
    def signature(path: Path):
        try:
            stat = path.stat()
        except OSError:
            return None
        return stat.st_size, stat.st_mtime_ns, stat.st_ino

    return [signature(path) for path in paths]


@contextmanager
def drop_stale_caches(out: Path, paths):
    """A context for a run that makes the shards `paths` of dataset folder `out`: when it ends (interrupted too), the
    training caches (``cache/``) are removed if one of those shards was added or changed: they were built from the
    dataset as it was and no longer match it (training would refuse them; the next ``train`` rebuilds its own). A run
    that added nothing keeps them."""
    cache, paths = out / CACHE_DIR, [Path(path) for path in paths]
    before = _signatures(paths) if cache.is_dir() else None
    try:
        yield
    finally:
        if before is not None and cache.is_dir() and _signatures(paths) != before:
            log.warning("removing %s: the training caches of the dataset before this run", cache)
            shutil.rmtree(cache, ignore_errors=True)


def prepare_output(out: Path, info: dict, resume: bool, keys=("config_hash", "seed", "scenes", "views_per_scene",
                                                               "generator_version"),
                   read_info=read_dataset_info, write_info=write_dataset_info, command: str = "datagen",
                   settings=hashed_settings, shard_kind: str = "dataset shard") -> None:
    """Create `out` with its dataset.json (`write_info`), or check that it matches when resuming: the
    `keys` of the one `read_info` reads there must equal `info`'s (nothing written on a refusal; for the
    ``config_hash``, the first of the `settings` it hashes that differs is named, ``camera.width: 64 in the
    dataset, 32 now``; None written null). Datagen's dataset by default; :mod:`datagen.mapgen` passes its own keys,
    files, settings and `shard_kind` (and `command`, which starts the note of a `resume` with no dataset to resume:
    a new one is started, and that is said on stdout, ``<command>: note: --resume: ...``; an error would still be
    the one line on stderr). The paths the run writes are checked too (:func:`check_output_paths`). Anything at
    ``dataset.json``, a symbolic link to nothing too, is a description `read_info` must read (a dangling one was taken
    for none: a new description of today's settings written, the shards there adopted unchecked)."""
    if os.path.lexists(out / INFO_NAME):
        check_dataset_kind(out, read_info, command)
        if not resume:
            raise InputError(f"{out}: already holds a dataset; pass --resume to continue it or choose another --out")
        previous = read_info(out)
        for key in keys:
            if previous.get(key) == info[key]:
                continue
            if key == "config_hash" and isinstance(previous.get("config"), dict):
                setting = first_difference(settings(previous["config"]), settings(info["config"]), "the dataset")
                if setting is not None:
                    raise InputError(f"{out}: cannot resume, the dataset was made with other settings ({setting}); "
                                     "use another --out")
            raise InputError(f"{out}: cannot resume, the dataset was made with a different {key} "
                             f"({setting_text(previous.get(key))}, now {setting_text(info[key])}); use another --out")
        check_output_paths(out, shard_kind)
        return
    check_not_dangling(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    if out.is_dir() and any(entry.name != LOCK_NAME for entry in out.iterdir()) and not (out / SHARDS_DIR).is_dir():
        raise InputError(f"{out}: folder is not empty and holds no dataset; choose another --out")
    check_output_paths(out, shard_kind)
    if resume:  # (a typo in --out would otherwise start a second dataset without a word)
        print(f"{command}: note: --resume: {out} holds no dataset yet (no {INFO_NAME}), so there is nothing to "
              "resume; starting a new one")
    try:
        (out / SHARDS_DIR).mkdir(parents=True, exist_ok=True)
        write_info(out, info)
    except OSError as error:
        raise InputError(f"{out}: cannot write the dataset there ({error.strerror or error})") from None


def generate(scenes: list[str], views_per_scene: int, out: str | Path, conf: DictConfig, *, seed: int = 0,
             workers: int = 1, backend: str = "local", resume: bool = False, progress: bool = True) -> dict:
    """Generate (or resume) a dataset; returns the summary also written to ``out/summary.json``.

    Args:
        scenes: scene specs (ranges, globs and folders of scenes are expanded).
        views_per_scene: views per scene.
        out: the dataset folder.
        conf: the merged datagen config (:func:`datagen.config.load_datagen_config`).
        seed: the run's seed; the same seed and config give the same bytes.
        workers: parallel processes (local) or concurrent Ray tasks (ray).
        backend: ``local`` or ``ray``.
        resume: continue a dataset in `out` (shards on disk are kept, the rest are made).
        progress: show a progress bar.
    Raises:
        InputError: bad arguments, an unusable output folder or one another run writes
            (:func:`~frontiernet.io.claim_output_folder`: two runs made the same shards), a resume that does
            not match the dataset on disk. Failing scenes do not raise: they are reported.
    """
    from .backends import run_tasks

    out = Path(out)
    specs, shard_size = _check_args(scenes, views_per_scene, seed, conf)
    check_backend(backend, workers)  # before anything is written: a refused run leaves nothing behind
    conf_dict = OmegaConf.to_container(conf, resolve=True)
    info = {"generator_version": GENERATOR_VERSION, "config_hash": config_hash(conf), "seed": seed,
            "scenes": specs, "views_per_scene": views_per_scene, "shard_size": shard_size, "config": conf_dict}
    check_output_name(out / INFO_NAME)  # before the system is asked about it (ENAMETOOLONG)
    created = not (out / INFO_NAME).exists()
    existed = out.exists()
    with claim_output_folder(out, force=True):  # one run at a time writes a dataset (--resume included)
        prepare_output(out, info, resume)
        removed = remove_stale_temporaries(out / SHARDS_DIR)
        if removed:
            log.info("removed %d unfinished shard file(s) of an interrupted run", removed)
        tasks = plan_shards(specs, views_per_scene, shard_size, seed, out)
        todo = [task for task in tasks if not shard_complete(task.path)]
        start = time.perf_counter()
        with drop_stale_caches(out, [task.path for task in todo]):  # once a shard is added
            results = run_tasks([asdict(task) for task in todo], conf_dict, info, backend=backend, workers=workers,
                                progress=progress, total_views=sum(task.num_views for task in todo))
        elapsed = time.perf_counter() - start
        remove_stale_temporaries(out / SHARDS_DIR)  # left by workers that died (their shards were redone)
        from .summary import summarise

        summary = summarise(out, tasks, results, elapsed, done_before=len(tasks) - len(todo))
        if created and summary["views"] == 0 and results:  # every shard failed: a dataset of nothing
            _take_back(out, existed)  # the next run must not find an empty dataset in its way
            failures = summary["failed_scenes"] or [{"scene": specs[0], "error": "no view made"}]
            raise InputError(f"{failures[0]['scene']}: {failures[0]['error']} (no view was made of "
                             f"{len(summary['failed_scenes'])} failed scene(s); nothing was left in {out})")
        write_json(out / "summary.json", summary)
        return summary


def _take_back(out: Path, existed: bool) -> None:
    """Remove what a run that made nothing wrote to `out`: the folder when the run created it,
    else its dataset.json and empty shards folder."""
    if not existed:
        shutil.rmtree(out, ignore_errors=True)
        return
    (out / INFO_NAME).unlink(missing_ok=True)
    remove_stale_temporaries(out / SHARDS_DIR)
    try:
        (out / SHARDS_DIR).rmdir()
    except OSError:
        pass
