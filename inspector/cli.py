"""``inspector`` command line: import, info, report, compare, serve, export, demo.

Bad input ends with exit code 2 and one line ``error: <file>: <what is wrong>``, never a traceback.
What counts as bad input, per command:

- ``import``: all or nothing. Any unreadable source rollout (or dataset, with ``--dataset``) is
  exit 2, and nothing is written: no session, no temporary directory.
- ``info``: describes PATH. Exit 2 when PATH itself cannot be read (its ``session.json``, the
  dataset's ``meta/`` files, a rollout directory named directly); a session's broken rollouts are
  listed under ``errors`` with exit 0 (info is how one finds out what is broken).
- ``report``: exit 2 when a path is unusable or nothing could be reported (no rollouts, or every one
  broken); otherwise exit 0, broken rollouts listed under ``errors``.
- ``compare``: as ``report`` for each side, and exit 2 when no rollout of A pairs with one of B.
- ``export``: writes every rollout it can; each broken one prints its own ``error:`` line, leaves no
  file, and makes the exit code 2.

Ctrl-C ends any command with exit code 130, SIGTERM (``kill``, a timeout) with 143: both stop the
command's worker processes and remove what it was writing (``serve`` ends with 0: stopping is how
it ends).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import signal
import socket
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from .cache import DEFAULT_FRAME_CACHE_MB
from .errors import InspectorError
from .units import DEFAULT_LIMIT_MARGIN_DEG

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 128 + signal.SIGINT
EXIT_TERMINATED = 128 + signal.SIGTERM


# Each command imports what it runs when it runs: `inspector info` must not pay for rerun, viser or
# the metrics (about a second of imports), so these imports stay inside the functions.
def _cmd_import(args: argparse.Namespace) -> int:
    from .data.importers.dreamzero_so101 import import_dreamzero

    dest = import_dreamzero(args.src, args.output, dataset=args.dataset, episode=args.episode,
                            overwrite=args.overwrite)
    print(f"wrote session {dest}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from .data.info import describe, format_info

    info = describe(Path(args.path))
    print(json.dumps(info, indent=2) if args.json else format_info(info))
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from .report.build import build_report, format_report

    report = build_report(args.paths, dataset=args.dataset, jobs=args.jobs, use_cache=not args.no_cache,
                          limit_margin_deg=args.limit_margin, ray=args.ray)
    if args.html:
        from .report.html import write_report_html

        print(f"wrote {write_report_html(report, args.html, sources=args.paths)}", file=sys.stderr)
    print(json.dumps(report, indent=2) if args.json else format_report(report))
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from .report.compare import build_comparison, format_comparison

    comparison = build_comparison(args.a, args.b, dataset=args.dataset, jobs=args.jobs,
                                  use_cache=not args.no_cache, limit_margin_deg=args.limit_margin)
    print(json.dumps(comparison, indent=2) if args.json else format_comparison(comparison))
    return 0


def _cmd_serve(args: argparse.Namespace) -> int:
    from .app import serve

    check_listenable(args.host, args.port)
    serve(args.paths, host=args.host, port=args.port, share=args.share, dataset=args.dataset,
          cache_mb=args.cache_mb, use_cache=not args.no_cache, exit_when_stopped=True)
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from .export.command import export_cli

    return export_cli(args.path, args.output, rollout=args.rollout, views=args.views,
                      dataset=args.dataset, use_cache=not args.no_cache, limit_margin_deg=args.limit_margin,
                      episodes=args.episode, ray=args.ray, jobs=args.jobs)


def _cmd_demo(args: argparse.Namespace) -> int:
    from .demo import rebuild_demo

    if not args.rebuild:
        print("use --rebuild to regenerate the demo session (inspector serve opens it)")
        return 0
    rebuild_demo(Path(args.out) if args.out else None, quick=args.quick)
    return 0


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("inspector")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


class _OneLineParser(argparse.ArgumentParser):
    """argparse, except that a bad flag or argument is one line, as every other error is:
    ``error: --jobs: must be at least 1 (got 0)``, exit 2 (argparse prints its usage block first)."""

    def error(self, message: str) -> NoReturn:
        match = re.fullmatch(r"argument ([^/:\s]+)(?:/\S+)?: (.*)", message, flags=re.DOTALL)
        where, what = (match[1], match[2]) if match else (self.prog, f"{message} (see {self.prog} --help)")
        print(f"error: {InspectorError(where, what)}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def _number(text: str, kind: type[int] | type[float]) -> float:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a {'whole ' if kind is int else ''}number (got {text!r})") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number (got {text})")
    return value


def _whole_number_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse type: a whole number >= ``minimum``."""
    def parse(text: str) -> int:
        value = int(_number(text, int))
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum} (got {value})")
        return value
    return parse


_positive_int = _whole_number_at_least(1)  # --jobs
_index = _whole_number_at_least(0)  # --episode


def _positive_float(text: str) -> float:
    value = _number(text, float)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be more than 0 (got {text})")
    return value


def _port(text: str) -> int:
    value = int(_number(text, int))
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be a TCP port from 0 to 65535 (got {value}; 0 picks a free one)")
    return value


def _margin(text: str) -> float:
    value = _number(text, float)
    if not (0.0 <= value < 360.0):
        raise argparse.ArgumentTypeError(f"must be a number of degrees in [0, 360) (got {text})")
    return value


def _limit_margin_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--limit-margin", type=_margin, default=DEFAULT_LIMIT_MARGIN_DEG, metavar="DEG",
                   help="a joint counts as past its URDF limit only beyond this margin "
                        f"(default {DEFAULT_LIMIT_MARGIN_DEG:g} deg)")


def _ray_argument(p: argparse.ArgumentParser, what: str) -> None:
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
    resolver = threading.Thread(target=lambda: found.append(_resolve(host, port)), daemon=True)
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


def _resolve(host: str, port: int) -> tuple[int, tuple] | OSError:
    try:
        family, _, _, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    except OSError as exc:
        return exc
    return family, address


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(
        prog="inspector",
        description="Rollout inspector for world-action models on the SO-101 arm.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("import", help="import model outputs into a native session")
    fmt = p.add_subparsers(dest="format", required=True)
    dz = fmt.add_parser("dreamzero-so101", help="DreamZero-SO101 evaluation directories")
    dz.add_argument("src", help="a rollout directory or a parent of several (searched recursively)")
    dz.add_argument("-o", "--output", required=True, help="session directory to create")
    dz.add_argument("--dataset", help="LeRobot dataset (root or org/name in the HF cache) with the GT episode")
    dz.add_argument("--episode", type=_index, help="GT episode index (default: the rollout's own)")
    dz.add_argument("--overwrite", action="store_true", help="replace an existing session")
    dz.set_defaults(func=_cmd_import)

    p = sub.add_parser("info", help="describe a LeRobot dataset or a session")
    p.add_argument("path")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("report", help="drift metrics as tables or JSON")
    p.add_argument("paths", nargs="+", help="sessions, rollouts, DreamZero-SO101 source dirs or LeRobot "
                                             "datasets (a directory or org/name in the local cache)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--dataset", help="LeRobot dataset with the GT episodes")
    p.add_argument("--jobs", "-j", type=_positive_int, default=None,
                   help="worker processes (default: one per core; 1 computes in this process); with "
                        "--ray, the local Ray instance's CPUs or a cluster's tasks at once")
    p.add_argument("--no-cache", action="store_true",
                   help="neither read nor write the metrics cache ($INSPECTOR_CACHE_DIR, else ~/.cache/inspector)")
    p.add_argument("--html", metavar="OUT.html",
                   help="also write one self-contained page (tables, figures; opens offline)")
    _ray_argument(p, "compute the rollouts")
    _limit_margin_argument(p)
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser("compare", help="two evaluations rollout by rollout (e.g. two checkpoints)")
    p.add_argument("a", help="session, rollout or DreamZero-SO101 source dir (A)")
    p.add_argument("b", help="the same for B; deltas are B - A")
    p.add_argument("--json", action="store_true")
    p.add_argument("--dataset", help="LeRobot dataset with the GT episodes")
    p.add_argument("--jobs", "-j", type=_positive_int, default=None,
                   help="worker processes (default: one per core; 1 computes in this process)")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the metrics cache")
    _limit_margin_argument(p)
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser("serve", help="the web app (default: the bundled demo session)")
    p.add_argument("paths", nargs="*", help="sessions, rollouts, DreamZero-SO101 source dirs or LeRobot "
                                            "datasets (a directory or org/name in the local cache)")
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default loopback only)")
    p.add_argument("--port", type=_port, default=8080, help="TCP port (default 8080; 0 picks a free one)")
    p.add_argument("--share", action="store_true", help="also open a public viser share link")
    p.add_argument("--dataset", help="LeRobot dataset with the GT episodes")
    p.add_argument("--cache-mb", type=_positive_float, default=DEFAULT_FRAME_CACHE_MB, metavar="MB",
                   help="memory for video frames sent to browsers, shared by all tabs "
                        f"(default {DEFAULT_FRAME_CACHE_MB})")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the metrics cache")
    p.set_defaults(func=_cmd_serve)

    p = sub.add_parser("export", help="write a Rerun .rrd recording")
    p.add_argument("path", help="a session, a rollout, a DreamZero-SO101 source dir or a LeRobot dataset")
    p.add_argument("-o", "--output", default=".",
                   help=".rrd file (or directory for several rollouts; default: the current directory)")
    p.add_argument("--rollout", help="tag of the rollout to export (default: all)")
    p.add_argument("--episode", type=_index, action="append", metavar="N",
                   help="a LeRobot dataset's episode to export (repeat for several)")
    p.add_argument("--views", nargs="*", help="camera views to include (default: all)")
    p.add_argument("--dataset", help="LeRobot dataset with the GT episodes")
    p.add_argument("--jobs", "-j", type=_positive_int, default=None,
                   help="worker processes writing several recordings (default: one per core)")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the metrics cache")
    _ray_argument(p, "write the recordings")
    _limit_margin_argument(p)
    p.set_defaults(func=_cmd_export)

    p = sub.add_parser("demo", help="rebuild the bundled demo session")
    p.add_argument("--rebuild", action="store_true")
    p.add_argument("--out", help="output directory (default: sessions/demo)")
    p.add_argument("--quick", action="store_true", help="a tiny version (a few frames), for tests")
    p.set_defaults(func=_cmd_demo)
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
        raise Terminated

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


if __name__ == "__main__":
    sys.exit(main())
