"""Naive baselines, run as their own processes so they are measured like the CLI: what a first
script (and this project before its scale work) does.

    python benchmarks/naive.py report SESSION [-n N]
    python benchmarks/naive.py export SESSION TAG OUT.rrd
    python benchmarks/naive.py export-all SESSION OUT_DIR

``report``: every rollout opened up front, one timeline each, every clip decoded whole into
memory and kept with its rollout, PSNR on the arrays, all of it held until the end.
``export``: the clips decoded whole, then one ``rr.log`` of an ``rr.Image`` per frame and view.
``export-all``: every rollout of a session written by today's exporter, one after another in
this one process (what ``inspector export SESSION -o DIR`` did before it used worker processes).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def naive_report(session_dir: str, n: int | None) -> dict:
    from inspector.analysis import metrics
    from inspector.analysis.timeline import build_timeline
    from inspector.data.session import open_session

    session = open_session(session_dir)  # every rollout's arrays read now
    kept = []
    rows = []
    for tag in sorted(session.rollouts)[:n]:
        tl = build_timeline(session.rollouts[tag])
        clips = {}
        psnr = {}
        for view in tl.video_views():
            imagined = tl.rollout.video(view).decode(max_bytes=2**40)
            h, w = imagined.shape[1:3]
            gt = tl.gt.clips[view].decode(size=(w, h), max_bytes=2**40)
            index = tl.gt_index_of_frame(view)
            pairs = [(f, index(f)) for f in range(len(imagined)) if 0 <= index(f) < len(gt)]
            psnr[view] = float(np.mean(metrics.psnr(imagined[[f for f, _ in pairs]], gt[[g for _, g in pairs]])))
            clips[view] = (imagined, gt)
        kept.append((tl, clips))  # held to the end, as a report that keeps its timelines does
        rows.append({"tag": tag, "psnr": psnr, "drift": None if tl.time_aligned_drift is None
                     else float(tl.time_aligned_drift.mean())})
    return {"rollouts": rows}


def naive_export(session_dir: str, tag: str, out: str) -> None:
    import rerun as rr

    from inspector.data.session import open_session

    rollout = open_session(session_dir).rollouts[tag]
    clips = {(v, gt): rollout.video(v, gt=gt).decode(max_bytes=2**40)
             for v in rollout.views for gt in (False, True) if not gt or v in rollout.gt_views}
    rec = rr.RecordingStream("naive")
    rec.save(out)
    for f in range(max(len(c) for c in clips.values())):
        rec.set_time("frame", sequence=f)
        for (view, gt), frames in clips.items():
            if f < len(frames):
                rec.log(f"video/{view}/{'gt' if gt else 'imagined'}", rr.Image(frames[f]))
    rec.disconnect()


def one_process_export_all(session_dir: str, out_dir: str) -> None:
    from pathlib import Path

    from inspector.cache import MetricsCache
    from inspector.data.session import open_session
    from inspector.export.recording import export_rollout

    session = open_session(session_dir)
    for tag in sorted(session.rollouts):
        export_rollout(session.rollouts[tag], Path(out_dir) / f"{tag}.rrd", None, 2.0, MetricsCache())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser("report")
    p.add_argument("session")
    p.add_argument("-n", type=int)
    p = sub.add_parser("export")
    p.add_argument("session")
    p.add_argument("tag")
    p.add_argument("out")
    p = sub.add_parser("export-all")
    p.add_argument("session")
    p.add_argument("out_dir")
    args = parser.parse_args(argv)
    if args.what == "report":
        print(json.dumps(naive_report(args.session, args.n)))
    elif args.what == "export-all":
        one_process_export_all(args.session, args.out_dir)
    else:
        naive_export(args.session, args.tag, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
