"""Bad input of the ninth probe of issue 55 (docs/bad_input.md) that the CLI itself handles: a name holding a
control character is printed escaped, on one line (E8); an option and the config key it sets given different
values are refused, not one of them dropped (E9); and a SIGTERM whose KeyboardInterrupt a finaliser swallowed
(the probe's g13: "Exception ignored in ... KeyboardInterrupt: signal 15", then exit 0) or that is pending as
the handler is restored still interrupts, with no traceback (frontiernet/workers.py: sigterm_as_interrupt).
Each test failed before its fix."""

from __future__ import annotations

import subprocess
import sys

import pytest

from frontiernet.cli.main import main

MISSING_SEQUENCE = "/nonexistent-probe9/tum"  # the old code refused this input, not the contradiction given with it


@pytest.mark.parametrize("argv, message", [
    (["scene", "info", "no\nsuch.glb"], "frontiernet scene: error: no\\nsuch.glb: mesh file not found"),
    (["render", "procedural:3", "--pose", "0,0,1.2,0", "--out", "o_e8", "--config", "no\nsuch.yaml"],
     "frontiernet render: error: no\\nsuch.yaml: config file not found"),
    (["scene", "info", "no\rsuch\u2028.glb"], "no\\rsuch\\u2028.glb: mesh file not found"),
])
def test_a_file_name_with_a_line_break_is_printed_escaped_on_one_line(argv, message, one_line_error, tmp_path,
                                                                      monkeypatch):
    # E8: the name was printed raw, the error split over two lines ("frontiernet scene: error: no" / "such.glb: ...")
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert message in one_line_error()
    assert not (tmp_path / "o_e8").exists()


def test_a_usage_error_quoting_a_word_with_a_line_break_is_one_line(one_line_error):
    # E8, the parser's own errors (frontiernet/cli/parser.py Parser.error) quote the words as typed too
    with pytest.raises(SystemExit) as stop:
        main(["explor\ne", "--scene", "procedural:3"])
    assert stop.value.code == 2
    assert "unknown command 'explor\\ne'" in one_line_error()


def test_an_internal_error_line_escapes_control_characters(monkeypatch, one_line_error):
    # E8, the internal-error line: a terminal escape or tab in the message was printed raw
    import frontiernet.cli.scene as scene

    def fault(args):
        raise RuntimeError("bad\x1b[2Jname\there")

    monkeypatch.setattr(scene, "run_info", fault)
    assert main(["scene", "info", "procedural:3"]) == 1
    error = one_line_error()
    assert "internal error (RuntimeError: bad\\x1b[2Jname\\there)" in error
    from pathlib import Path

    Path(error.split("the traceback is in ")[1].split(" (-v")[0]).unlink()


@pytest.mark.parametrize("option, key", [(["--stride", "2"], "frames.stride=3"),
                                         (["--max-frames", "2"], "frames.max_frames=3"),
                                         (["--max-frames", "2"], "frames.max_frames=null")])
def test_sequence_refuses_an_option_and_its_key_given_different_values(option, key, one_line_error, tmp_path):
    # E9: `--stride 2 frames.stride=3` ran stride 2, the key dropped without a word (explore, demo and bench refuse it)
    out = tmp_path / "o"
    argv = ["sequence", "--no-video", "--no-mcap", "--input", MISSING_SEQUENCE, "--out", str(out), *option, key]
    assert main(argv) == 2
    assert f"{' '.join(option)} contradicts {key}: give one of them" in one_line_error()
    assert not out.exists()


def test_sequence_takes_an_option_and_its_key_of_one_value(one_line_error, tmp_path):
    argv = ["sequence", "--input", MISSING_SEQUENCE, "--out", str(tmp_path / "o"), "--stride", "2", "frames.stride=2"]
    assert main(argv) == 2
    assert "sequence folder not found" in one_line_error()  # past the check, to the input's own


def _python(script: str) -> subprocess.CompletedProcess:
    """`script` in a Python process of its own: signals reach a process's main thread (under pytest-xdist
    not the test's), and a handler left installed would outlive the test."""
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)


SWALLOWED = """
import signal, sys, time, weakref
from frontiernet.workers import sigterm_as_interrupt

class Thing:
    pass

started = time.monotonic()
try:
    with sigterm_as_interrupt():
        thing = Thing()
        ref = weakref.ref(thing, lambda _: signal.raise_signal(signal.SIGTERM))  # the signal lands in a callback
        del thing  # (the callback runs here; its KeyboardInterrupt was printed and dropped)
        while WAIT and time.monotonic() - started < 30:
            time.sleep(0.01)
    print("not interrupted")
except KeyboardInterrupt as error:
    print(f"interrupted ({error}) after {time.monotonic() - started:.1f} s")
print("restored:", signal.getsignal(signal.SIGTERM) is signal.SIG_DFL, sys.unraisablehook is sys.__unraisablehook__)
"""


@pytest.mark.parametrize("wait", [True, False])
def test_a_sigterm_that_a_weakref_callback_swallowed_still_interrupts_with_no_traceback(wait):
    # probe 9, g13: SIGTERM as bench ended ran the handler inside a weakref callback: "Exception ignored in ...
    # KeyboardInterrupt: signal 15" on stderr, and the command went on to exit 0. Now it is raised again shortly
    # after (wait) or as the block ends (not wait), and nothing is printed.
    done = _python(f"WAIT = {wait}\n{SWALLOWED}")
    assert done.returncode == 0 and done.stderr == "", done.stderr[-2000:]
    lines = done.stdout.splitlines()
    assert lines[0].startswith("interrupted (signal 15) after "), done.stdout
    assert float(lines[0].split(" after ")[1].split()[0]) < 10  # (not the 30 s the block would run on)
    assert lines[1] == "restored: True True"


def test_a_sigterm_pending_as_the_block_ends_interrupts_after_the_handler_is_restored():
    # signal.signal runs a pending signal's handler before it sets the new one: a SIGTERM pending as the block
    # restored the previous handler raised there, and the raising handler stayed installed past the block (into
    # the interpreter's shutdown, where a later SIGTERM printed a traceback)
    done = _python("""
import signal
from frontiernet.workers import sigterm_as_interrupt
real, calls = signal.signal, []

def pending_at_restore(signum, handler):
    calls.append(handler)
    if len(calls) == 2:  # the restore, with a SIGTERM pending: CPython runs its handler first
        signal.raise_signal(signal.SIGTERM)
    return real(signum, handler)

signal.signal = pending_at_restore
try:
    with sigterm_as_interrupt():
        pass
    print("not interrupted")
except KeyboardInterrupt:
    print("interrupted")
signal.signal = real
print("restored" if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL else "left installed")
""")
    assert done.returncode == 0 and done.stderr == "", done.stderr[-2000:]
    assert done.stdout.split() == ["interrupted", "restored"], done.stdout
