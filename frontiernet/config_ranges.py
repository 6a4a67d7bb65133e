"""Declared ranges of config values: ``configs/ranges/<name>.yaml`` says what each key of
``configs/<name>.yaml`` may be; :func:`frontiernet.config.check_ranges` (called by
:func:`~frontiernet.config.merge_user`) refuses a merged config with a value outside, naming the
key, up front (before a command sets anything up).

A declaration maps a dotted key to a spec. A YAML list is the choices of a text key
(``map.invalid_depth: [free, skip]``; a null among them: null is taken), or of an integer key (``[6, 26]``: those
integers alone); a string is a range of numbers::

    "(0, inf)"                  a number > 0
    "int [1, inf)"              an integer >= 1
    "[0, 1] or null"            a number in [0, 1], or null (the key's rule is off)
    "int [0, 256] or auto"      an integer in [0, 256], or the text auto
    "pair [-inf, inf]"          a [min, max] pair with min <= max
    "box [-50, 50]"             a [[min x, y, z], [max x, y, z]] box with min < max on each axis
    "list [0, inf)"             a list of numbers >= 0 (any length; "list length 3 ...": three)
    "increasing list int [1, inf)"  ... in strictly increasing order
    "bool"                      true or false ("bool or null", "bool or auto": also those)

Brackets are inclusive, parentheses exclusive, ``inf`` unbounded.

A key holding a comparison declares a *relation* between keys, its value the reason the message gives::

    "map.log_odds_min <= map.occupied_threshold < map.log_odds_max": the clamped log-odds reach both sides
    "labels.num_classes == len(labels.bin_edges)": one class a bin edge
    "procedural.l_shape_probability + procedural.u_shape_probability <= 1": the rest is a rectangle
    "map.max_range_m <= sim:camera.max_depth": rays beyond the sensor's range
    "tracking.height_window_m[0] <= 0 <= tracking.height_window_m[1]": the window holds the camera's height

A chain of ``<``, ``<=``, ``==``, ``>=``, ``>`` between terms, each a sum (``+``) of products (``*``, and
``/`` by a factor: ``a * 360 / b`` is ``a * (360 / b)``; a zero divisor leaves the relation unchecked, the key's
own range refuses it) of numbers, keys of the file, ``len(key)``, ``key[i]`` (item i of a list key: a pair's min
``[0]``, max ``[1]``) and ``file:key`` (a key of another shipped file: the relation holds where the layout holds
both). A relation with a null or absent key is not checked (null turns a rule off). Composite configs (a run's
config holds ``sim`` and ``scenes`` as sections) say where each file's keys sit with a *layout*,
``{"": "explore", "scenes": "scenes", "ground_truth": "datagen.ground_truth"}``: a section prefix
of the composite, then the file, or the file and its section, whose declarations apply there.
"""

from __future__ import annotations

import math
import numbers
import operator
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
_BOOLEAN = re.compile(r"^bool(?P<alternatives>(\s+or\s+[\w-]+)*)$")
_COMPARISON = re.compile(r"\s+(<=|>=|==|<|>)\s+")
_OPERATORS = {"<": operator.lt, "<=": operator.le, "==": operator.eq, ">=": operator.ge, ">": operator.gt}
_LENGTH = re.compile(r"^len\((?P<key>[\w.:]+)\)$")
_ITEM = re.compile(r"^(?P<key>[\w.:]+)\[(?P<index>\d+)\]$")
_PRODUCT = re.compile(r" ([*/]) ")

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
    shape: str = "value"  # value | pair | box | list | bool
    length: int | None = None  # a list's required length
    increasing: bool = False
    nullable: bool = False
    numbers: bool = True
    texts: tuple[str, ...] = ()
    choices: tuple[int, ...] = ()  # an integer key's values (declared as a list of them); () any in the interval

    def describe(self) -> str:
        """What a value must be, as the message says it: ``an integer >= 1``, ``one of free, skip``."""
        others = self.texts + (("null",) if self.nullable else ())
        if self.choices:
            return "one of " + ", ".join(map(str, self.choices)) + (" (or null)" if self.nullable else "")
        if self.shape == "bool":
            return "true or false" + (f" (or {' or '.join(others)})" if others else "")
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
        return text + (f" (or {' or '.join(others)})" if others else "")

    def admits(self, value) -> bool:
        """Whether `value` (a plain value: number, str, list, None) is in this range."""
        if value is None:
            return self.nullable
        if isinstance(value, str):
            return value in self.texts
        if self.shape == "bool":
            return isinstance(value, bool)
        if not self.numbers:
            return False
        if self.choices:
            return isinstance(value, numbers.Integral) and not isinstance(value, bool) and value in self.choices
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
        if beyond_int64(value):
            return False  # (a float of it would overflow; numpy's int64 does too)
        if not math.isfinite(value) or (not self.integer and beyond_float32(value)):
            return False
        above = value >= self.low if self.low_closed else value > self.low
        below = value <= self.high if self.high_closed else value < self.high
        return above and below


FLOAT32_MAX = 3.4028234663852886e38
FLOAT32_TINY = 1.1754943508222875e-38
"""The largest finite and the smallest normal magnitude of a 32-bit float (``np.finfo(np.float32)``):
a number key's values are computed in float32 (depth, poses, rays, network inputs), where a larger one
overflows to inf and a smaller nonzero one is lost to 0, so such a value is refused up front."""


INT64_LIMIT = 2 ** 63
"""Integers are computed in int64 (numpy's): one of this magnitude or more is refused up front."""


def beyond_float32(value) -> bool:
    """Whether number `value` (a plain int or float) overflows float32 or is a nonzero below its
    smallest normal magnitude (:data:`FLOAT32_MAX`, :data:`FLOAT32_TINY`)."""
    magnitude = abs(value)
    return magnitude > FLOAT32_MAX or 0.0 < magnitude < FLOAT32_TINY


def beyond_int64(value) -> bool:
    """Whether plain integer `value` is outside numpy's int64 (:data:`INT64_LIMIT`)."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool) and abs(value) >= INT64_LIMIT


def magnitude_note(value, integer: bool = False) -> str:
    """What a range message adds where `value` (a number or a nested list of them) is refused for its
    size alone, as it may lie inside the declared interval (``1e300`` for ``(0, inf)``): ``: not a finite
    number ...`` for infinity or NaN (YAML reads ``1e400`` as infinity: ``got inf`` alone read as if inf
    were below the bound), ``: beyond the 32-bit floats ...`` for a number key (:func:`beyond_float32`),
    ``: beyond the 64-bit integers ...`` for an integer key (`integer`, :func:`beyond_int64`); else ``""``."""
    items = value if isinstance(value, (list, tuple)) else [value]
    flat = [v for item in items for v in (item if isinstance(item, (list, tuple)) else [item])
            if isinstance(v, numbers.Real) and not isinstance(v, bool)]
    floats = [v for v in flat if not isinstance(v, numbers.Integral)]  # (a huge int is no float: isnan overflows)
    if any(math.isnan(v) for v in floats):
        return ": not a number (NaN)"
    if any(math.isinf(v) for v in floats):
        return ": not a finite number (a number past 1.8e308, such as 1e400, overflows a float to infinity)"
    if integer:
        return ": beyond the 64-bit integers it is computed in (magnitudes below 2**63)" \
            if any(beyond_int64(v) for v in flat) else ""
    if any((isinstance(v, numbers.Integral) or math.isfinite(v)) and beyond_float32(v) for v in flat):
        return ": beyond the 32-bit floats it is computed in (magnitudes up to 3.4e38, and at least 1.2e-38 unless 0)"
    return ""


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() and abs(value) < 1e16 else str(value)


def parse_range(spec, where: str) -> Range:
    """The :class:`Range` of declaration `spec` (module docstring); `where` names it in the error
    (a malformed declaration is the library's bug, but say which)."""
    if isinstance(spec, list):
        texts = tuple(item for item in spec if item is not None)
        if texts and all(isinstance(item, int) and not isinstance(item, bool) for item in texts):
            return Range(integer=True, choices=texts, nullable=None in spec)
        if not texts or not all(isinstance(item, str) for item in texts):
            raise ValueError(f"{where}: choices must be a list of text or of integers (and null), got {spec!r}")
        return Range(numbers=False, texts=texts, nullable=None in spec)
    boolean = _BOOLEAN.match(str(spec).strip())
    if boolean is not None:
        alternatives = boolean["alternatives"].split()[1::2]
        return Range(shape="bool", numbers=False, nullable="null" in alternatives,
                     texts=tuple(word for word in alternatives if word != "null"))
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


@dataclass(frozen=True)
class Relation:
    """A declared relation (module docstring): ``terms[0] operators[0] terms[1] ...``, each term a sum of
    parts, each a product (``" * "``, ``" / "``) of factors (a number text, a dotted key, ``len(key)``); `reason` is
    what the message says it is for."""

    terms: tuple[tuple[str, ...], ...]
    operators: tuple[str, ...]
    reason: str

    def keys(self) -> list[str]:
        """The dotted keys the relation reads, in order."""
        return [key for term in self.terms for part in term for _, factor in _factors(part)
                if (key := _factor_key(factor)) is not None]

    def renamed(self, names: Mapping[str, str]) -> "Relation":
        """The relation with each key renamed by `names` (a file's key -> the composite config's)."""
        def rename(factor: str) -> str:
            key = _factor_key(factor)
            return factor if key is None else factor.replace(key, names[key])
        def product(part: str) -> str:
            return "".join((f" {op} " if at else "") + rename(factor) for at, (op, factor) in enumerate(_factors(part)))
        return Relation(tuple(tuple(product(part) for part in term) for term in self.terms), self.operators,
                        self.reason)

    def text(self) -> str:
        terms = [" + ".join(term) for term in self.terms]
        return " ".join(item for pair in zip(terms, self.operators + ("",)) for item in pair).strip()

    def sums(self, values: Mapping[str, object]) -> list[float] | None:
        """Each term's value for `values` (key -> plain value); None when a key is absent or null, a value
        no number (its own range refuses that) or a divisor 0."""
        sums = []
        for term in self.terms:
            total = 0.0
            for part in term:
                product = 1.0
                for op, factor in _factors(part):
                    value = _factor_value(factor, values)
                    if value is None or (op == "/" and value == 0):
                        return None
                    product = product / value if op == "/" else product * value
                total += product
            sums.append(total)
        return sums

    def holds(self, values: Mapping[str, object]) -> bool | None:
        """Whether the relation holds for `values` (key -> plain value); None where :meth:`sums` is."""
        sums = self.sums(values)
        if sums is None:
            return None
        return all(_OPERATORS[op](a, b) for op, a, b in zip(self.operators, sums, sums[1:]))

    def broken(self, values: Mapping[str, object]) -> str:
        """The first comparison that fails for `values` as the numbers compared (``"228,757,340,160 > 10,000,000"``)
        where a term computes something (a sum or product: the keys' values alone do not show it); else ""."""
        sums = self.sums(values)
        if sums is None or all(len(term) == 1 and len(_factors(term[0])) == 1 for term in self.terms):
            return ""
        for op, a, b in zip(self.operators, sums, sums[1:]):
            if not _OPERATORS[op](a, b):
                return f"{_computed(a)} {_NEGATED[op]} {_computed(b)}"
        return ""


_NEGATED = {"<": ">=", "<=": ">", "==": "!=", ">=": "<", ">": "<="}


def _computed(value: float) -> str:
    """`value` as a message shows a computed number: an integer with thousands separators, else 4 digits."""
    if math.isfinite(value) and abs(value) < 1e15 and abs(value - round(value)) <= 1e-9 * max(1.0, abs(value)):
        return f"{round(value):,}"
    return f"{value:.4g}"


def _factors(part: str) -> list[tuple[str, str]]:
    """The (operator, factor) pairs of a product ``a * b / c``: ``[("*", "a"), ("*", "b"), ("/", "c")]``."""
    pieces = _PRODUCT.split(part)
    return list(zip(["*"] + pieces[1::2], pieces[0::2]))


def _factor_key(factor: str) -> str | None:
    """The key a factor reads (``len(a.b)``, ``a.b[1]``: ``a.b``), None for a number."""
    length = _LENGTH.match(factor) or _ITEM.match(factor)
    if length is not None:
        return length["key"]
    try:
        float(factor)
    except ValueError:
        return factor
    return None


def _factor_value(factor: str, values: Mapping[str, object]) -> float | None:
    key = _factor_key(factor)
    if key is None:
        return float(factor)
    value = values.get(key)
    if _LENGTH.match(factor):
        return float(len(value)) if isinstance(value, (list, tuple)) else None
    item = _ITEM.match(factor)
    if item is not None:  # (a list too short, or no list: its own range says so)
        index = int(item["index"])
        value = value[index] if isinstance(value, (list, tuple)) and index < len(value) else None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    return float(value)


def parse_relation(text: str, reason, where: str) -> Relation:
    """The :class:`Relation` declared as key `text` with value `reason` (module docstring)."""
    pieces = _COMPARISON.split(text.strip())
    terms = tuple(tuple(part.strip() for part in term.split(" + ")) for term in pieces[0::2])
    if len(pieces) < 3 or any(not factor or " " in factor for term in terms for part in term
                              for _, factor in _factors(part)):
        raise ValueError(f"{where}: not a relation: {text!r}")
    if not isinstance(reason, str) or not reason.strip():
        raise ValueError(f"{where}: a relation's value says what it is for, got {reason!r}")
    return Relation(terms, tuple(pieces[1::2]), reason.strip())


@lru_cache(maxsize=None)
def _declarations(name: str) -> tuple[dict[str, Range], tuple[Relation, ...]]:
    import yaml

    path = ranges_folder() / f"{name}.yaml"
    if not path.is_file():
        return {}, ()
    table = yaml.safe_load(path.read_text()) or {}
    relations = tuple(parse_relation(str(key), value, f"{path}: {key}") for key, value in table.items()
                      if _COMPARISON.search(str(key)))
    ranges = {str(key): parse_range(spec, f"{path}: {key}") for key, spec in table.items()
              if not _COMPARISON.search(str(key))}
    return ranges, relations


def declared(name: str) -> dict[str, Range]:
    """The ranges of ``configs/ranges/<name>.yaml``: dotted key of ``configs/<name>.yaml`` ->
    :class:`Range`; empty when the file does not exist."""
    return _declarations(name)[0]


def declared_relations(name: str) -> tuple[Relation, ...]:
    """The relations of ``configs/ranges/<name>.yaml``, in its keys (another file's: ``file:key``)."""
    return _declarations(name)[1]


def _sources(layout: Layout):
    """(prefix, file name, the file's section's key prefix) for each shipped file of `layout`, in order."""
    for prefix, sources in layout.items():
        for source in [sources] if isinstance(sources, str) else sources:
            name, _, section = source.partition(".")
            yield prefix, name, f"{section}." if section else ""


def _composite_key(prefix: str, start: str, key: str) -> str | None:
    """Where `key` of a file whose section `start` (``"map."``, or ``""`` for the whole file) sits at `prefix`
    lands in the composite config; None when the key lies outside that section."""
    if not key.startswith(start):
        return None
    rest = key[len(start):]
    return f"{prefix}.{rest}" if prefix else rest


def _placed(layout: Layout, name: str, key: str) -> str | None:
    """Where key `key` of shipped file `name` sits in a composite config of `layout`; None if nowhere."""
    return next((placed for prefix, source, start in _sources(layout)
                 if source == name and (placed := _composite_key(prefix, start, key)) is not None), None)


def layout_ranges(layout: Layout) -> dict[str, Range]:
    """Dotted key of a composite config -> its :class:`Range`, for a `layout` (module docstring):
    each prefix's files in order, a later file's declaration of a key winning."""
    out: dict[str, Range] = {}
    for prefix, name, start in _sources(layout):
        for key, spec in declared(name).items():
            if (placed := _composite_key(prefix, start, key)) is not None:
                out[placed] = spec
    return out


def layout_relations(layout: Layout) -> list[Relation]:
    """The declared relations of `layout`'s files in the composite config's keys: those whose keys all sit
    in it (a file section's relations of keys outside the section, or of a file the layout lacks, are left out)."""
    out: list[Relation] = []
    for prefix, name, start in _sources(layout):
        for relation in declared_relations(name):
            names = {}
            for key in relation.keys():
                other, colon, other_key = key.partition(":")
                names[key] = _placed(layout, other, other_key) if colon else _composite_key(prefix, start, key)
            if all(names.values()) and (renamed := relation.renamed(names)) not in out:
                out.append(renamed)
    return out
