"""Reading inputs and writing outputs: an input file or folder checked for what it is
(:func:`input_file`, :func:`input_folder`; arrays and images: :mod:`.array_files`), an output folder claimed for one run
(:func:`claim_output_folder`) and outputs written atomically, so an interrupted run never leaves a
half-written file."""

from __future__ import annotations

import errno
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from .errors import InputError


def ensure_dir(path: str | Path) -> Path:
    """Create output folder `path` (and parents); fail with a clear message if impossible (a symbolic link to
    nothing there or on the way named as such: :func:`check_not_dangling`, not "cannot create ... (File exists)")."""
    path = Path(path)
    for folder in (path, *path.parents):
        check_not_dangling(folder)
    if path.exists() and not path.is_dir():
        raise InputError(f"{path}: output path exists and is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"{path}: cannot create output folder ({error.strerror})") from None
    return path


def present(path: str | Path) -> bool:
    """Whether anything has the name `path` (a file, a folder, a pipe, a link, dangling or not): an optional
    file of a format is then read, and :func:`input_file` names one of the wrong kind, instead of
    taking it for absent (``is_file()`` is False for a pipe, which a read would wait on forever)."""
    return os.path.lexists(path)


def nonempty_path(path: str | Path, what: str) -> Path:
    """`path` as a Path unless it is the empty string, which ``Path`` reads as ``.`` (the current folder):
    InputError ``an empty path ('') names no <what>`` (an option given as ``''``; the CLI's input options
    check it as they are parsed: :func:`~frontiernet.cli.options.input_path`)."""
    if isinstance(path, str) and not path:
        raise InputError(f"an empty path ('') names no {what}; give a path (the current folder is '.')")
    return Path(path)


def input_file(path: str | Path, what: str = "file", *, empty_ok: bool = True) -> Path:
    """`path` as a Path if it is a file; InputError naming it otherwise: ``<path>: <what> not
    found``, ``<path>: is a folder, expected a file`` (``<what>``: ``config file``, ``model
    file``, ...), ``an empty path ('') names no <what>`` and with `empty_ok` off ``<path>: empty
    file (0 bytes)``."""
    path = nonempty_path(path, what)
    if path.is_dir():
        raise InputError(f"{path}: is a folder, expected a file ({what})")
    if not path.exists():
        raise InputError(f"{path}: {what} not found{why_missing(path)}")
    if not path.is_file():
        raise InputError(f"{path}: not a regular file, expected a file ({what})")
    if not empty_ok and path.stat().st_size == 0:
        raise InputError(f"{path}: empty file (0 bytes), expected a {what}")
    return path


def why_missing(path: Path) -> str:
    """What an input `path` that does not exist is, where it is more than nothing (``""`` then): ``: a symbolic
    link loop (a -> b -> a)`` (a link, or a folder on the way, that leads back to itself: "not found" alone
    sent one looking for a missing file) or ``: a symbolic link to X, which does not exist``."""
    try:
        os.stat(path)
    except OSError as error:
        if error.errno == errno.ELOOP:
            hops, current = [str(path)], path
            while current.is_symlink() and len(hops) < 6:
                target = os.readlink(current)
                hops.append(target)
                current = current.parent / target
                if os.path.normpath(current) == os.path.normpath(path):
                    break
            chain = " -> ".join(hops) + (" -> ..." if len(hops) == 6 else "")
            return f": a symbolic link loop ({chain}), which leads back to itself"
    except ValueError:
        return ""
    if path.is_symlink():
        return f": a symbolic link to {os.readlink(path)}, which does not exist"
    return ""


def input_folder(path: str | Path, what: str = "input") -> Path:
    """`path` as a Path if it is a folder; InputError naming it otherwise: ``<path>: <what>
    folder not found``, ``<path>: is a file, expected a folder (<what>)``, or ``an empty path ('')
    names no <what> folder``."""
    path = nonempty_path(path, f"{what} folder")
    if path.exists() and not path.is_dir():
        kind = "a file" if path.is_file() else "not a regular file nor a folder (a device or a pipe?)"
        raise InputError(f"{path}: is {kind}, expected a folder ({what})")
    if not path.is_dir():
        raise InputError(f"{path}: {what} folder not found{why_missing(path)}")
    return path


def check_yaml_mapping(root, path: str | Path) -> None:
    """InputError naming YAML file `path` unless its top node `root` (``yaml.compose``'s: nothing built, no
    alias expanded) is a mapping, or there is none (an empty file): a config of a bare value or a list is
    refused so (a bare ``hello`` read as a key named hello, a bare ``42`` failed inside OmegaConf)."""
    import yaml

    if root is None or isinstance(root, yaml.MappingNode) or root.tag == "tag:yaml.org,2002:null":
        return
    got = "a list" if isinstance(root, yaml.SequenceNode) else f"the bare value {root.value!r}"
    raise InputError(f"{path}: a config must be a YAML mapping (key: value lines), got {got}")


FORCE = "--force"
"""The option of every command that replaces earlier outputs (export, render, explore, scene topdown)."""


def check_writable_folder(folder: str | Path, what: str) -> Path:
    """Before the work: InputError naming `what` unless a file can be made in `folder` (it is tried,
    and removed: permissions alone do not tell, e.g. for root or a read-only file system)."""
    import tempfile

    folder = Path(folder)
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise InputError(f"{what}: cannot write in {folder} ({error.strerror or type(error).__name__})") from None
    return folder


MAX_PATH_BYTES = 4095  # the longest path the system takes (Linux's PATH_MAX, 4,096 bytes with its terminating zero)


def check_output_name(path: str | Path) -> Path:
    """InputError when a name in output `path` is longer than the file system takes (255 bytes), or the whole
    path (made absolute, as the system resolves it) longer than :data:`MAX_PATH_BYTES`: before anything asks
    the system about it (``Path.exists`` raises ENAMETOOLONG, an internal error, where it says "no" to others)."""
    path = Path(path)
    for name in path.parts:
        if len(os.fsencode(name)) > 255:
            raise InputError(f"{str(path)[:48]}...: a name of {len(os.fsencode(name))} bytes in the output path; "
                             "file systems take at most 255")
    whole = len(os.fsencode(os.path.abspath(path)))
    if whole > MAX_PATH_BYTES:
        raise InputError(f"{str(path)[:48]}...: an output path of {whole:,} bytes; the system takes at most "
                         f"{MAX_PATH_BYTES:,}")
    return path


def _check_regular(path: Path) -> None:
    """InputError when something other than a regular file is at output `path` (a device, a pipe, a
    socket): outputs are written beside and renamed into place, which would replace it."""
    if path.exists() and not path.is_dir() and not path.is_file():
        raise InputError(f"{path}: not a regular file (a device or a pipe?); outputs are files: choose another path")


def check_not_dangling(path: str | Path) -> None:
    """InputError when output `path` is a symbolic link to nothing: no folder can be made there, and a file
    written there would replace the link (say so before the work, not "cannot create ... (File exists)"); a link
    of a loop is named as such (:func:`why_missing`), not as a link to a target that "does not exist"."""
    path = Path(path)
    if path.is_symlink() and not path.exists():
        why = why_missing(path)
        if why.startswith(": a symbolic link loop"):  # (its target exists: "make its target first" cannot be done)
            raise InputError(f"{path}{why}; remove a link of the loop, or choose another output")
        raise InputError(f"{path}: a symbolic link to {os.readlink(path)}, which does not exist; make its target "
                         "first, or remove the link, or choose another output")


def check_output_file(path: str | Path, force: bool = True, *, writable: str | None = None) -> Path:
    """Before the work: InputError when output file `path` is a folder or not a regular file, or
    exists and `force` is off (nothing written before is replaced unless asked: :data:`FORCE`), or
    has a name too long; with `writable` (the option, ``--json``), also when no file can be made in its
    folder (missing, no permission: :func:`check_writable_folder`): an output written after the work."""
    path = Path(path)
    check_output_name(path)
    check_not_dangling(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give the output's file name")
    _check_regular(path)
    if path.exists() and not force:
        raise InputError(f"{path}: exists; pass {FORCE} to replace it, or choose another output")
    if writable:
        check_writable_folder(path.resolve().parent, f"{writable} {path}")
    return path


def check_not_an_input(path, inputs, option: str, choose: str = "another file") -> None:
    """InputError when output file `path` (of `option`, ``--json``) is one of a command's inputs, or an existing file
    inside one of its input folders: `inputs` holds (path, what it is: ``the dataset (--data)``) pairs, None paths
    skipped. Whatever ``--force`` says, the results are never written over what the command reads (``evaluate --json
    ds/dataset.json`` replaced the description of the dataset it had just evaluated, which no command read again).
    `choose`: what the message advises instead (``another --out`` for a file of an output folder)."""
    target = Path(path)
    if not target.is_file():
        return  # (a new file, even inside an input folder, replaces nothing; a folder is refused as no file)
    for given, what in inputs:
        if given is None or not Path(given).exists():
            continue
        source = Path(given)
        inside = source.is_dir() and os.path.realpath(target).startswith(os.path.realpath(source) + os.sep)
        if inside or os.path.samefile(target, source):
            where = f"a file of {what} {given}" if inside else f"{what} {given}"
            raise InputError(f"{option} {path}: is {where}, which this command reads; writing its results there "
                             f"would destroy it: choose {choose}")


def check_output_folder(path: str | Path, force: bool = False) -> Path:
    """Before the work: InputError when output folder `path` is a file or lies under one, or cannot be
    made or written in (:func:`check_writable_folder` where it is or will be made), or
    already holds files and `force` is off (a command's earlier outputs are not replaced unless
    asked: :data:`FORCE`; the lock of :func:`claim_output_folder` is no output), or has a name too long."""
    path = Path(path)
    check_output_name(path)
    check_not_dangling(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{path}: output path exists and is not a folder")
    blocking = next((parent for parent in path.parents if parent.exists() and not parent.is_dir()), None)
    if blocking is not None:
        raise InputError(f"{path}: cannot create the output folder: {blocking} is a file")
    # where the folder is (or will be) made: a file must be creatable there (not /proc, not read-only)
    check_writable_folder(next(folder for folder in (path, *path.parents) if folder.exists()), str(path))
    if path.is_dir() and not force and any(entry.name != LOCK_NAME for entry in path.iterdir()):
        raise InputError(f"{path}: folder already holds files (earlier outputs?); pass {FORCE} to write over "
                         f"them, or choose another --out")
    return path


def check_output_files(folder: str | Path, names, inputs=()) -> None:
    """Before the work: InputError when something other than a regular file stands where one of the files
    `names` that a run writes in output folder `folder` goes (a folder named ``metrics.json``: the run was
    refused after its work, when it wrote its results; a symbolic link to nothing, which the file written
    would replace: :func:`check_not_dangling`), or when one of them is one of the run's `inputs` ((path, what)
    pairs: :func:`check_not_an_input`; ``render 'floorplan:rp/rgb.png' --out rp --force`` replaced the plan it
    rendered by the picture, ``predict --image pp/input.png --out pp --force`` the photo by its resized copy)."""
    for name in names:
        path = Path(folder) / name
        check_not_dangling(path)
        if path.is_dir():
            raise InputError(f"{path}: a folder is where the run writes its {name}; remove it, or choose another --out")
        _check_regular(path)
        check_not_an_input(path, inputs, "--out", "another --out")


LOCK_NAME = ".frontiernet.lock"
"""The lock file of :func:`claim_output_folder` in an output folder while a run writes there."""


@contextmanager
def claim_output_folder(path: str | Path, force: bool = False) -> Iterator[Path]:
    """Output folder `path` for one run, for the ``with`` block: checked
    (:func:`check_output_folder`), created, and locked for the block, so that a second run
    started on it meanwhile is refused at once (an exclusive lock on :data:`LOCK_NAME` there,
    held by this process: the system drops it when the process dies). A folder this call
    created is removed when the block fails and left nothing in it (a run refused after its
    setup leaves no empty folder behind).

    Raises:
        InputError: as :func:`check_output_folder`; another run holds the folder.
    """
    import fcntl

    path = check_output_folder(path, force)
    made = [folder for folder in (path, *path.parents) if not folder.exists()]
    ensure_dir(path)
    lock = _lock_file(path)
    while True:
        handle = open(lock, "a+")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            owner = handle.read().strip()
            handle.close()
            raise InputError(in_use_message(path, owner, "--out")) from None
        if lock.exists() and os.path.samestat(os.fstat(handle.fileno()), lock.stat()):
            break
        handle.close()  # the holder ended and removed the file between our open and lock: lock the new one
    try:
        handle.truncate(0)
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        check_output_folder(path, force)  # under the lock: what a run that ended just now wrote counts
        yield path
    except BaseException:
        lock.unlink(missing_ok=True)
        handle.close()
        for folder in made:  # innermost first
            remove_if_empty(folder)
        raise
    lock.unlink(missing_ok=True)
    handle.close()


def _lock_file(folder: Path) -> Path:
    """The path of :data:`LOCK_NAME` in `folder`; InputError naming it when something other than a regular file
    has its name (a folder could not be opened, a pipe would block the open)."""
    lock = folder / LOCK_NAME
    if lock.is_symlink():  # followed, the file it names would be written over with a pid, then the link removed
        raise InputError(f"{lock}: a symbolic link, expected the lock file frontiernet keeps while a run writes "
                         "there; remove it")
    if os.path.lexists(lock) and not lock.is_file():
        raise InputError(f"{lock}: {'is a folder' if lock.is_dir() else 'not a regular file'}, expected the lock "
                         "file frontiernet keeps while a run writes there; remove it")
    return lock


def in_use_message(path: Path, owner: str, option: str) -> str:
    """The refusal of folder `path` while another run holds its lock (`owner`: the pid its lock file names, or
    ''; `option`: how the user names another folder)."""
    return (f"{path}: another run{f' (process {owner})' if owner else ''} is writing there; wait for it to end, "
            f"or choose another {option}")


def check_not_locked(path: str | Path, option: str = "--out") -> None:
    """InputError naming folder `path` while another process holds the lock :func:`claim_output_folder` takes
    there (a probe: this process takes it and lets go at once, and never creates the lock file). For the checks
    a command makes before it claims the folder: a run in progress there has written some files already,
    which would otherwise read as an earlier run's."""
    import fcntl

    try:
        handle = open(_lock_file(Path(path)))
    except OSError:  # no lock file: no run there (or not one this can read)
        return
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise InputError(in_use_message(Path(path), handle.read().strip(), option)) from None
        fcntl.flock(handle, fcntl.LOCK_UN)


def remove_if_empty(folder: str | Path) -> None:
    """Remove `folder` when no file lies anywhere under it (what a run stopped by bad input left)."""
    import shutil

    folder = Path(folder)
    if folder.is_dir() and not any(path.is_file() for path in folder.rglob("*")):
        shutil.rmtree(folder, ignore_errors=True)


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary file beside `path` for the ``with`` block to write; renamed into place when the
    block ends, removed when it raises (`path` is then left as it was).

    ``with atomic_path(out / "figure.png") as tmp: figure.savefig(tmp, format="png")``. For a
    writer that needs a file name; :func:`write_bytes` and :func:`write_text` write data.

    Raises:
        InputError: a folder in the way, something other than a file there (a device such as
            /dev/full, a pipe: the rename would replace it), or a folder that cannot be written
            (missing, no permission).
    """
    path = Path(path)
    if path.is_dir():  # os.replace would fail after the work, with a traceback
        raise InputError(f"{path}: cannot write, a folder is in the way")
    _check_regular(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as error:  # a missing folder, a file where the folder should be, no permission
        raise InputError(f"{path}: cannot write ({error.strerror})") from None
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file normal permissions
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write `data` to `path` atomically (:func:`atomic_path`); returns `path`."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    """Write `text` (UTF-8) to `path` atomically (:func:`atomic_path`); returns `path`."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path: str | Path, data) -> Path:
    return write_text(path, json.dumps(data, indent=2) + "\n")


def write_npy(path: str | Path, array: np.ndarray) -> Path:
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        np.save(handle, array)
    return Path(path)


def check_image_name(path: str | Path) -> None:
    """InputError unless `path`'s suffix names an image format OpenCV writes (.png, .jpg, ...)."""
    import cv2

    if not cv2.haveImageWriter(str(path)):
        raise InputError(f"{path}: not an image file name OpenCV can write (use .png or .jpg)")


def write_image(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an (H, W, 3) uint8 RGB image (format from the suffix, e.g. .png)."""
    import cv2

    check_image_name(path)

    ok, data = cv2.imencode(Path(path).suffix, np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise InputError(f"{path}: cannot encode image")
    return write_bytes(path, data.tobytes())


def colorize_depth(depth: np.ndarray, max_depth: float) -> np.ndarray:
    """(H, W) float metres (NaN invalid) -> (H, W, 3) uint8 turbo colour image, invalid black."""
    import cv2

    valid = np.isfinite(depth)
    scaled = np.zeros(depth.shape, np.uint8)
    scaled[valid] = (np.clip(depth[valid] / max_depth, 0, 1) * 255).astype(np.uint8)
    colored = cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO)[..., ::-1].copy()
    colored[~valid] = 0
    return colored
