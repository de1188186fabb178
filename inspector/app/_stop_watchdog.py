"""The last word on Ctrl-C: a command whose app hangs stopping still ends, saying where it hung."""

from __future__ import annotations

import faulthandler
import os
import sys
import threading


def exit_if_stopping_hangs(grace_s: float) -> None:
    """Ctrl-C always ends the command: should stopping the app take over ``grace_s`` (a thread
    holding a tab, a stuck close), every thread's stack is printed, so the hang can be found, and
    the process exits (code 1).

    The stacks are printed from a Python thread, holding the GIL: other threads then stand still
    while their frames are read (faulthandler's own watchdog reads them without the GIL, and a
    thread still running Python code, an import say, can crash that read). A C watchdog stays as
    the last resort, for a thread that holds the GIL and never lets the timer run."""

    def dump_and_exit() -> None:
        faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
        sys.stderr.flush()
        os._exit(1)

    timer = threading.Timer(grace_s, dump_and_exit)
    timer.daemon = True
    timer.start()
    faulthandler.dump_traceback_later(2 * grace_s, exit=True, file=sys.stderr)
