"""Finished runs of a benchmark folder, one file per run or packed per (scene, method).

Two layouts hold a finished run's record (the ``metrics.json`` record of
:func:`frontiernet.exploration.outputs.metrics_record`: every metric and the coverage per step);
both are read everywhere (report, resume):

* **per run**, as each run finishes (:mod:`.runner`: written into ``<key>.partial`` and renamed):
  ``runs/<key>/metrics.json`` beside the run's other outputs, where the key is
  ``<scene key>/<method>/start<i>_repeat<r>`` (:attr:`.plan.RunSpec.key`; ``<method>@<depth>``
  in a benchmark of several depth sources, so a pack holds one method on one source);
* **packed** (``frontiernet bench --pack --out DIR``, :func:`pack`): one file per (scene, method),
  ``runs/<scene key>/<method>.jsonl.gz``: gzip (no timestamp, so packing the same runs again
  gives the same bytes) of UTF-8 JSON lines, one per run, in start and repeat order::

      {"key": "<scene key>/<method>/start0_repeat0", "metrics": {...the run's metrics.json...}}

  ``zcat FILE`` shows it. The per-step curves (``coverage_per_step``, ``surface_coverage_per_step``:
  a run writes them rounded to 5 decimals) are stored as ``{"steps_1e5": [k_0, k_1 - k_0, ...]}``,
  the integers k_i = value_i x 1e5 as differences from the step before (at most a few digits each,
  where the floats took seven characters): about 40 % smaller packs. A curve with a value that is
  not exactly k / 1e5 stays a list, and packs written before hold lists; both read back. The
  records read are the same values as the per-run files (JSON writes a float as its shortest
  round-tripping repr, and k / 1e5 is the float the run rounded to), so a report rebuilt from
  either layout is byte-identical. The published run's 1,035 ``metrics.json`` (14.6 MB) pack into
  135 files of 1.0 MB (docs/benchmark.md).

A run in both layouts (a pack made, then the per-run file written again) is read from its
per-run file, which the next pack moves in.

The plan (settings, start poses and every planned run) is ``plan.json`` as a benchmark writes it
and ``plan.json.gz`` (the same bytes, gzip without a timestamp) once packed: a plan's rows repeat
scene paths, poses and keys, so the 1,215 rows of the published run take 403 kB as JSON and 13 kB
packed. Both are read everywhere; a benchmark resumed in a packed folder keeps its plan packed.
"""

from __future__ import annotations

import gzip
import itertools
import json
import re
import zlib
from collections import defaultdict
from pathlib import Path

from ..errors import InputError
from ..io import input_file, present, write_bytes

PACK_SUFFIX = ".jsonl.gz"
PLAN = "plan.json"
PACKED_PLAN = "plan.json.gz"
COMPRESS_LEVEL = 9  # gzip's smallest; a format choice, not a tunable: packs are small and written rarely
CURVES = ("coverage_per_step", "surface_coverage_per_step")
"""The per-step curves of a run's record, stored as integer steps in a pack (module docstring)."""
CURVE_STEPS = "steps_1e5"
CURVE_SCALE = 100_000  # a run's record rounds its curves to 5 decimals (exploration/outputs.py:metrics_record)


def _gzip(data: bytes) -> bytes:
    """`data` gzip'd as every file of this module is: smallest, no timestamp (the same bytes again)."""
    return gzip.compress(data, COMPRESS_LEVEL, mtime=0)


def encode_curves(record: dict) -> dict:
    """`record` with each of :data:`CURVES` that is exactly k / 1e5 at every step as
    ``{"steps_1e5": [k_0, k_1 - k_0, ...]}``; other curves (and every other field) unchanged."""
    encoded = dict(record)
    for name in CURVES:
        values = record.get(name)
        if not isinstance(values, list) or not all(isinstance(v, (int, float)) for v in values):
            continue
        scaled = [round(v * CURVE_SCALE) for v in values]
        if all(k / CURVE_SCALE == v for k, v in zip(scaled, values)):
            encoded[name] = {CURVE_STEPS: [b - a for a, b in zip([0, *scaled], scaled)]}
    return encoded


def decode_curves(record: dict) -> dict:
    """The inverse of :func:`encode_curves` (records with list curves come back unchanged).

    Raises:
        ValueError: a curve is a mapping but not ``{"steps_1e5": [integers]}``.
    """
    decoded = dict(record)
    for name in CURVES:
        value = record.get(name)
        if isinstance(value, dict):
            steps = value.get(CURVE_STEPS)
            if set(value) != {CURVE_STEPS} or not isinstance(steps, list) or \
                    not all(isinstance(k, int) and not isinstance(k, bool) for k in steps):
                raise ValueError(f'{name} is neither a list nor {{"{CURVE_STEPS}": [integers]}}')
            decoded[name] = [k / CURVE_SCALE for k in itertools.accumulate(steps)]
    return decoded


def plan_file(out: str | Path) -> Path | None:
    """The plan of benchmark folder `out`: ``plan.json`` (as a benchmark writes it; it wins where
    both are, being what a run wrote since), else ``plan.json.gz`` (as a pack leaves it), else None.

    Raises:
        InputError: something other than a regular file has the plan's name (a folder, a pipe, a link
            to nothing: :func:`~frontiernet.io.input_file`'s words), which was taken for no plan.
    """
    for name in (PLAN, PACKED_PLAN):
        if present(Path(out) / name):
            return input_file(Path(out) / name, "benchmark plan")
    return None


def check_runs_folder(out: str | Path) -> None:
    """InputError when something other than a folder has the name of the ``runs`` folder of benchmark
    folder `out` (its finished runs were read as none: a pack rewrote the plan as packed, a report failed)."""
    runs = Path(out) / "runs"
    if present(runs) and not runs.is_dir():
        raise InputError(f"{runs}: {'is a file' if runs.is_file() else 'not a folder'}, expected the benchmark's "
                         "runs folder")


def read_plan(out: str | Path, resume: bool = False) -> dict:
    """The plan of benchmark folder `out` (settings, start poses, runs with their keys), from
    ``plan.json`` or ``plan.json.gz`` (:func:`plan_file`); with `resume`, one a benchmark resumes (its
    settings hold the ``conf`` and the ``budget`` it ran with).

    Raises:
        InputError: `out` holds no benchmark, or its plan is not a regular file, not JSON (or not gzip) or
            not of a plan's shape, or its ``runs`` is no folder (:func:`check_runs_folder`).
    """
    path = plan_file(out)
    if path is None and Path(out).exists() and not Path(out).is_dir():
        raise InputError(f"{out}: is a file; a benchmark is a folder (--out DIR)")
    if path is None:
        raise InputError(f"{out}: no benchmark here (no plan.json); run frontiernet bench --scenes ... --out {out}")
    try:
        data = path.read_bytes()
        plan = json.loads(gzip.decompress(data) if path.name == PACKED_PLAN else data)
    except (ValueError, UnicodeDecodeError, OSError, EOFError, zlib.error) as error:
        raise InputError(f"{path}: not a benchmark plan ({error})") from None
    wrong = _plan_shape_error(plan, resume)
    if wrong:
        raise InputError(f"{path}: not a benchmark plan ({wrong}); frontiernet bench writes it: restore it, or "
                         "give another --out")
    check_runs_folder(out)
    return plan


def _plan_shape_error(plan, resume: bool) -> str | None:
    """What is wrong with the shape of `plan` as JSON read it, or None: a mapping of ``settings`` (with
    `resume`, holding ``conf`` and ``budget``), ``start_poses`` and ``runs`` (each a mapping with its ``key``,
    ``scene`` and ``method``), as :func:`~frontiernet.benchmark.main.main` writes it."""
    if not isinstance(plan, dict):
        return f"a JSON {type(plan).__name__}, not an object"
    for key, kind in (("settings", dict), ("start_poses", dict), ("runs", list)):
        if not isinstance(plan.get(key), kind):
            return f"no '{key}' {'list' if kind is list else 'object'}"
    if resume and (not isinstance(plan["settings"].get("conf"), dict) or "budget" not in plan["settings"]):
        return "its 'settings' lack 'conf' or 'budget'"
    for index, run in enumerate(plan["runs"]):
        if not isinstance(run, dict) or not all(isinstance(run.get(key), str) for key in ("key", "scene", "method")):
            return f"run {index} is not an object with a 'key', 'scene' and 'method'"
    return None


def _plan_bytes(plan: dict) -> bytes:
    return (json.dumps(plan, indent=2) + "\n").encode("utf-8")


def write_plan(out: str | Path, plan: dict) -> Path:
    """Write `plan` into benchmark folder `out`, atomically, in the form the folder keeps it:
    ``plan.json.gz`` where a pack left one (and no ``plan.json``), else ``plan.json``."""
    out = Path(out)
    if plan_file(out) == out / PACKED_PLAN:
        data = _gzip(_plan_bytes(plan))
        return write_bytes(out / PACKED_PLAN, data)
    return write_bytes(out / PLAN, _plan_bytes(plan))


def _pack_plan(out: Path) -> Path:
    """``plan.json`` of `out` packed into ``plan.json.gz`` (its bytes, read back before the JSON
    file is removed); the packed plan when there is no JSON one."""
    path = out / PLAN
    if not path.is_file():
        return out / PACKED_PLAN
    data = path.read_bytes()
    packed = _gzip(data)
    write_bytes(out / PACKED_PLAN, packed)
    if gzip.decompress((out / PACKED_PLAN).read_bytes()) != data:
        raise InputError(f"{out / PACKED_PLAN}: the packed plan does not read back; {path} kept")
    path.unlink()
    return out / PACKED_PLAN


def pack_path(out: str | Path, key: str) -> Path:
    """The pack of run `key`: ``runs/<scene key>/<method>.jsonl.gz`` in benchmark folder `out`."""
    return Path(out) / "runs" / (key.rsplit("/", 1)[0] + PACK_SUFFIX)


def read_metrics(path: Path) -> dict:
    """A per-run ``metrics.json``; InputError naming it when it is not a regular file holding a JSON
    object (a folder, a pipe, a link to nothing, a file in the way: ``runs/<scene key>`` a file).
    FileNotFoundError when it is not there (the run is not finished, or packed: :class:`FinishedRuns`)."""
    path = Path(path)
    if path.is_symlink() and not path.exists():  # a link to nothing: named, not taken for a run not finished
        input_file(path, "run's metrics")
    if path.exists() and not path.is_file():  # (a pipe's read would wait for a writer)
        kind = "a folder" if path.is_dir() else "not a regular file"
        raise InputError(f"{path}: not a run's metrics ({kind}); remove the run's folder to run it again")
    try:
        record = json.loads(path.read_text())
    except FileNotFoundError:
        raise
    except (ValueError, UnicodeDecodeError, OSError) as error:
        why = error.strerror if isinstance(error, OSError) and error.strerror else error
        raise InputError(f"{path}: not a run's metrics ({why}); remove the run's folder to run it again") from None
    if not isinstance(record, dict):
        raise InputError(f"{path}: not a run's metrics (not a JSON object); remove the run's folder to run it again")
    return record


def read_pack(path: Path, data: bytes | None = None) -> dict[str, dict]:
    """Run key -> metrics record of pack `path`, in the file's order; `data`: the pack's bytes where
    they are in hand (read from `path` otherwise).

    Raises:
        InputError: the file is not a pack (not a regular file, not gzip, truncated, a line that is not
            ``{"key", "metrics"}`` JSON, a key of another scene or method, a key twice).
    """
    group = f"{Path(path).parent.name}/{Path(path).name[:-len(PACK_SUFFIX)]}"  # <scene key>/<method>
    records = {}

    def corrupt(reason: str) -> InputError:
        return InputError(f"{path}: not a packed benchmark file ({reason}); restore it (git checkout, a copy) "
                          "or remove it to run its runs again")

    if data is None:  # a folder or a pipe with a pack's name: refused, not read (a pipe's read waits for ever)
        input_file(path, "packed benchmark file")
    try:
        text = gzip.decompress(Path(path).read_bytes() if data is None else data).decode("utf-8")
    except (OSError, EOFError, zlib.error, UnicodeDecodeError) as error:  # BadGzipFile is an OSError
        raise corrupt(str(error) or type(error).__name__) from None
    for number, line in enumerate(text.splitlines(), 1):
        try:
            entry = json.loads(line)
        except ValueError as error:
            raise corrupt(f"line {number}: {error}") from None
        if not (isinstance(entry, dict) and isinstance(entry.get("key"), str) and isinstance(entry.get("metrics"), dict)):
            raise corrupt(f'line {number} is not {{"key": ..., "metrics": {{...}}}}')
        key = entry["key"]
        if key.rsplit("/", 1)[0] != group or key in records:
            raise corrupt(f"line {number}: run {key} " + ("twice" if key in records else "of another method or scene"))
        try:
            records[key] = decode_curves(entry["metrics"])
        except ValueError as error:
            raise corrupt(f"line {number}: {error}") from None
    return records


def _natural(key: str) -> list:
    """Sort key of a run key with its numbers compared as numbers (start2 before start10)."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", key)]


def _pack_bytes(records: dict[str, dict]) -> bytes:
    """The bytes of a pack of `records` (run key -> metrics record): keys in natural order, curves as integer steps."""
    lines = [json.dumps({"key": key, "metrics": encode_curves(records[key])}, separators=(",", ":"))
             for key in sorted(records, key=_natural)]
    return _gzip(("\n".join(lines) + "\n").encode("utf-8"))


def write_pack(path: Path, records: dict[str, dict]) -> Path:
    """Write `records` (run key -> metrics record) as pack `path`, atomically, keys in natural order."""
    return write_bytes(path, _pack_bytes(records))


class FinishedRuns:
    """The metrics records of the finished runs of benchmark folder `out`, from either layout
    (module docstring); each pack is read once, when one of its runs is first asked for."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self._packs: dict[Path, tuple] = {}  # pack path -> (its stat when read, key -> record)

    def _pack(self, path: Path) -> dict[str, dict]:
        if not present(path):  # no pack: its runs are not finished (or not packed)
            return {}
        stamp = input_file(path, "packed benchmark file").stat()  # a link to nothing, a folder, a pipe: named
        stamp = (stamp.st_mtime_ns, stamp.st_size)
        if path not in self._packs or self._packs[path][0] != stamp:  # new, or repacked since (a --pack beside)
            self._packs[path] = (stamp, read_pack(path))
        return self._packs[path][1]

    def metrics(self, key: str) -> dict | None:
        """The record of run `key` (``<scene key>/<method>/start<i>_repeat<r>``), None if not finished.

        Raises:
            InputError: its metrics.json or its pack is corrupt (named).
        """
        try:
            return read_metrics(self.out / "runs" / key / "metrics.json")
        except FileNotFoundError:
            return self._pack(pack_path(self.out, key)).get(key)


def discard_runs(out: str | Path, keys) -> int:
    """Remove the finished runs `keys` of benchmark folder `out` (their ``metrics.json``, or their
    records from their packs, each pack rewritten atomically or removed once empty), so that a resumed
    benchmark runs them again; their other outputs are written over then. Returns how many were finished."""
    out, count = Path(out), 0
    by_pack = defaultdict(set)
    for key in keys:
        path = out / "runs" / key / "metrics.json"
        if path.is_file():
            path.unlink()
            count += 1
        by_pack[pack_path(out, key)].add(key)
    for path, dropped in by_pack.items():
        if not path.is_file():
            continue
        records = read_pack(path)
        kept = {key: record for key, record in records.items() if key not in dropped}
        count += len(records) - len(kept)
        if not kept:
            path.unlink()
        elif len(kept) < len(records):
            write_pack(path, kept)
    return count


def pack(out: str | Path) -> dict:
    """Move the ``metrics.json`` of every finished run of the plan in benchmark folder `out` into
    its (scene, method) pack (module docstring), then remove those files; a run's other outputs
    (trajectory.json, frontiers.json, coverage.png, config.yaml) stay. The plan is packed too
    (``plan.json`` -> ``plan.json.gz``), and a pack in an older form (curves as lists where they
    are integer steps today) is rewritten in today's form, once its new bytes are checked to read
    back the same records. Runs nothing; safe beside a running benchmark of this code (it packs the
    runs finished when it starts; the benchmark's next resume reads the packed plan), not beside
    another pack, nor beside a benchmark of code from before packed plans (which finds no
    plan.json: pack such a folder with that code, ``scripts/pinned.sh``).

    Returns:
        ``{"runs": runs packed now, "packs": [pack paths written], "rewritten": [older-form pack paths
        rewritten], "packed": runs in packs in all, "plan": the packed plan}``.
    Raises:
        InputError: no benchmark in `out`, or a corrupt metrics.json or pack, or something other than a
            regular file where a planned run's metrics.json goes (a folder, a pipe, its method's folder a
            file: :func:`read_metrics`), which was taken for a run not finished (nothing written or removed then).
    """
    out = Path(out)
    plan = read_plan(out)
    fresh = defaultdict(dict)  # pack path -> key -> record, of the per-run files
    for run in plan["runs"]:  # all read before anything is written: a folder, a pipe, a file in the way refused
        if run.get("copy_of"):
            continue
        try:
            fresh[pack_path(out, run["key"])][run["key"]] = read_metrics(out / "runs" / run["key"] / "metrics.json")
        except FileNotFoundError:  # not finished (or packed)
            continue
    for path in fresh:  # the packs they go into, where something has their name: regular files (a link to nothing)
        if present(path):
            input_file(path, "packed benchmark file")
    written, rewritten, packed = [], [], {}  # packed: pack path -> its number of runs
    for path in sorted((out / "runs").glob(f"*/*{PACK_SUFFIX}")):  # packs in an older form: rewritten in today's
        if path in fresh:  # (written below with its new runs)
            continue
        records = read_pack(path, old := input_file(path, "packed benchmark file").read_bytes())
        packed[path] = len(records)
        if old == (data := _pack_bytes(records)):
            continue
        if json.dumps(sorted(read_pack(path, data).items())) != json.dumps(sorted(records.items())):  # NaN == NaN
            raise InputError(f"{path}: rewritten in today's form it would not read back the same runs; left as it is")
        write_bytes(path, data)  # checked before the old pack is replaced
        rewritten.append(path)
    for path, records in fresh.items():
        merged = {**(read_pack(path) if present(path) else {}), **records}
        write_pack(path, merged)
        if set(read_pack(path)) != set(merged):  # read back before anything is removed
            raise InputError(f"{path}: the pack written does not read back; per-run files kept")
        written.append(path)
        packed[path] = len(merged)
        for key in records:
            folder = out / "runs" / key
            (folder / "metrics.json").unlink()
            for empty in (folder, folder.parent):  # the run's folder and its method's, once empty
                try:
                    empty.rmdir()
                except OSError:
                    break
    return {"runs": sum(len(records) for records in fresh.values()), "packs": written, "rewritten": rewritten,
            "packed": sum(packed.values()), "plan": _pack_plan(out)}


__all__ = ["FinishedRuns", "check_runs_folder", "discard_runs", "pack", "plan_file", "read_plan", "write_plan", "read_pack", "write_pack", "read_metrics",
           "pack_path", "PACK_SUFFIX", "encode_curves", "decode_curves"]
