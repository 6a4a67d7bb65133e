"""The one error type for bad user input.

The CLI turns an :class:`InputError` into a single line on stderr and exit code 2,
with no traceback. Library code raises it whenever a file, value or spec given by
the user is wrong, and names that input in the message.
"""


import math


class InputError(ValueError):
    """Bad user input: a missing or corrupt file, an unsupported format, a bad value."""


def positive_number(value, name: str, unit: str = "", *, allow_zero: bool = False) -> float:
    """`value` as a float if it is a finite number > 0 (>= 0 with `allow_zero`).

    Otherwise raise :class:`InputError` naming `name`, e.g. ``"voxels.voxel_size must be a
    positive number of metres, got -1"``.
    """
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
        and (value >= 0 if allow_zero else value > 0)
    if not ok:
        kind = "non-negative" if allow_zero else "positive"
        raise InputError(f"{name} must be a {kind} number{' of ' + unit if unit else ''}, got {value!r}")
    return float(value)


def number_range(value, name: str, lower: float = -math.inf, upper: float = math.inf) -> tuple[float, float]:
    """`value` as a ``(min, max)`` pair of finite floats with ``lower <= min <= max <= upper``.

    Otherwise raise :class:`InputError` naming `name`, e.g. ``"poses.height_range_m must
    satisfy 0.0 <= min <= max, got [2.0, 1.0]"``.
    """
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a [min, max] pair of numbers, got {value!r}") from None
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
        raise InputError(f"{name} must be an integer {bound}, got {value!r}")
    return int(value)
