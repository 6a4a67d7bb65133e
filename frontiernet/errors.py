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
