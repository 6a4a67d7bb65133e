"""The one error type for bad user input.

The CLI turns an :class:`InputError` into a single line on stderr and exit code 2,
with no traceback. Library code raises it whenever a file, value or spec given by
the user is wrong, and names that input in the message.
"""


class InputError(ValueError):
    """Bad user input: a missing or corrupt file, an unsupported format, a bad value."""
