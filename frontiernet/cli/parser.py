"""The argument parser of ``frontiernet`` and of each of its subcommands (:class:`Parser`)."""

from __future__ import annotations

import argparse
import difflib
import re
import sys
import unicodedata

NEGATIVE_NUMBER = re.compile(r"-\.?\d")
"""What the parser reads as a (negative) number, not an option (CPython's current argparse pattern, ``match``)."""


def one_line(text: str) -> str:
    """`text` with its control characters (line breaks, tabs, escapes; Unicode categories Cc, Cs, Zl and Zp)
    written as Python writes them in a string's repr (``\\n``, ``\\x1b``, ``\\u2028``): an error line that quotes a
    file name or value holding a newline (``scene info $'no\\nsuch.glb'``) stays one line."""
    return "".join(repr(char)[1:-1] if unicodedata.category(char) in ("Cc", "Cs", "Zl", "Zp") else char
                   for char in text)


class _StoreOnce(argparse._StoreAction):
    """argparse's store, for an option given more than once: a second value is refused (argparse kept the last and
    dropped the first without a word: ``explore --scene procedural:3 --scene procedural:4`` explored 4), and a list
    option (``nargs`` ``+`` or ``*``: ``--scenes``) takes the values of every one, as ``--set`` does (``bench
    --scenes A --scenes B`` ran B alone). Options with an action of their own (flags, ``--config``) keep it."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        given = namespace.__dict__.setdefault("_options_given", {})
        if self.dest in given:
            if self.nargs in ("+", "*"):
                values = [*getattr(namespace, self.dest), *values]
            else:
                parser.error(f"{option_string} given twice ({given[self.dest]}, then {values}): give one")
        given[self.dest] = values
        setattr(namespace, self.dest, values)


class Parser(argparse.ArgumentParser):
    """argparse, but usage errors are one line with exit code 2 (argparse's own code), and an
    argument that starts with '-' and a digit is a value, never an option: ``--pose -4.5,-0.5,1.2,0``,
    ``--start -1,2,1.2,-90``, ``--seed -1`` read as written. Older argparse (3.11's) takes only a
    lone ``-4.5`` for a number and ``-4.5,...`` for an unknown option; the rule here is the one of
    CPython's current argparse: ``-``, an optional ``.``, a digit. No option here is named ``-<digit>``.
    Options are taken only as spelt (no abbreviations): ``datagen --views 3`` is refused, not read as
    ``--views-per-scene``, and a later option cannot change what an old command line means."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER
        for name in (None, "store"):  # (the default action: groups share the registry)
            self.register("action", name, _StoreOnce)

    def error(self, message: str):  # noqa: D401
        self.exit(2, f"{self.prog}: error: {one_line(message)}\n")

    def parse_known_args(self, args=None, namespace=None):
        """argparse's, after refusing an option (``--name`` or ``--name=value``) this parser does not
        have, given before its subcommand (if any; the subcommand's parser checks the rest), with
        the closest one it may have meant: otherwise argparse reports its value as a misplaced
        argument (``datagen --views 3``: "invalid choice '3'") or a required option as missing
        (``explore --scen x``); and a word where the subcommand's name goes that names none
        (``frontiernet explor --scene x``: was "unrecognized option --scene"), with the closest
        subcommand, as :meth:`_unknown_subcommand` says."""
        tokens = list(sys.argv[1:] if args is None else args)
        known = set(self._option_string_actions)
        subcommands = next((action for action in self._actions if isinstance(action, argparse._SubParsersAction)),
                           None)
        commands = set(subcommands.choices) if subcommands is not None else set()
        for child in (subcommands.choices.values() if subcommands is not None else ()):
            child.siblings = subcommands.choices  # (an option of another subcommand is named so: _option_hint)
        values, flag = 0, None  # the values the option `flag` before still takes (-1: any number, nargs + or *)
        for token in tokens:
            name = token.split("=", 1)[0]
            if token in commands and values == -1:  # (its list took the name: argparse named a later word instead)
                what = str(subcommands.metavar or "command").lower()
                self.error(f"{flag} took '{token}' for one of its values, but '{token}' names the {what}: give it "
                           f"first, then its options (`{self.prog} {token} ...`)")
            if token == "--" or token in commands:
                break
            if token.startswith("-") and len(token) > 1 and not NEGATIVE_NUMBER.match(token):
                action = self._option_string_actions.get(name)
                values = 0 if action is None or "=" in token else self._values_taken(action)
                flag = name
                if name.startswith("--") and len(name) > 2 and name not in known:
                    self.error(f"unrecognized option {name}{self._option_hint(name, sorted(known))}")
                continue
            if values:
                values -= values > 0
                continue
            if subcommands is not None:
                self._unknown_subcommand(token, subcommands)
        return super().parse_known_args(tokens, namespace)

    def _option_hint(self, name: str, known: list[str]) -> str:
        """What to say of an option `name` this parser does not have: the one of `known` it starts (``--scen``:
        ``--scene``), else the other subcommands of this parser's command that have it (``bench render
        --no-baseline``: bench train's, not the far spelling --scene), else the closest spelling of `known`."""
        close = [option for option in known if option.startswith(name)][:1]
        owners = [command for command, parser in getattr(self, "siblings", {}).items()
                  if parser is not self and name in parser._option_string_actions]
        if not close and owners:
            command = self.prog.rsplit(" ", 1)[0]
            return f" ({name} is an option of {', '.join(f'`{command} {owner}`' for owner in owners)})"
        close = close or difflib.get_close_matches(name, known, n=1, cutoff=0.6)
        return f" (did you mean {close[0]}?)" if close else ""

    @staticmethod
    def _values_taken(action: argparse.Action) -> int:
        """How many words after `action`'s flag are its values: -1 for any number (nargs + or *)."""
        nargs = action.nargs
        if nargs in ("+", "*", argparse.REMAINDER):
            return -1
        return 1 if nargs in (None, "?") else int(nargs) if isinstance(nargs, int) else 0

    def _unknown_subcommand(self, token: str, subcommands: argparse._SubParsersAction) -> None:
        """Exit 2 with one line: `token` stands where a subcommand's name goes and names none
        (``unknown command 'explor' (did you mean explore?); the commands: scene, render, ...``)."""
        what = str(subcommands.metavar or "command").lower()
        names = list(subcommands.choices)
        close = difflib.get_close_matches(token, names, n=1, cutoff=0.6)
        hint = f"did you mean {close[0]}?" if close else f"the {what}s: {', '.join(names)}"
        self.error(f"unknown {what} '{token}' ({hint})")
