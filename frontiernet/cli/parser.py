"""The argument parser of ``frontiernet`` and of each of its subcommands (:class:`Parser`)."""

from __future__ import annotations

import argparse
import re

NEGATIVE_NUMBER = re.compile(r"-\.?\d")
"""What the parser reads as a (negative) number, not an option (CPython's current argparse pattern, ``match``)."""


class Parser(argparse.ArgumentParser):
    """argparse, but usage errors are one line with exit code 2 (argparse's own code), and an
    argument that starts with '-' and a digit is a value, never an option: ``--pose -4.5,-0.5,1.2,0``,
    ``--start -1,2,1.2,-90``, ``--seed -1`` read as written. Older argparse (3.11's) takes only a
    lone ``-4.5`` for a number and ``-4.5,...`` for an unknown option; the rule here is the one of
    CPython's current argparse: ``-``, an optional ``.``, a digit. No option here is named ``-<digit>``."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

    def error(self, message: str):  # noqa: D401
        self.exit(2, f"{self.prog}: error: {message}\n")
