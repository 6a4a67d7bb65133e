"""The one error type for bad user input, and the checks that raise it.

The CLI turns an :class:`InputError` into a single line on stderr and exit code 2,
with no traceback. Library code raises it whenever a file, value or spec given by
the user is wrong, and names that input in the message. The checks here are the shared
ones: numbers (:func:`positive_number`, :func:`number_range`, :func:`whole_number`,
:func:`cpu_count_option`, :func:`check_seed`) and keys
(:func:`check_keys`, for config files, overrides and scene-spec options alike).
"""

from __future__ import annotations

import math
from typing import Mapping


class InputError(ValueError):
    """Bad user input: a missing or corrupt file, an unsupported format, a bad value."""


def setting_text(value) -> str:
    """A setting's value as a message names it: repr, with None written as a config file writes it,
    ``null`` (Python's ``None`` is no value a user gives: ``run.seed=~`` said "got None"), inside lists and
    dicts too."""
    if value is None:
        return "null"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(setting_text(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key!r}: {setting_text(item)}" for key, item in value.items()) + "}"
    return repr(value)


def decode_problem(error: BaseException) -> str:
    """What is wrong with a file's text that a JSON or text read refused, in words (no exception's class name):
    ``not UTF-8 text (byte 0xff at offset 0; a UTF-16 file? save it as UTF-8)``, ``not valid JSON at line 1
    column 2 (Unterminated string starting at)``, ``a damaged or cut-short zip archive`` (a zip member's read: the
    archive's, zlib's or an early end); for any other error its first line, or ``unreadable``."""
    import json
    import zipfile
    import zlib

    if isinstance(error, UnicodeDecodeError):
        data = bytes(error.object) if isinstance(error.object, (bytes, bytearray, memoryview)) else b""
        bad = data[error.start:error.start + 1].hex() or "?"
        utf16 = data[:2] in (b"\xff\xfe", b"\xfe\xff")
        return (f"not UTF-8 text (byte 0x{bad} at offset {error.start}"
                + ("; a UTF-16 file? save it as UTF-8)" if utf16 else ")"))
    if isinstance(error, json.JSONDecodeError):
        return f"not valid JSON at line {error.lineno} column {error.colno} ({error.msg})"
    if isinstance(error, (zipfile.BadZipFile, zlib.error, EOFError)):
        return "a damaged or cut-short zip archive"
    if isinstance(error, OSError) and error.strerror:
        return error.strerror
    text = (str(error).strip().splitlines() or [""])[0]
    return text or "unreadable"


def positive_number(value, name: str, unit: str = "", *, allow_zero: bool = False) -> float:
    """`value` as a float if it is a finite number > 0 (>= 0 with `allow_zero`).

    Otherwise raise :class:`InputError` naming `name`, e.g. ``"voxels.voxel_size must be a
    positive number of metres, got -1"``.
    """
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
        and (value >= 0 if allow_zero else value > 0)
    if not ok:
        kind = "non-negative" if allow_zero else "positive"
        raise InputError(f"{name} must be a {kind} number{' of ' + unit if unit else ''}, got {setting_text(value)}")
    return float(value)


def fraction_or_null(value, name: str) -> float | None:
    """`value` as a float in (0, 1], or None when it is None (a key whose null keeps the rule from
    before it); otherwise InputError naming ``<name> (or null)``."""
    if value is None:
        return None
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)):
        raise InputError(f"{name} (or null) must be a finite number, got {setting_text(value)}")
    if not 0.0 < value <= 1.0:
        raise InputError(f"{name} must be in (0, 1] (or null), got {float(value)}")
    return float(value)


def number_range(value, name: str, lower: float = -math.inf, upper: float = math.inf) -> tuple[float, float]:
    """`value` as a ``(min, max)`` pair of finite floats with ``lower <= min <= max <= upper``.

    Otherwise raise :class:`InputError` naming `name`, e.g. ``"poses.height_range_m must
    satisfy 0.0 <= min <= max, got [2.0, 1.0]"``.
    """
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a [min, max] pair of numbers, got {setting_text(value)}") from None
    if not (math.isfinite(low) and math.isfinite(high) and lower <= low <= high <= upper):
        bound = f" <= {upper}" if math.isfinite(upper) else ""
        raise InputError(f"{name} must satisfy {lower} <= min <= max{bound}, got {[low, high]}")
    return low, high


def whole_number(value, name: str, minimum: int = 0, maximum: float = math.inf) -> int:
    """`value` as an int if it is an integer (not a bool) with ``minimum <= value <= maximum``.

    Otherwise raise :class:`InputError` naming `name`, e.g. ``"--seed must be an integer >= 0, got -1"``.
    """
    import numbers

    ok = isinstance(value, numbers.Integral) and not isinstance(value, bool) and minimum <= value <= maximum
    if not ok:
        bound = f">= {minimum}" if maximum == math.inf else f"in [{minimum}, {maximum}]"
        raise InputError(f"{name} must be an integer {bound}, got {setting_text(value)}")
    return int(value)


MAX_SEED = 2**32 - 1
"""The largest seed a command takes (``--seed``, ``run.seed``, ``seed``): numpy's seeding (``np.random.seed``,
``RandomState``) and Lightning's ``seed_everything`` take 0 to 2**32 - 1 (``default_rng``, which draws the
poses, takes any size; a seed past this range is a typo). ``configs/ranges/*.yaml`` declare the same range."""


def check_seed(value, name: str, repeats: int = 1) -> int:
    """`value` as an int seed in [0, :data:`MAX_SEED`]; with `repeats` (runs seeded ``seed .. seed + repeats -
    1``: ``bench --repeats``) the last one too. Otherwise InputError naming `name`, e.g. ``"--seed must be an
    integer in [0, 4294967295], got 100000000000000000000 (numpy's seed range)"``."""
    try:
        return whole_number(value, name, 0, MAX_SEED - (max(int(repeats), 1) - 1))
    except InputError as error:
        last = f"; the runs' seeds are --seed to --seed + {int(repeats) - 1} (--repeats {int(repeats)})" \
            if repeats > 1 else ""
        raise InputError(f"{error} (numpy's seed range{last})") from None


PER_CORE = 4
"""At most this many threads or local worker processes per core of the machine (:func:`cpu_count_option`):
more only slows a run, and a huge count crashes the libraries that start them (torch)."""


def cpu_count_option(value, name: str, minimum: int = 1) -> int:
    """`value` (threads, local worker processes) as an int in [`minimum`, :data:`PER_CORE` x this
    machine's cores]; otherwise InputError naming `name`, e.g. ``"--threads must be an integer in
    [1, 8] (at most 4 per core of this machine), got 99999"``."""
    import os

    most = PER_CORE * (os.cpu_count() or 1)
    try:
        return whole_number(value, name, minimum, most)
    except InputError as error:
        raise InputError(f"{error} (at most {PER_CORE} per core of this machine)") from None


def _kind(value) -> str | None:
    """What a config value is, as far as a user's value must match the default's: a section, a
    list, a number or a true/false; None (anything goes) for text, null and open sections."""
    if isinstance(value, dict):
        return "a section (key: value lines)" if value else None
    if isinstance(value, list):
        return "a list"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, (int, float)):
        return "a number"
    return None


def check_keys(base: Mapping, extra: Mapping, source: str, noun: str = "config key") -> None:
    """InputError naming the first key of `extra` that `base` lacks, with its closest spellings
    (else the valid keys there), or whose value is of another kind than the default's
    (:func:`_kind`; null is taken, except for a section: a default that is a non-empty mapping).
    `source` (a file, "override", a scene spec) starts the message; `noun` names what a key is to the
    user ("config key", "option")."""
    from difflib import get_close_matches

    def deeper(tree: dict, prefix: str):  # every dotted key below `tree`
        for key, value in tree.items():
            yield f"{prefix}{key}"
            if isinstance(value, dict):
                yield from deeper(value, f"{prefix}{key}.")

    def walk(defaults, given, prefix: str):
        for key, value in given.items():
            name = f"{prefix}{key}"
            if key not in defaults:
                nested = [path for path in deeper(defaults, prefix) if path.rsplit(".", 1)[-1] == str(key)]
                close = nested or [prefix + k for k in get_close_matches(str(key), [str(k) for k in defaults], n=3)]
                hint = (f"; did you mean {', '.join(close[:3])}?" if close
                        else f"; valid: {', '.join(prefix + str(k) for k in defaults)}")
                raise InputError(f"{source}: unknown {noun} '{name}'{hint}")
            default = defaults[key]
            expected = _kind(default)
            if value is None and isinstance(default, dict) and default:  # a section, not an optional value
                keys = ", ".join(str(k) for k in list(default)[:4]) + (", ..." if len(default) > 4 else "")
                raise InputError(f"{source}: {noun} '{name}' is a section (its keys: {keys}), "
                                 "not a value that can be null")
            if value is not None and expected is not None and _kind(value) != expected:
                shown = "" if isinstance(default, dict) else f" (default {setting_text(default)})"
                raise InputError(f"{source}: {noun} '{name}' takes {expected}{shown}, got {setting_text(value)}")
            if isinstance(value, dict) and isinstance(default, dict) and default:
                walk(default, value, f"{name}.")

    def plain(tree):
        from omegaconf import DictConfig, OmegaConf

        return OmegaConf.to_container(tree, resolve=False) if isinstance(tree, DictConfig) else dict(tree)

    walk(plain(base), plain(extra), "")
