"""The commands that read or write data: ``import`` (each format), ``info``, ``outcomes import``,
``calibrate``. Each imports what it runs when it runs (``inspector info`` must not pay for rerun,
viser or the metrics)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..schema import json_text
from . import flags as flag
from .options import calibration_argument, emit

# What every ``inspector import`` command's arguments hold besides the format's own flags.
_IMPORT_COMMON = {"command", "format", "func", "src", "output", "overwrite"}


def _cmd_import(args: argparse.Namespace) -> int:
    from ..data.importers import format_named

    fmt = format_named(args.format)
    assert fmt is not None  # the parser offers only the registry's names
    options = {k: v for k, v in vars(args).items() if k not in _IMPORT_COMMON}
    dest = fmt.importer.import_command(args.src, args.output, overwrite=args.overwrite, **options)
    print(f"wrote session {dest}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from ..data.info import describe, format_info

    info = describe(Path(args.path), calibration=args.calibration)
    emit(json_text(info, indent=2) if args.json else format_info(info))
    return 0


def _cmd_outcomes_import(args: argparse.Namespace) -> int:
    from ..outcomes import import_outcomes

    done = import_outcomes(args.file, args.path, add_tags=args.add_tag or ())
    for row in done.unmatched:
        print(f"warning: {args.file}: line {row.line}: {row.names()} matches no rollout", file=sys.stderr)
    if done.unmatched_rows > len(done.unmatched):
        print(f"warning: {args.file}: {done.unmatched_rows - len(done.unmatched):,} more row(s) match no rollout",
              file=sys.stderr)
    print(f"imported {done.rows} row(s) of {args.file} as the outcomes of {done.rollouts} rollout(s) into {done.store}")
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from ..analysis.calibrate_command import calibrate, format_calibration

    result = calibrate(args.path, args.view, args.points, rollout=args.rollout, fovy_guess_deg=args.fov,
                       max_error_px=args.max_error, fit_principal_point=args.fit_principal_point)
    emit(json_text(result, indent=2) if args.json else format_calibration(result))
    return 0


def import_parser(formats: Any, name: str, what: str, src_help: str,
                   func: Callable[[argparse.Namespace], int]) -> argparse.ArgumentParser:
    """``inspector import NAME SRC -o DEST [--overwrite]``: what every format takes."""
    p = formats.add_parser(name, help=what)
    p.add_argument("src", help=src_help)
    p.add_argument("-o", "--output", required=True, help="session directory to create")
    p.add_argument("--overwrite", action="store_true", help="replace an existing session")
    p.set_defaults(func=func)
    return p


def dreamzero_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", help="LeRobot dataset (root or org/name in the HF cache) with the GT episode")
    p.add_argument("--episode", type=flag.index, help="GT episode index (default: the rollout's own)")


def offline_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", help="LeRobot dataset with the GT episode (default: the runs' inspector_gt.json)")
    p.add_argument("--episode", type=flag.index, help="GT episode index (default: inspector_gt.json's)")
    p.add_argument("--start-frame", type=flag.index, help="episode frame the run started at (default: inspector_gt.json's, else 0)")
    p.add_argument("--fps", type=flag.rate_hz(), help="action rate [Hz] (default: the dataset's, else 30)")


def served_arguments(p: argparse.ArgumentParser) -> None:
    from ..data.importers import format_named

    fmt = format_named("dreamzero-served")
    assert fmt is not None
    served: Any = fmt.importer  # its module: the defaults, named once there
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


# A format's own flags, by its name (their checked types live here, in the command line's
# package); a format without any needs no entry. Each flag's name is its import's keyword.
IMPORT_ARGUMENTS: dict[str, Callable[[argparse.ArgumentParser], None]] = {
    "dreamzero-so101": dreamzero_arguments, "groot-dreams": calibration_argument,
    "dreamzero-offline": offline_arguments, "dreamzero-served": served_arguments}


def add_import(sub: Any) -> None:
    """``inspector import NAME``, one per format of the importer registry, in its order."""
    from ..data.importers import FORMATS

    p = sub.add_parser("import", help="import model outputs into a native session")
    commands = p.add_subparsers(dest="format", required=True)
    for fmt in FORMATS:
        own = IMPORT_ARGUMENTS.get(fmt.name)
        q = import_parser(commands, fmt.name, fmt.summary, fmt.src_help, _cmd_import)
        if own is not None:
            own(q)


def add_info(sub: Any) -> None:
    p = sub.add_parser("info", help="describe a session, a LeRobot dataset or a GR00T-Dreams dump")
    p.add_argument("path")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    calibration_argument(p)
    p.set_defaults(func=_cmd_info)



def add_outcomes(sub: Any) -> None:
    p = sub.add_parser("outcomes", help="outcomes of rollouts from a file (a judge, a run sheet, a script)")
    verbs = p.add_subparsers(dest="verb", required=True)
    q = verbs.add_parser("import", help="store a JSON-lines or CSV file's outcomes (tag or episode per row)")
    q.add_argument("file", help="outcomes file: .jsonl (one object per line) or .csv (a header row)")
    q.add_argument("path", help="the session (or raw directory: then its sidecar) the rows belong to")
    q.add_argument("--add-tag", action="append", metavar="NAME",
                   help="a failure tag of the session's own, beside the standard ones (repeatable)")
    q.set_defaults(func=_cmd_outcomes_import)



def add_calibrate(sub: Any) -> None:
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

