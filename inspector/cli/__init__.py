"""``inspector`` command line: import, info, report, compare, serve, export, eval, rank, agreement, demo.

Bad input ends with exit code 2 and one line ``error: <file>: <what is wrong>``, never a traceback.
What counts as bad input, per command:

- ``import``: all or nothing. Any unreadable source rollout (or dataset, with ``--dataset``) is
  exit 2, and nothing is written: no session, no temporary directory.
- ``info``: describes PATH. Exit 2 when PATH itself cannot be read (its ``session.json``, the
  dataset's ``meta/`` files, a rollout directory named directly); a session's broken rollouts are
  listed under ``errors`` with exit 0 (info is how one finds out what is broken).
- ``report``: exit 2 when a path is unusable or nothing could be reported (no rollouts, or every one
  broken); otherwise exit 0, broken rollouts (and a dataset's broken episodes) listed under ``errors``.
- ``compare``: as ``report`` for each side, and exit 2 when no rollout of A pairs with one of B.
- ``export``: writes every rollout it can; each broken one prints its own ``error:`` line, leaves no
  file, and makes the exit code 2.
- ``rank``: exit 2 when a path is not a session, fewer than two are given, or a vote file is
  malformed or names a rollout its session does not have.
- ``agreement``: exit 2 when a path is not a session, the sides share no checkpoint or no task, or
  fewer than 3 checkpoint-task points are judged on both sides.
- ``serve``: exit 2 when no path can be served; a path that cannot be opened among others is its
  ``error:`` line on stderr and an error card in the app, and the others are served.
- ``eval``: exit 2 at once when the run cannot start (dataset, server, handshake, cameras, output);
  otherwise every sample that fails prints its own ``error:`` line, the others are written, and
  the exit code is 2 if any failed.

Ctrl-C ends any command with exit code 130, SIGTERM (``kill``, a timeout) with 143: both stop the
command's worker processes and remove what it was writing (``serve`` ends with 0: stopping is how
it ends).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence

from .._signals import clear_stop_request, note_stop_request
from ..errors import InspectorError
from . import app_commands, data_commands, report_commands
from .options import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED, MAX_BOOTSTRAP, OneLineParser, measures

__all__ = ["EXIT_BAD_INPUT", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "MAX_BOOTSTRAP", "Terminated", "build_parser",
           "main", "measures", "run"]


def version() -> str:
    from importlib import metadata

    try:
        return metadata.version("inspector")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="inspector",
        description="Rollout inspector for world-action models on the SO-101 arm.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    data_commands.add_import(sub)
    data_commands.add_info(sub)
    report_commands.add_report(sub)
    report_commands.add_compare(sub)
    data_commands.add_outcomes(sub)
    app_commands.add_serve(sub)
    app_commands.add_export(sub)
    app_commands.add_eval(sub)
    report_commands.add_rank(sub)
    report_commands.add_agreement(sub)
    data_commands.add_calibrate(sub)
    app_commands.add_demo(sub)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C's KeyboardInterrupt would be, so that it stops a command the
    same way: its worker pools stopped, its partial files removed (SIGTERM's default would end
    this process alone, on the spot)."""


def _sigterm_as_interrupt() -> Callable[[], None]:
    """Turn SIGTERM into :class:`Terminated` while a command runs; returns what puts the previous
    handler back. Only the main thread may set handlers: elsewhere nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def terminated(signum, frame):
        note_stop_request()  # kept even where the raise below lands in a callback that ignores it
        raise Terminated

    clear_stop_request()
    previous = signal.signal(signal.SIGTERM, terminated)

    def restore() -> None:
        signal.signal(signal.SIGTERM, previous)
    return restore


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    restore_sigterm = _sigterm_as_interrupt()
    try:
        return func(args)
    except InspectorError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Terminated:
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # output piped into head & co.
        sys.stderr.close()
        return 0
    except OSError as exc:  # disk full, permission denied, a file where a directory should be
        print(f"error: {InspectorError(exc.filename or '-', exc.strerror or str(exc))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    finally:
        restore_sigterm()


def run() -> None:
    """The ``inspector`` command: :func:`main`, then out of the process.

    A command stopped by a signal ends at once, after its own clean-up (the ``finally`` blocks the
    interrupt unwound), without the interpreter's exit: the signal may have landed in an import,
    leaving that module's lock held for good, and the exit joins every worker thread (the app
    loads the arm's meshes in one) — a thread waiting on that lock would hold the process forever.
    """
    code = main()
    if code in (EXIT_TERMINATED, EXIT_INTERRUPTED):
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(code)
    sys.exit(code)

