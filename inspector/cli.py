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
import re
import signal
import socket
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from . import _flag_values as flag
from ._signals import clear_stop_request, note_stop_request
from .cache import DEFAULT_FRAME_CACHE_MB
from .errors import InspectorError
from .schema import json_text
from .units import DEFAULT_LIMIT_MARGIN_DEG

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 128 + signal.SIGINT
EXIT_TERMINATED = 128 + signal.SIGTERM
# Flags' upper bounds (docs/reliability.md): past them a value is no one's intent and costs memory or
# time in proportion (2,000 bootstrap replicates take seconds; a billion, 15 GB).
MAX_BOOTSTRAP = 20_000
MAX_JOBS = 1_000_000  # beyond the cores, --jobs is capped with a note anyway
MAX_CACHE_MB = 1 << 20  # 1 TiB of frames


# Each command imports what it runs when it runs: `inspector info` must not pay for rerun, viser or
# the metrics (about a second of imports), so these imports stay inside the functions.
def _cmd_import(args: argparse.Namespace) -> int:
    if args.format == "groot-dreams":
        from .data.importers.groot_dreams import import_groot_dreams

        dest = import_groot_dreams(args.src, args.output, calibration=args.calibration, overwrite=args.overwrite)
        print(f"wrote session {dest}")
        return 0
    from .data.importers.dreamzero_so101 import import_dreamzero

    dest = import_dreamzero(args.src, args.output, dataset=args.dataset, episode=args.episode,
                            overwrite=args.overwrite)
    print(f"wrote session {dest}")
    return 0


def _cmd_import_offline(args: argparse.Namespace) -> int:
    from .data.importers.dreamzero_offline import import_offline

    dest, _ = import_offline(args.src, args.output, dataset=args.dataset, episode=args.episode,
                             start_frame=args.start_frame, fps=args.fps, overwrite=args.overwrite)
    print(f"wrote session {dest}")
    return 0


def _cmd_import_eval(args: argparse.Namespace) -> int:
    from .data.importers.lerobot_eval import import_eval

    dest, _ = import_eval(args.src, args.output, overwrite=args.overwrite)
    print(f"wrote session {dest}")
    return 0


def _cmd_import_served(args: argparse.Namespace) -> int:
    from .data.importers.dreamzero_served import Timing, import_served

    timing = Timing(frames_per_call=args.frames_per_call, executed_per_call=args.open_loop_horizon,
                    steps_per_frame=args.steps_per_frame, control_hz=args.control_hz)
    dest, _ = import_served(args.src, args.output, views=args.views, timing=timing, dataset=args.dataset,
                            recording=args.recording, episode=args.episode, overwrite=args.overwrite)
    print(f"wrote session {dest}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from .data.info import describe, format_info

    info = describe(Path(args.path), calibration=args.calibration)
    _emit(json_text(info, indent=2) if args.json else format_info(info))
    return 0


def _emit(text: str) -> None:
    """Print a command's output. A failure to write it (a full disk) is one line naming the file
    standard output goes to, and the unwritten rest is dropped (no second error at exit)."""
    try:
        print(text)
        sys.stdout.flush()
    except BrokenPipeError:
        raise
    except OSError as exc:
        where = _stdout_file()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # what is still buffered goes nowhere at exit
        os.close(devnull)
        raise InspectorError(where, f"cannot write the output ({exc.strerror or exc})") from None


def _stdout_file() -> str:
    """The file standard output is (``out.json`` of ``> out.json``), or ``<stdout>``."""
    try:
        return os.readlink(f"/proc/self/fd/{sys.stdout.fileno()}")
    except (OSError, ValueError):
        return "<stdout>"


def _cmd_report(args: argparse.Namespace) -> int:
    from .report.build import build_report, format_report

    thresholds = None
    if args.sanity or args.sanity_config:
        from .report.sanity import load_thresholds

        thresholds = load_thresholds(args.sanity_config)  # a bad file fails before any work
    report = build_report(args.paths, dataset=args.dataset, jobs=args.jobs, use_cache=not args.no_cache,
                          limit_margin_deg=args.limit_margin, ray=args.ray, calibration=args.calibration,
                          outcome_source=args.outcome_source, measures=_measures(args))
    if thresholds is not None:
        from .report.sanity import add_sanity

        add_sanity(report, thresholds)
    if args.html:
        from .report.html import write_report_html

        print(f"wrote {write_report_html(report, args.html, sources=args.paths)}", file=sys.stderr)
        if not (args.json or args.text):  # the page is what was asked for: the tables only on request
            return 0
    _emit(json_text(report, indent=2) if args.json else format_report(report))
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from .report.compare import build_comparison, format_comparison

    comparison = build_comparison(args.a, args.b, dataset=args.dataset, jobs=args.jobs,
                                  use_cache=not args.no_cache, limit_margin_deg=args.limit_margin,
                                  outcome_source=args.outcome_source, measures=_measures(args))
    _emit(json_text(comparison, indent=2) if args.json else format_comparison(comparison))
    return 0


def _cmd_outcomes_import(args: argparse.Namespace) -> int:
    from .outcomes import import_outcomes

    done = import_outcomes(args.file, args.path, add_tags=args.add_tag or ())
    for row in done.unmatched:
        print(f"warning: {args.file}: line {row.line}: {row.names()} matches no rollout", file=sys.stderr)
    if done.unmatched_rows > len(done.unmatched):
        print(f"warning: {args.file}: {done.unmatched_rows - len(done.unmatched):,} more row(s) match no rollout",
              file=sys.stderr)
    print(f"imported {done.rows} row(s) of {args.file} as the outcomes of {done.rollouts} rollout(s) into {done.store}")
    return 0


def _cmd_serve(args: argparse.Namespace) -> int:
    from .app import serve

    check_listenable(args.host, args.port)
    serve(args.paths, host=args.host, port=args.port, share=args.share, dataset=args.dataset,
          cache_mb=args.cache_mb, use_cache=not args.no_cache, exit_when_stopped=True,
          calibration=args.calibration, ab=args.ab, outcome_source=args.outcome_source, measures=_measures(args))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    import importlib.util

    if importlib.util.find_spec("rerun") is None:
        raise InspectorError("inspector export", "needs the Rerun SDK: pip install 'inspector[export]' "
                                                 "(pip install -e '.[export]' in a clone)")
    from .export.command import export_cli

    return export_cli(args.path, args.output, rollout=args.rollout, views=args.views,
                      dataset=args.dataset, use_cache=not args.no_cache, limit_margin_deg=args.limit_margin,
                      episodes=args.episode, ray=args.ray, jobs=args.jobs, calibration=args.calibration,
                      outcome_source=args.outcome_source, measures=_measures(args))


def _cmd_eval(args: argparse.Namespace) -> int:
    import importlib.util

    missing = [m for m in ("msgpack", "websockets") if importlib.util.find_spec(m) is None]
    if missing:
        raise InspectorError("inspector eval", f"needs {' and '.join(missing)}: pip install 'inspector[eval]'")
    from .eval.run import DEFAULT_SAMPLES, EvalPlan, evaluate, format_result

    model = {k: v for k, v in (("name", args.model), ("checkpoint", args.checkpoint)) if v is not None}
    plan = EvalPlan(server=args.server, dataset=args.dataset, output=args.output, episodes=args.episodes,
                    samples=args.samples or DEFAULT_SAMPLES, frames=args.frames, every_chunk=args.every_chunk,
                    cameras=dict(args.camera or []),
                    prompt=args.prompt, timeout_s=args.timeout, resume=args.resume,
                    executed_per_chunk=args.executed_per_chunk,
                    video_keys=dict(args.video) if args.video else None, model=model,
                    max_reply_mb=args.max_reply_mb)
    result = evaluate(plan)
    print(format_result(result))
    return 0 if result.ok else EXIT_BAD_INPUT


def _cmd_rank(args: argparse.Namespace) -> int:
    from .report.ranking import build_ranking, format_ranking

    result = build_ranking(args.paths, n_bootstrap=args.bootstrap, seed=args.seed)
    if args.html:
        from .report.decision_html import write_ranking_html

        print(f"wrote {write_ranking_html(result, args.html)}", file=sys.stderr)
    _emit(json_text(result, indent=2) if args.json else format_ranking(result))
    return 0


def _cmd_agreement(args: argparse.Namespace) -> int:
    from .report.agreement import build_agreement, format_agreement

    result = build_agreement(args.imagined, args.real, by=args.by, match=dict(args.match or []),
                             imagined_source=args.imagined_source, real_source=args.real_source,
                             n_bootstrap=args.bootstrap, seed=args.seed)
    if args.html:
        from .report.decision_html import write_agreement_html

        print(f"wrote {write_agreement_html(result, args.html)}", file=sys.stderr)
    _emit(json_text(result, indent=2) if args.json else format_agreement(result))
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from .analysis.calibrate_command import calibrate, format_calibration

    result = calibrate(args.path, args.view, args.points, rollout=args.rollout, fovy_guess_deg=args.fov,
                       max_error_px=args.max_error, fit_principal_point=args.fit_principal_point)
    _emit(json_text(result, indent=2) if args.json else format_calibration(result))
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from .demo import rebuild_demo, write_checkpoints

    if args.checkpoints:
        write_checkpoints(Path(args.out or "."), overwrite=args.overwrite)
        return 0
    if not args.rebuild:
        print("use --rebuild to regenerate the demo session (inspector serve opens it), or --checkpoints "
              "for the sessions the README's workflows use")
        return 0
    # flushed per line: a rebuild takes minutes, and a pipe (CI, tee) would hold every line to the end
    rebuild_demo(Path(args.out) if args.out else None, quick=args.quick, log=lambda line: print(line, flush=True))
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


def _limit_margin_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--limit-margin", type=flag.margin_deg, default=DEFAULT_LIMIT_MARGIN_DEG, metavar="DEG",
                   help="a joint counts as past its URDF limit only beyond this margin "
                        f"(default {DEFAULT_LIMIT_MARGIN_DEG:g} deg)")


def _measure_arguments(p: argparse.ArgumentParser) -> None:
    """The sanity measures' tolerances (docs/metrics.md; :func:`_measures` reads them back)."""
    from .analysis.measure_settings import DEFAULT_MEASURES as d

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


def _measures(args: argparse.Namespace):
    from .analysis.measure_settings import MeasureSettings

    return MeasureSettings(args.completion_tol_deg, args.completion_tol_mm, args.completion_hold_s,
                           args.seam_multiple, args.seam_floor)


def _decision_arguments(p: argparse.ArgumentParser) -> None:
    """What ``rank`` and ``agreement`` share: output forms and the bootstrap."""
    p.add_argument("--json", action="store_true")
    p.add_argument("--html", metavar="OUT.html", help="also write one self-contained page with the figure")
    p.add_argument("--bootstrap", type=flag.whole(100, MAX_BOOTSTRAP), default=2000, metavar="N",
                   help=f"bootstrap replicates for the 95%% intervals (default 2000, at most {MAX_BOOTSTRAP})")
    p.add_argument("--seed", type=flag.index, default=0, help="the bootstrap's random seed (default 0)")


def _calibration(text: str) -> str:
    from .data.importers.calibration import parse_calibration

    try:
        parse_calibration(text, "none")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def _calibration_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--calibration", type=_calibration, metavar="SPEC",
                   help="how a GR00T-Dreams dump's joints map onto the URDF's zeros: gr00t-so100 (its "
                        "default), lerobot-legacy or none, then JOINT=ZERO[:SIGN] overrides, e.g. "
                        "gr00t-so100,shoulder_pan=0")


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


def _outcome_source_argument(p: argparse.ArgumentParser) -> None:
    """``--outcome-source``: report, compare, serve and export read it the same way (the sources of
    :data:`inspector.outcomes.SOURCES`, spelled out: the parser imports nothing heavy)."""
    p.add_argument("--outcome-source", choices=("label", "file", "sim", "recording"), default=None,
                   help="the one outcome source shown (tables, the app, a recording; a rollout without it has "
                        "no outcome); default: a label over a file over sim/recording")


def _import_parser(formats: Any, name: str, what: str, src_help: str,
                   func: Callable[[argparse.Namespace], int]) -> argparse.ArgumentParser:
    """``inspector import NAME SRC -o DEST [--overwrite]``: what every format takes."""
    p = formats.add_parser(name, help=what)
    p.add_argument("src", help=src_help)
    p.add_argument("-o", "--output", required=True, help="session directory to create")
    p.add_argument("--overwrite", action="store_true", help="replace an existing session")
    p.set_defaults(func=func)
    return p


def _served_arguments(p: argparse.ArgumentParser) -> None:
    from .data.importers import dreamzero_served as served

    p.add_argument("--views", help=f"tile layout: a preset ({', '.join(served.GRIDS)}) or rows by ';', cells "
                                   "by ',', '-' unused (default: so101 for 640x352 frames, else droid)")
    p.add_argument("--frames-per-call", type=flag.whole(1, 1000), default=served.FRAMES_PER_CALL,
                   help=f"imagined frames each inference call adds (default {served.FRAMES_PER_CALL})")
    p.add_argument("--open-loop-horizon", type=flag.whole(1, 4096), default=served.EXECUTED_PER_CALL,
                   help=f"actions the client executes per call (default {served.EXECUTED_PER_CALL})")
    p.add_argument("--steps-per-frame", type=flag.Bounded(float, 0.1, 1000.0), default=served.STEPS_PER_FRAME,
                   help=f"control steps between imagined frames (default {served.STEPS_PER_FRAME})")
    p.add_argument("--control-hz", type=flag.rate_hz(),
                   help=f"control rate [Hz] (default: the recording's fps, else {served.CONTROL_HZ:g})")
    rec = p.add_mutually_exclusive_group()
    rec.add_argument("--dataset", help="LeRobot dataset recorded while the policy ran (the GT)")
    rec.add_argument("--recording", help="the client's episode_N.mp4, or the run_sim_eval.py directory of them")
    p.add_argument("--episode", type=flag.index, help="episode of the first served video (default 0; the k-th "
                                                   "pairs with episode + k)")


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(
        prog="inspector",
        description="Rollout inspector for world-action models on the SO-101 arm.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("import", help="import model outputs into a native session")
    fmt = p.add_subparsers(dest="format", required=True)
    dz = _import_parser(fmt, "dreamzero-so101", "DreamZero-SO101 evaluation directories",
                        "a rollout directory or a parent of several (searched recursively)", _cmd_import)
    dz.add_argument("--dataset", help="LeRobot dataset (root or org/name in the HF cache) with the GT episode")
    dz.add_argument("--episode", type=flag.index, help="GT episode index (default: the rollout's own)")
    gd = _import_parser(fmt, "groot-dreams", "a GR00T-Dreams (DreamGen) IDM_dump output: neural trajectories",
                        "the dump's directory (meta/, data/, videos/)", _cmd_import)
    _calibration_argument(gd)
    off = _import_parser(fmt, "dreamzero-offline", "DreamZero-SO101 offline_inference.py runs (predicted_actions.csv)",
                         "a run directory or a parent of several (searched recursively)", _cmd_import_offline)
    off.add_argument("--dataset", help="LeRobot dataset with the GT episode (default: the runs' inspector_gt.json)")
    off.add_argument("--episode", type=flag.index, help="GT episode index (default: inspector_gt.json's)")
    off.add_argument("--start-frame", type=flag.index, help="episode frame the run started at (default: inspector_gt.json's, else 0)")
    off.add_argument("--fps", type=flag.rate_hz(), help="action rate [Hz] (default: the dataset's, else 30)")
    _import_parser(fmt, "lerobot-eval", "a lerobot-eval output directory (eval_info.json, videos/, recordings/)",
                   "the evaluation's output directory", _cmd_import_eval)
    _served_arguments(_import_parser(
        fmt, "dreamzero-served", "DreamZero's served predictions (video_pred_output/NNNNNN_<prompt>_<time>.mp4)",
        "the server's video_pred_output directory, or one of its videos", _cmd_import_served))

    p = sub.add_parser("info", help="describe a session, a LeRobot dataset or a GR00T-Dreams dump")
    p.add_argument("path")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    _calibration_argument(p)
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("report", help="drift metrics as tables or JSON")
    p.add_argument("paths", nargs="+", help="sessions, rollouts, DreamZero-SO101 source dirs or LeRobot "
                                             "datasets (a directory or org/name in the local cache)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--dataset", help="LeRobot dataset with the GT episodes")
    p.add_argument("--jobs", "-j", type=flag.whole(1, MAX_JOBS), default=None,
                   help="worker processes (default: one per core; 1 computes in this process); with "
                        "--ray, the local Ray instance's CPUs or a cluster's tasks at once")
    p.add_argument("--no-cache", action="store_true",
                   help="neither read nor write the metrics cache ($INSPECTOR_CACHE_DIR, else ~/.cache/inspector)")
    p.add_argument("--html", metavar="OUT.html",
                   help="write one self-contained page (tables, figures; opens offline) instead of printing "
                        "the tables (--json or --text prints them too)")
    p.add_argument("--text", action="store_true", help="with --html, print the text tables as well")
    p.add_argument("--sanity", action="store_true",
                   help="add the verdict of the five sanity tests (chunk fidelity, latent stability, joint "
                        "coherence, multi-task disambiguation, autoregressive rollout)")
    p.add_argument("--sanity-config", metavar="FILE.json",
                   help="thresholds of the sanity tests over the defaults (implies --sanity; see docs/report.md)")
    _ray_argument(p, "compute the rollouts")
    _limit_margin_argument(p)
    _calibration_argument(p)
    _outcome_source_argument(p)
    _measure_arguments(p)
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser("compare", help="two evaluations rollout by rollout (e.g. two checkpoints)")
    p.add_argument("a", help="session, rollout or DreamZero-SO101 source dir (A)")
    p.add_argument("b", help="the same for B; deltas are B - A")
    p.add_argument("--json", action="store_true")
    p.add_argument("--dataset", help="LeRobot dataset with the GT episodes")
    p.add_argument("--jobs", "-j", type=flag.whole(1, MAX_JOBS), default=None,
                   help="worker processes (default: one per core; 1 computes in this process)")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the metrics cache")
    _limit_margin_argument(p)
    _outcome_source_argument(p)
    _measure_arguments(p)
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser("outcomes", help="outcomes of rollouts from a file (a judge, a run sheet, a script)")
    verbs = p.add_subparsers(dest="verb", required=True)
    q = verbs.add_parser("import", help="store a JSON-lines or CSV file's outcomes (tag or episode per row)")
    q.add_argument("file", help="outcomes file: .jsonl (one object per line) or .csv (a header row)")
    q.add_argument("path", help="the session (or raw directory: then its sidecar) the rows belong to")
    q.add_argument("--add-tag", action="append", metavar="NAME",
                   help="a failure tag of the session's own, beside the standard ones (repeatable)")
    q.set_defaults(func=_cmd_outcomes_import)

    p = sub.add_parser("serve", help="the web app (default: the bundled demo session)")
    p.add_argument("paths", nargs="*", help="sessions, rollouts, DreamZero-SO101 source dirs or LeRobot "
                                            "datasets (a directory or org/name in the local cache)")
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default loopback only)")
    p.add_argument("--port", type=flag.port, default=8080, help="TCP port (default 8080; 0 picks a free one)")
    p.add_argument("--share", action="store_true", help="also open a public viser share link")
    p.add_argument("--dataset", help="LeRobot dataset with the GT episodes")
    p.add_argument("--cache-mb", type=flag.positive(MAX_CACHE_MB), default=DEFAULT_FRAME_CACHE_MB, metavar="MB",
                   help="memory for video frames sent to browsers, shared by all tabs "
                        f"(default {DEFAULT_FRAME_CACHE_MB})")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the metrics cache")
    p.add_argument("--ab", action="store_true",
                   help="blind A/B comparison of two or more sessions (checkpoints): pairs from the same start, "
                        "names hidden until the vote (keys A, B, =); votes go to each session's votes.json "
                        "for inspector rank")
    _calibration_argument(p)
    _outcome_source_argument(p)
    _measure_arguments(p)
    p.set_defaults(func=_cmd_serve)

    p = sub.add_parser("export", help="write a Rerun .rrd recording")
    p.add_argument("path", help="a session, a rollout, a DreamZero-SO101 source dir or a LeRobot dataset")
    p.add_argument("-o", "--output", default=".",
                   help=".rrd file (or directory for several rollouts; default: the current directory)")
    p.add_argument("--rollout", help="tag of the rollout to export (default: all)")
    p.add_argument("--episode", type=flag.index, action="append", metavar="N",
                   help="a LeRobot dataset's episode to export (repeat for several)")
    p.add_argument("--views", nargs="*", help="camera views to include (default: all)")
    p.add_argument("--dataset", help="LeRobot dataset with the GT episodes")
    p.add_argument("--jobs", "-j", type=flag.whole(1, MAX_JOBS), default=None,
                   help="worker processes writing several recordings (default: one per core)")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the metrics cache")
    _ray_argument(p, "write the recordings")
    _limit_margin_argument(p)
    _calibration_argument(p)
    _outcome_source_argument(p)
    _measure_arguments(p)
    p.set_defaults(func=_cmd_export)

    p = sub.add_parser("eval", help="evaluate a served checkpoint against a LeRobot dataset, open loop "
                                    "(DreamZero / RoboArena websocket protocol)")
    p.add_argument("server", help="the policy server: ws://HOST:PORT or HOST:PORT")
    p.add_argument("dataset", help="LeRobot dataset (a directory or org/name in the local cache)")
    p.add_argument("-o", "--output", required=True, help="session directory to write")
    p.add_argument("--episodes", type=flag.index_list, metavar="LIST", help="episodes, e.g. 0,3,10-20 (default: all)")
    how = p.add_mutually_exclusive_group()
    how.add_argument("--samples", type=flag.whole(1, 100_000), metavar="N",
                     help="N start frames evenly spaced in each episode (default 8)")
    how.add_argument("--frames", type=flag.index_list, metavar="LIST", help="these start frames in each episode")
    how.add_argument("--every-chunk", action="store_true",
                     help="an open-loop replay of each episode: a chunk every --executed-per-chunk frames, each "
                          "from the real observation there, stored as one rollout (kind open_loop_replay)")
    p.add_argument("--camera", type=flag.key_value("KEY=NAME"), action="append", metavar="KEY=NAME",
                   help="send dataset camera NAME under server key KEY (observation/KEY when KEY has no /); repeat")
    p.add_argument("--prompt", help="the prompt for every sample (default: each episode's task)")
    p.add_argument("--timeout", type=flag.positive(86_400.0), default=300.0, metavar="S",
                   help="longest wait for the connection and for each reply [s] (default 300)")
    p.add_argument("--resume", action="store_true", help="continue the session at -o: skip the samples it holds")
    p.add_argument("--executed-per-chunk", type=flag.whole(1, 4096), default=9, metavar="N",
                   help="steps a chunk runs before the next (--every-chunk) and that its predicted frames span "
                        "(default 9)")
    p.add_argument("--video", type=flag.key_value("KEY=VIEW"), action="append", metavar="KEY=VIEW",
                   help="keep the reply's predicted frames under KEY as view VIEW (default: video=<first camera>)")
    p.add_argument("--model", help="the model's name in the session (default: the server address)")
    p.add_argument("--checkpoint", help="the checkpoint's name in the session")
    p.add_argument("--max-reply-mb", type=flag.positive(4096.0), default=128.0, metavar="MB",
                   help="refuse a reply (or handshake) larger than MB megabytes, unread: that sample fails "
                        "(default 128: 80 times DreamZero-SO101's reply with its predicted video)")
    p.set_defaults(func=_cmd_eval)

    p = sub.add_parser("rank", help="rank sessions (checkpoints) from blind A/B votes (Bradley-Terry), "
                                    "else by success rate")
    p.add_argument("paths", nargs="+", metavar="PATH", help="session directories (two or more)")
    _decision_arguments(p)
    p.set_defaults(func=_cmd_rank)

    p = sub.add_parser("agreement", help="does success judged in imagination rank checkpoints as real success does")
    p.add_argument("--imagined", nargs="+", required=True, metavar="PATH",
                   help="sessions whose outcomes were judged in the world model's imagination")
    p.add_argument("--real", nargs="+", required=True, metavar="PATH",
                   help="sessions of the same checkpoints and tasks on the robot or in a simulator")
    p.add_argument("--by", choices=("success", "progress"), default="success",
                   help="compare success rates (default) or mean progress")
    p.add_argument("--match", type=flag.key_value("IMAGINED=REAL"), action="append", metavar="IMAGINED=REAL",
                   help="an imagined checkpoint's name as the real side calls it; repeat")
    for side in ("imagined", "real"):
        p.add_argument(f"--{side}-source", choices=("label", "file", "sim", "recording"), default=None,
                       help=f"read only this outcome source on the {side} side (default: each rollout's "
                            "effective outcome, label > file > sim > recording)")
    _decision_arguments(p)
    p.set_defaults(func=_cmd_agreement)

    p = sub.add_parser("calibrate", help="a fixed view's camera from clicked points of the arm in GT frames",
                       description="Solves the camera of VIEW (intrinsics and pose in the arm's base frame) from "
                                   "points of the arm clicked in GT frames: the origin of a URDF link or "
                                   "gripper_tip at a step of a rollout's GT episode, and its pixel. RANSAC "
                                   "leaves bad clicks out; the camera goes into the session's cameras.json "
                                   "(docs/formats.md#camerasjson).")
    p.add_argument("path", metavar="PATH", help="a session, one rollout of it, or a raw directory")
    p.add_argument("--view", required=True, help="the camera view the points were clicked in (e.g. front)")
    p.add_argument("--points", metavar="FILE",
                   help='{"view": V, "points": [{"step": S, "point": NAME, "u": U, "v": V}, ...]} '
                        "(default: the clicks saved in the session for VIEW)")
    p.add_argument("--rollout", metavar="TAG", help="the rollout whose GT episode the steps are of "
                                                    "(where the points file does not say; default: the only one)")
    p.add_argument("--fov", type=flag.Bounded(float, 1.0, 179.0, words="a field of view from 1 to 179 degrees"),
                   default=55.0, metavar="DEG", help="vertical field of view to start from (default 55)")
    p.add_argument("--max-error", type=flag.positive(1000.0), default=5.0, metavar="PX",
                   help="refuse a camera whose RMS reprojection error is above PX (default 5); points past "
                        "twice it are left out as bad clicks")
    p.add_argument("--fit-principal-point", action="store_true",
                   help="fit the principal point too (default: the image centre)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("demo", help="rebuild the bundled demo session, or write checkpoint-like sessions from it",
                       description="--rebuild renders the demo again with MuJoCo offscreen (needs the demo extra "
                                   "and Debian's libosmesa6; 10-15 min of CPU, a progress bar with an estimate). "
                                   "--checkpoints writes sessions/step-{56000,64000,72000}, robot/step-*, "
                                   "judge.jsonl from the demo (a few seconds): docs/development.md#the-demo-session")
    p.add_argument("--rebuild", action="store_true", help="render the demo session again (MuJoCo, offscreen)")
    p.add_argument("--checkpoints", action="store_true",
                   help="write three checkpoint-like sessions, their robot-side twins and a judge file")
    p.add_argument("--overwrite", action="store_true", help="--checkpoints: replace what an earlier run wrote")
    p.add_argument("--out", help="output directory (--rebuild: default sessions/demo; --checkpoints: default .)")
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


if __name__ == "__main__":
    run()
