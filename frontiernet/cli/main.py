"""``frontiernet`` entry point: dispatches subcommands, turns bad input into exit code 2.

Each subcommand module exposes ``add_parser(subparsers)``, which registers its parser
and sets ``func`` to the function that runs it with the parsed arguments. Packages built
on the library (``datagen``, ``train``, ``deploy``, or a user's own) add commands through
the ``frontiernet.commands`` entry point group, naming such a module (:data:`COMMANDS`, a
:class:`~frontiernet.registry.Registry`); the library never imports them.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading

from .. import __version__
from ..errors import InputError
from ..registry import Registry
from ..workers import sigterm_as_interrupt
from . import bench, demo, explore, render, scene, sequence
from .parser import Parser, one_line

COMMANDS = Registry("command", "frontiernet.commands", {"scene": scene, "render": render, "explore": explore,
                                                       "demo": demo, "bench": bench, "sequence": sequence})
"""The subcommands: name -> a module with ``add_parser(subparsers)``."""
def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="frontiernet",
                     description="frontiernet: visual frontier learning (FrontierNet, RA-L 2025). "
                                 "Scenes, the ray-cast simulator, data generation, training and exploration.")
    parser.add_argument("--version", action="version", version=f"frontiernet {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for command in COMMANDS.load_all():
        command.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        return _main(argv)
    finally:  # (an exit code, or argparse's SystemExit)
        if argv is None and threading.current_thread() is threading.main_thread():
            ignore_late_signals()


def ignore_late_signals() -> None:
    """Ignore SIGINT and SIGTERM for the rest of the process: the command has its exit code, and what is left is
    the interpreter's teardown, where a Ctrl-C raised KeyboardInterrupt inside torch's atexit finaliser
    ("Exception ignored in atexit callback" and a traceback after the command's last line). Only for the process's
    own command line (``sys.exit(main())``, `argv` None): a caller of ``main([...])`` keeps its handlers."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        with sigterm_as_interrupt():  # `kill PID` stops every command as Ctrl-C does: exit 130, "interrupted"
            return int(args.func(args) or 0)
    except InputError as error:
        print(f"frontiernet {args.command}: error: {one_line(str(error))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"frontiernet {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into a reader that stopped (`| head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except Exception as error:  # a fault of ours, not of the input: one line, the traceback in a log file
        if args.verbose:
            raise
        log = write_traceback(args.command, sys.argv[1:] if argv is None else argv)
        message = one_line((str(error).splitlines() or [""])[0])[:200]
        print(f"frontiernet {args.command}: internal error ({type(error).__name__}: {message}); the traceback is "
              f"in {log} (-v prints it here)", file=sys.stderr)
        return 1


def write_traceback(command: str, argv: list[str]) -> str:
    """Write the command line `argv` and the exception being handled, with its traceback, to a new
    log file under the temporary folder (``frontiernet-logs/<command>-<time>-<pid>.log``); returns its path."""
    import tempfile
    import time
    import traceback

    folder = os.path.join(tempfile.gettempdir(), "frontiernet-logs")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, f"{command}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log")
    with open(path, "w") as handle:
        handle.write(f"frontiernet {' '.join(argv)}\nfrontiernet {__version__}, Python {sys.version}\n\n")
        traceback.print_exc(file=handle)
    return path


if __name__ == "__main__":
    sys.exit(main())
