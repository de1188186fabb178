"""What several commands share: the one-line argument parser, option groups declared once
(``--dataset``, ``--jobs``, the sanity measures' tolerances, ...), writing a command's output, and
the check that ``serve`` can listen where it is told to.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import socket
import sys
import threading
from typing import NoReturn

from ..errors import InspectorError
from ..units import DEFAULT_LIMIT_MARGIN_DEG
from . import flags as flag

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 128 + signal.SIGINT
EXIT_TERMINATED = 128 + signal.SIGTERM
# Flags' upper bounds (docs/reliability.md): past them a value is no one's intent and costs memory or
# time in proportion (2,000 bootstrap replicates take seconds; a billion, 15 GB).
MAX_BOOTSTRAP = 20_000
MAX_JOBS = 1_000_000  # beyond the cores, --jobs is capped with a note anyway
MAX_CACHE_MB = 1 << 20  # 1 TiB of frames
GT_DATASET_HELP = "LeRobot dataset with the GT episodes"


def emit(text: str) -> None:
    """Print a command's output. A failure to write it (a full disk) is one line naming the file
    standard output goes to, and the unwritten rest is dropped (no second error at exit)."""
    try:
        print(text)
        sys.stdout.flush()
    except BrokenPipeError:
        raise
    except OSError as exc:
        where = stdout_file()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # what is still buffered goes nowhere at exit
        os.close(devnull)
        raise InspectorError(where, f"cannot write the output ({exc.strerror or exc})") from None


def stdout_file() -> str:
    """The file standard output is (``out.json`` of ``> out.json``), or ``<stdout>``."""
    try:
        return os.readlink(f"/proc/self/fd/{sys.stdout.fileno()}")
    except (OSError, ValueError):
        return "<stdout>"


class OneLineParser(argparse.ArgumentParser):
    """argparse, except that a bad flag or argument is one line, as every other error is:
    ``error: --jobs: must be at least 1 (got 0)``, exit 2 (argparse prints its usage block first)."""

    def error(self, message: str) -> NoReturn:
        match = re.fullmatch(r"argument ([^/:\s]+)(?:/\S+)?: (.*)", message, flags=re.DOTALL)
        where, what = (match[1], match[2]) if match else (self.prog, f"{message} (see {self.prog} --help)")
        print(f"error: {InspectorError(where, what)}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def dataset_argument(p: argparse.ArgumentParser, help: str = GT_DATASET_HELP) -> None:
    """``--dataset``: where the GT episodes are (a directory, or org/name in the local cache)."""
    p.add_argument("--dataset", help=help)


def jobs_argument(p: argparse.ArgumentParser, what: str = "worker processes") -> None:
    """``--jobs``/``-j``: how many worker processes (default one per core), within its range."""
    p.add_argument("--jobs", "-j", type=flag.whole(1, MAX_JOBS), default=None, help=f"{what} (default: one per core)")


def no_cache_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the metrics cache")


def limit_margin_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--limit-margin", type=flag.margin_deg, default=DEFAULT_LIMIT_MARGIN_DEG, metavar="DEG",
                   help="a joint counts as past its URDF limit only beyond this margin "
                        f"(default {DEFAULT_LIMIT_MARGIN_DEG:g} deg)")


def measure_arguments(p: argparse.ArgumentParser) -> None:
    """The sanity measures' tolerances (docs/metrics.md; :func:`measures` reads them back)."""
    from ..analysis.measure_settings import DEFAULT_MEASURES as d

    g = p.add_argument_group("sanity measures", "tolerances of completion and of the chunk-seam flag")
    g.add_argument("--completion-tol-deg", type=flag.non_negative(1000.0), default=d.completion_tol_deg, metavar="DEG",
                   help="completion: joints within this of the GT's final pose, 6-joint norm in the data's "
                        f"units (default {d.completion_tol_deg:g})")
    g.add_argument("--completion-tol-mm", type=flag.non_negative(10_000.0), default=d.completion_tol_mm, metavar="MM",
                   help=f"completion: the tool point within this of the final pose's (default {d.completion_tol_mm:g} mm)")
    g.add_argument("--completion-hold-s", type=flag.non_negative(86_400.0), default=d.completion_hold_s, metavar="S",
                   help=f"completion: staying there this long (default {d.completion_hold_s:g} s)")
    g.add_argument("--seam-multiple", type=flag.non_negative(1000.0), default=d.seam_multiple, metavar="X",
                   help="a chunk seam is flagged when its jump exceeds this multiple of the GT's typical "
                        f"(95th percentile) step (default {d.seam_multiple:g}) ...")
    g.add_argument("--seam-floor", type=flag.non_negative(1000.0), default=d.seam_floor_deg, metavar="DEG",
                   help=f"... and this floor, in the data's units (default {d.seam_floor_deg:g})")


def measures(args: argparse.Namespace):
    from ..analysis.measure_settings import MeasureSettings

    return MeasureSettings(args.completion_tol_deg, args.completion_tol_mm, args.completion_hold_s,
                           args.seam_multiple, args.seam_floor)


def decision_arguments(p: argparse.ArgumentParser) -> None:
    """What ``rank`` and ``agreement`` share: output forms and the bootstrap."""
    p.add_argument("--json", action="store_true")
    p.add_argument("--html", metavar="OUT.html", help="also write one self-contained page with the figure")
    p.add_argument("--bootstrap", type=flag.whole(100, MAX_BOOTSTRAP), default=2000, metavar="N",
                   help=f"bootstrap replicates for the 95%% intervals (default 2000, at most {MAX_BOOTSTRAP})")
    p.add_argument("--seed", type=flag.index, default=0, help="the bootstrap's random seed (default 0)")


def calibration_spec(text: str) -> str:
    from ..data.importers.calibration import parse_calibration

    try:
        parse_calibration(text, "none")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def calibration_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--calibration", type=calibration_spec, metavar="SPEC",
                   help="how a GR00T-Dreams dump's joints map onto the URDF's zeros: gr00t-so100 (its "
                        "default), lerobot-legacy or none, then JOINT=ZERO[:SIGN] overrides, e.g. "
                        "gr00t-so100,shoulder_pan=0")


def ray_argument(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--ray", nargs="?", const="local", metavar="ADDRESS",
                   help=f"{what} as Ray tasks: a local Ray instance, or the cluster at ADDRESS (auto, "
                        "HOST:PORT, ray://HOST:PORT); sessions must be on storage every node reads at "
                        "the same path (needs pip install 'inspector[ray]')")


# How long resolving --host may take before serve gives up (a resolver without network can hang) [s].
RESOLVE_TIMEOUT_S = 4.0


def check_listenable(host: str, port: int) -> None:
    """Refuse, in seconds and in one line, a host that does not resolve or an address that cannot
    be listened on (a port in use, a privileged port, an address not on this machine), before the
    web server's threads start: a failure there is a traceback in a thread and a process that never ends.

    Raises:
        InspectorError: naming ``--host`` or ``--port`` and why.
    """
    found: list = []
    resolver = threading.Thread(target=lambda: found.append(resolve(host, port)), daemon=True)
    resolver.start()
    resolver.join(RESOLVE_TIMEOUT_S)
    if not found:
        raise InspectorError("--host", f"cannot resolve {host!r} within {RESOLVE_TIMEOUT_S:g} s")
    if isinstance(found[0], OSError):
        raise InspectorError("--host", f"cannot resolve {host!r} ({found[0].strerror or found[0]})")
    family, address = found[0]
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server itself binds
        try:
            probe.bind(address)
        except OSError as exc:
            raise InspectorError("--port", f"cannot listen on {host}:{port} ({exc.strerror or exc})") from None


def resolve(host: str, port: int) -> tuple[int, tuple] | OSError:
    try:
        family, _, _, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    except OSError as exc:
        return exc
    return family, address


def rollout_measure_arguments(p: argparse.ArgumentParser, limit_margin: bool = True, calibration: bool = True) -> None:
    """What the commands that compute rollouts' rows take alike (report, compare, export, serve):
    the joint-limit margin, a GR00T-Dreams dump's calibration, the outcome source and the sanity
    measures' tolerances."""
    if limit_margin:
        limit_margin_argument(p)
    if calibration:
        calibration_argument(p)
    outcome_source_argument(p)
    measure_arguments(p)


def outcome_source_argument(p: argparse.ArgumentParser) -> None:
    """``--outcome-source``: report, compare, serve and export read it the same way (the sources of
    :data:`inspector.outcomes.SOURCES`, spelled out: the parser imports nothing heavy)."""
    p.add_argument("--outcome-source", choices=("label", "file", "sim", "recording"), default=None,
                   help="the one outcome source shown (tables, the app, a recording; a rollout without it has "
                        "no outcome); default: a label over a file over sim/recording")
