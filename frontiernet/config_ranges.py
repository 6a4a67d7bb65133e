"""Declared ranges of config values: ``configs/ranges/<name>.yaml`` says what each key of
``configs/<name>.yaml`` may be; :func:`frontiernet.config.check_ranges` (called by
:func:`~frontiernet.config.merge_user`) refuses a merged config with a value outside, naming the
key, up front (before a command sets anything up).

A declaration maps a dotted key to a spec. A YAML list is the choices of a text key
(``map.invalid_depth: [free, skip]``; a null among them: null is taken); a string is a range of numbers::

    "(0, inf)"                  a number > 0
    "int [1, inf)"              an integer >= 1
    "[0, 1] or null"            a number in [0, 1], or null (the key's rule is off)
    "int [0, 256] or auto"      an integer in [0, 256], or the text auto
    "pair [-inf, inf]"          a [min, max] pair with min <= max
    "box [-50, 50]"             a [[min x, y, z], [max x, y, z]] box with min < max on each axis
    "list [0, inf)"             a list of numbers >= 0 (any length; "list length 3 ...": three)
    "increasing list int [1, inf)"  ... in strictly increasing order

Brackets are inclusive, parentheses exclusive, ``inf`` unbounded. Composite configs (a run's
config holds ``sim`` and ``scenes`` as sections) say where each file's keys sit with a *layout*,
``{"": "explore", "scenes": "scenes", "ground_truth": "datagen.ground_truth"}``: a section prefix
of the composite, then the file, or the file and its section, whose declarations apply there.
"""

from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Mapping, Sequence

from .errors import InputError

_INTERVAL = re.compile(r"^(?P<words>[a-z0-9 ]*?)\s*(?P<open>[\[(])\s*(?P<low>[^,\s]+)\s*,\s*(?P<high>[^\])\s]+)\s*"
                       r"(?P<close>[\])])(?P<alternatives>(\s+or\s+[\w-]+)*)$")
_SHAPES = ("pair", "box", "list", "increasing", "length", "int")

Layout = Mapping[str, str | Sequence[str]]
"""Where a composite config's shipped files sit: section prefix ("" for the top) -> file name(s) or
``file.section`` (module docstring)."""


@dataclass(frozen=True)
class Range:
    """One declared spec: numbers in an interval (with `numbers`), and/or one of the words `texts`."""

    low: float = -math.inf
    high: float = math.inf
    low_closed: bool = True
    high_closed: bool = True
    integer: bool = False
    shape: str = "value"  # value | pair | box | list
    length: int | None = None  # a list's required length
    increasing: bool = False
    nullable: bool = False
    numbers: bool = True
    texts: tuple[str, ...] = ()

    def describe(self) -> str:
        """What a value must be, as the message says it: ``an integer >= 1``, ``one of free, skip``."""
        if not self.numbers:
            return "one of " + ", ".join(self.texts) + (" (or null)" if self.nullable else "")
        kind = "integer" if self.integer else "number"
        if math.isinf(self.low) and math.isinf(self.high):
            bound = ""
        elif math.isinf(self.high):
            bound = f" {'>=' if self.low_closed else '>'} {_number(self.low)}"
        elif math.isinf(self.low):
            bound = f" {'<=' if self.high_closed else '<'} {_number(self.high)}"
        else:
            bound = f" in {'[' if self.low_closed else '('}{_number(self.low)}, {_number(self.high)}" \
                    f"{']' if self.high_closed else ')'}"
        if self.shape == "pair":
            text = f"a [min, max] pair of {kind}s{bound} with min <= max"
        elif self.shape == "box":
            text = f"a [[min x, y, z], [max x, y, z]] box of {kind}s{bound} with min < max on each axis"
        elif self.shape == "list":
            size = f"{self.length} " if self.length is not None else ""
            text = f"a list of {size}{kind}s{bound}" + (" in increasing order" if self.increasing else "")
        else:
            text = f"a{'n' if kind == 'integer' else ''} {kind}{bound}"
        others = self.texts + (("null",) if self.nullable else ())
        return text + (f" (or {' or '.join(others)})" if others else "")

    def admits(self, value) -> bool:
        """Whether `value` (a plain value: number, str, list, None) is in this range."""
        if value is None:
            return self.nullable
        if isinstance(value, str):
            return value in self.texts
        if not self.numbers:
            return False
        if self.shape == "value":
            return self._admits_number(value)
        if self.shape == "box":
            corners = value if isinstance(value, (list, tuple)) and len(value) == 2 else None
            return corners is not None and all(isinstance(c, (list, tuple)) and len(c) == 3 and
                                               all(self._admits_number(v) for v in c) for c in corners) \
                and all(low < high for low, high in zip(*corners))
        if not isinstance(value, (list, tuple)) or not all(self._admits_number(item) for item in value):
            return False
        if self.shape == "pair":
            return len(value) == 2 and value[0] <= value[1]
        if self.length is not None and len(value) != self.length:
            return False
        return not self.increasing or all(a < b for a, b in zip(value, value[1:]))

    def _admits_number(self, value) -> bool:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return False
        if self.integer and not isinstance(value, numbers.Integral):
            return False
        if not math.isfinite(value):
            return False
        above = value >= self.low if self.low_closed else value > self.low
        below = value <= self.high if self.high_closed else value < self.high
        return above and below


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else str(value)


def parse_range(spec, where: str) -> Range:
    """The :class:`Range` of declaration `spec` (module docstring); `where` names it in the error
    (a malformed declaration is the library's bug, but say which)."""
    if isinstance(spec, list):
        texts = tuple(item for item in spec if item is not None)
        if not texts or not all(isinstance(item, str) for item in texts):
            raise ValueError(f"{where}: choices must be a list of text (and null), got {spec!r}")
        return Range(numbers=False, texts=texts, nullable=None in spec)
    match = _INTERVAL.match(str(spec).strip())
    if match is None:
        raise ValueError(f"{where}: not a range spec: {spec!r}")
    words = match["words"].split()
    length = None
    if "length" in words:
        at = words.index("length")
        length = int(words.pop(at + 1)) if at + 1 < len(words) and words[at + 1].isdigit() else None
        if length is None:
            raise ValueError(f"{where}: 'length' needs a number: {spec!r}")
    if any(word not in _SHAPES for word in words):
        raise ValueError(f"{where}: unknown word in {spec!r} (known: {', '.join(_SHAPES)})")
    alternatives = match["alternatives"].split()[1::2]  # "or auto or null" -> auto, null
    shape = "pair" if "pair" in words else "box" if "box" in words else "list" if ("list" in words or length is not None) else "value"
    return Range(low=float(match["low"]), high=float(match["high"]), low_closed=match["open"] == "[",
                 high_closed=match["close"] == "]", integer="int" in words, shape=shape, length=length,
                 increasing="increasing" in words, nullable="null" in alternatives,
                 texts=tuple(word for word in alternatives if word != "null"))


def ranges_folder() -> Path:
    """``configs/ranges``, as installed."""
    return Path(str(resources.files("frontiernet.configs").joinpath("ranges")))


@lru_cache(maxsize=None)
def declared(name: str) -> dict[str, Range]:
    """The declarations of ``configs/ranges/<name>.yaml``: dotted key of ``configs/<name>.yaml``
    -> :class:`Range`; empty when the file does not exist."""
    import yaml

    path = ranges_folder() / f"{name}.yaml"
    if not path.is_file():
        return {}
    table = yaml.safe_load(path.read_text()) or {}
    return {str(key): parse_range(spec, f"{path}: {key}") for key, spec in table.items()}


def layout_ranges(layout: Layout) -> dict[str, Range]:
    """Dotted key of a composite config -> its :class:`Range`, for a `layout` (module docstring):
    each prefix's files in order, a later file's declaration of a key winning."""
    out: dict[str, Range] = {}
    for prefix, sources in layout.items():
        for source in [sources] if isinstance(sources, str) else sources:
            name, _, section = source.partition(".")
            start = f"{section}." if section else ""
            for key, spec in declared(name).items():
                if key.startswith(start):
                    rest = key[len(start):]
                    out[f"{prefix}.{rest}" if prefix else rest] = spec
    return out
