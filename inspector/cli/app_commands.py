"""The commands that serve, write recordings, evaluate and build the demo: ``serve``, ``export``,
``eval``, ``demo``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..app import DEFAULT_FRAME_CACHE_MB
from ..errors import InspectorError
from . import flags as flag
from .options import (
    EXIT_BAD_INPUT,
    MAX_CACHE_MB,
    check_listenable,
    dataset_argument,
    jobs_argument,
    measures,
    no_cache_argument,
    ray_argument,
    rollout_measure_arguments,
)


def _cmd_serve(args: argparse.Namespace) -> int:
    from ..app import serve

    check_listenable(args.host, args.port)
    serve(args.paths, host=args.host, port=args.port, share=args.share, dataset=args.dataset,
          cache_mb=args.cache_mb, use_cache=not args.no_cache, exit_when_stopped=True,
          calibration=args.calibration, ab=args.ab, outcome_source=args.outcome_source, measures=measures(args))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    import importlib.util

    if importlib.util.find_spec("rerun") is None:
        raise InspectorError("inspector export", "needs the Rerun SDK: pip install 'inspector[export]' "
                                                 "(pip install -e '.[export]' in a clone)")
    from ..export.command import export_cli

    return export_cli(args.path, args.output, rollout=args.rollout, views=args.views,
                      dataset=args.dataset, use_cache=not args.no_cache, limit_margin_deg=args.limit_margin,
                      episodes=args.episode, ray=args.ray, jobs=args.jobs, calibration=args.calibration,
                      outcome_source=args.outcome_source, measures=measures(args))


def _cmd_eval(args: argparse.Namespace) -> int:
    import importlib.util

    missing = [m for m in ("msgpack", "websockets") if importlib.util.find_spec(m) is None]
    if missing:
        raise InspectorError("inspector eval", f"needs {' and '.join(missing)}: pip install 'inspector[eval]'")
    from ..eval.run import DEFAULT_SAMPLES, EvalPlan, evaluate, format_result

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


def _cmd_demo(args: argparse.Namespace) -> int:
    from ..demo import rebuild_demo, write_checkpoints

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


def add_serve(sub: Any) -> None:
    p = sub.add_parser("serve", help="the web app (default: the bundled demo session)")
    p.add_argument("paths", nargs="*", help="sessions, rollouts, DreamZero-SO101 source dirs or LeRobot "
                                            "datasets (a directory or org/name in the local cache)")
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default loopback only)")
    p.add_argument("--port", type=flag.port, default=8080, help="TCP port (default 8080; 0 picks a free one)")
    p.add_argument("--share", action="store_true", help="also open a public viser share link")
    dataset_argument(p)
    p.add_argument("--cache-mb", type=flag.positive(MAX_CACHE_MB), default=DEFAULT_FRAME_CACHE_MB, metavar="MB",
                   help="memory for video frames sent to browsers, shared by all tabs "
                        f"(default {DEFAULT_FRAME_CACHE_MB})")
    no_cache_argument(p)
    p.add_argument("--ab", action="store_true",
                   help="blind A/B comparison of two or more sessions (checkpoints): pairs from the same start, "
                        "names hidden until the vote (keys A, B, =); votes go to each session's votes.json "
                        "for inspector rank")
    rollout_measure_arguments(p, limit_margin=False)
    p.set_defaults(func=_cmd_serve)



def add_export(sub: Any) -> None:
    p = sub.add_parser("export", help="write a Rerun .rrd recording")
    p.add_argument("path", help="a session, a rollout, a DreamZero-SO101 source dir or a LeRobot dataset")
    p.add_argument("-o", "--output", default=".",
                   help=".rrd file (or directory for several rollouts; default: the current directory)")
    p.add_argument("--rollout", help="tag of the rollout to export (default: all)")
    p.add_argument("--episode", type=flag.index, action="append", metavar="N",
                   help="a LeRobot dataset's episode to export (repeat for several)")
    p.add_argument("--views", nargs="*", help="camera views to include (default: all)")
    dataset_argument(p)
    jobs_argument(p, "worker processes writing several recordings")
    no_cache_argument(p)
    ray_argument(p, "write the recordings")
    rollout_measure_arguments(p)
    p.set_defaults(func=_cmd_export)



def add_eval(sub: Any) -> None:
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



def add_demo(sub: Any) -> None:
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
