"""Naive baselines, run as their own processes so they are measured like the CLI: what a first
script (and this project before its scale work) does.

    python benchmarks/naive.py report SESSION [-n N]
    python benchmarks/naive.py export SESSION TAG OUT.rrd
    python benchmarks/naive.py export-all SESSION OUT_DIR
    python benchmarks/naive.py eval SERVER DATASET OUT_SESSION -n N
    python benchmarks/naive.py served VIDEO_PRED_OUTPUT RUN_DIR

``report``: every rollout opened up front, one timeline each, every clip decoded whole into
memory and kept with its rollout, PSNR on the arrays, all of it held until the end.
``export``: the clips decoded whole, then one ``rr.log`` of an ``rr.Image`` per frame and view.
``export-all``: every rollout of a session written by today's exporter, one after another in
this one process (what ``inspector export SESSION -o DIR`` did before it used worker processes).
``served``: DreamZero served predictions against the client's recordings: every served video and
every recording decoded whole and held, the views cut, each imagined frame's recording frame
picked by the same timing, PSNR and SSIM on the arrays.
``eval``: a first evaluation loop against a policy server: each sample's frames read alone
(``Episode.frame``: a fresh container and a seek), resized with PIL, sent, written, one after
another; prints the client's time per sample (outside the server's replies) as JSON.
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


def naive_eval(server: str, dataset: str, out: str, n: int) -> dict:
    import time
    import uuid

    from PIL import Image
    from websockets.sync.client import connect

    from inspector.data import SessionWriter, open_dataset
    from inspector.eval.wire import packb, unpackb

    ds = open_dataset(dataset)
    ws = connect(server, compression=None, max_size=None, ping_interval=None)
    config = unpackb(ws.recv())
    height, width = config["image_resolution"]
    keys = [f"observation/exterior_image_{i}_left" for i in range(config["n_external_cameras"])]
    keys += ["observation/wrist_image_left"] if config["needs_wrist_camera"] else []
    client = []
    with SessionWriter.create(out, units=ds.units, dataset=str(ds.root)) as writer:
        for ref in ds.episodes:
            episode = ds.episode(ref.index)
            for start in np.linspace(0, episode.length - 24, n).astype(int):
                t0 = time.perf_counter()
                obs = {key: np.asarray(Image.fromarray(episode.frame(cam, int(start))).resize((width, height)))
                       for key, cam in zip(keys, ds.cameras)}
                state = episode.state[start]
                obs.update({"observation/joint_position": state[:5], "observation/gripper_position": state[5:],
                            "prompt": episode.task, "session_id": str(uuid.uuid4()), "endpoint": "infer"})
                t1 = time.perf_counter()
                ws.send(packb({"session_id": obs["session_id"], "endpoint": "reset"}))
                ws.recv()
                ws.send(packb(obs))
                chunk = np.asarray(unpackb(ws.recv()), np.float64)
                t2 = time.perf_counter()
                writer.add_rollout(f"ep{ref.index:03d}_f{start:04d}", kind="single_chunk", actions=chunk[None],
                                   episode_index=ref.index, start_frame=int(start), prompt=episode.task,
                                   fps=episode.fps)
                client.append(time.perf_counter() - t0 - (t2 - t1))
    ws.close()
    return {"samples": len(client), "client_ms_p50": float(np.percentile(client, 50) * 1000)}


def naive_served(served_dir: str, run_dir: str) -> dict:
    from pathlib import Path

    from PIL import Image

    from inspector.analysis import metrics
    from inspector.data.importers import dreamzero_served as served
    from inspector.data.video import VideoClip

    kept, rows = [], []
    timing = served.Timing()
    for k, video in enumerate(served.find_served(Path(served_dir))):
        frames = VideoClip(video.path).decode(max_bytes=2**40)[1:]
        recording = VideoClip(Path(run_dir) / f"episode_{k}.mp4").decode(max_bytes=2**40)
        grid, client = served.parse_grid("droid"), served.parse_grid(served.CLIENT_GRID)
        steps = timing.frame_steps(len(frames) // timing.frames_per_call)
        wanted = [round(float(s)) for s in steps]
        paired = next((i for i, w in enumerate(wanted) if w >= len(recording)), len(wanted))
        psnr, ssim = {}, {}
        for view in grid.views:
            imagined = np.stack([grid.cut(f, view) for f in frames[:paired]])
            gt = np.stack([client.cut(recording[w], view) for w in wanted[:paired]])
            gt = np.stack([np.asarray(Image.fromarray(g).resize(imagined.shape[2:0:-1])) for g in gt])
            psnr[view] = float(np.mean(metrics.psnr(imagined, gt)))
            ssim[view] = float(np.mean(metrics.ssim(imagined, gt)))
        kept.append((frames, recording))
        rows.append({"tag": video.tag, "psnr": psnr, "ssim": ssim})
    return {"rollouts": rows}


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
    p = sub.add_parser("served")
    p.add_argument("served_dir")
    p.add_argument("run_dir")
    p = sub.add_parser("eval")
    p.add_argument("server")
    p.add_argument("dataset")
    p.add_argument("out")
    p.add_argument("-n", type=int, default=8)
    args = parser.parse_args(argv)
    if args.what == "eval":
        print(json.dumps(naive_eval(args.server, args.dataset, args.out, args.n)))
    elif args.what == "served":
        print(json.dumps(naive_served(args.served_dir, args.run_dir)))
    elif args.what == "report":
        print(json.dumps(naive_report(args.session, args.n)))
    elif args.what == "export-all":
        one_process_export_all(args.session, args.out_dir)
    else:
        naive_export(args.session, args.tag, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
