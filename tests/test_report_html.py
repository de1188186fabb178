"""``inspector report --html``: the figures against the fixtures' own numbers (read back from the
drawn SVG), the command, its size for 1,000 rollouts, and the page offline in Debian Chromium."""

from __future__ import annotations

import copy
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from browser import canvas_is_drawn, skip_reason, wait_until

from inspector.report.build import build_report
from inspector.report.decision_html import ranking_figure
from inspector.report.figures import joint_overlay, per_step_rmse, rmse_by_position
from inspector.report.html import render_report_html
from inspector.report.sanity_html import degradation_figure, verdict_table
from inspector.report.svg import N_COLOURS, Axes, legend_html, nice_ticks, series_style

pytestmark = pytest.mark.slow  # reports written by the CLI

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
SINGLE = {"f000": "zeroshot_chunk/f000", "f084": "zeroshot_chunk/f084", "f169": "zeroshot_chunk/f169",
          "train_ep0": "demo/train_ep0"}


@pytest.fixture(scope="module")
def fixture_report(dreamzero_dir) -> dict:
    return build_report([str(dreamzero_dir)], jobs=1)


@pytest.fixture(scope="module")
def metas(dreamzero_dir) -> dict[str, dict]:
    return {tag: json.loads((dreamzero_dir / rel / "meta.json").read_text()) for tag, rel in SINGLE.items()}


@pytest.fixture(scope="module")
def demo_report() -> dict:
    return build_report([str(DEMO)], jobs=1)


# ----------------------------------------------------------------------------------------------
# Reading the drawn SVG back in data units


def _figure(page: str, key: str) -> str:
    m = re.search(rf'<figure id="{key}".*?</figure>', page, re.S)
    assert m, f"figure {key} not in the page"
    return m.group(0)


def _charts(figure: str) -> list[tuple[dict, str]]:
    """(mapping, inner SVG) of each chart; mapping holds x0 x1 px0 px1 and y0 y1 py0 py1."""
    out = []
    for m in re.finditer(r'<svg class="chart"[^>]*data-x="([^"]+)" data-y="([^"]+)">(.*?)</svg>', figure, re.S):
        x0, x1, px0, px1 = map(float, m.group(1).split())
        y0, y1, py0, py1 = map(float, m.group(2).split())
        out.append(({"x": (x0, x1, px0, px1), "y": (y0, y1, py0, py1)}, m.group(3)))
    return out


def _to_data(mapping: dict, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x0, x1, px0, px1 = mapping["x"]
    y0, y1, py0, py1 = mapping["y"]
    return x0 + (px - px0) / (px1 - px0) * (x1 - x0), y0 + (py - py0) / (py1 - py0) * (y1 - y0)


def _path_points(d: str) -> np.ndarray:
    """(n, 2) pixel points of an ``Mx,y l dx,dy ...`` path (its pieces joined)."""
    points = []
    for piece in filter(None, d.split("M")):
        head, _, steps = piece.partition("l")
        x, y = map(float, head.split(","))
        points.append((x, y))
        for step in steps.split():
            dx, dy = map(float, step.split(","))
            x, y = x + dx, y + dy
            points.append((x, y))
    return np.array(points)


def _curves(chart: tuple[dict, str]) -> list[tuple[str, str | None, np.ndarray, np.ndarray]]:
    """(class, data-key, x, y) of each line of a chart, in data units."""
    mapping, svg = chart
    out = []
    for m in re.finditer(r'<path class="ln ([^"]+)"(?: data-key="(\d+)")? d="([^"]+)"', svg):
        pts = _path_points(m.group(3))
        x, y = _to_data(mapping, pts[:, 0], pts[:, 1])
        out.append((m.group(1), m.group(2), x, y))
    return out


def _pixel(mapping: dict, axis: str) -> float:
    """One pixel in data units along ``axis``."""
    lo, hi, p0, p1 = mapping[axis]
    return abs(hi - lo) / abs(p1 - p0)


# ----------------------------------------------------------------------------------------------
# Figures against the fixtures' numbers


def test_figure_data_reproduce_the_metas(fixture_report, metas):
    rows = fixture_report["rollouts"]
    tags = [r["tag"] for r in rows]
    data = per_step_rmse(rows)
    assert sorted(tags[k] for k in data["keys"]) == sorted(SINGLE)
    for k, curve in zip(data["keys"], data["per_sample"]):
        np.testing.assert_allclose(curve, np.sqrt(metas[tags[k]]["per_step_mse"]), atol=1e-9)
    expected = np.mean([np.sqrt(m["per_step_mse"]) for m in metas.values()], axis=0)
    np.testing.assert_allclose(data["mean"], expected, atol=1e-9)

    pos = rmse_by_position(rows)
    assert pos["relative"] is False  # the zero-shot samples' episode length is not in their metas
    for k, x, rmse in zip(pos["keys"], pos["x"], pos["rmse"]):
        meta = metas[tags[k]]
        assert x == meta.get("frame_in_ep", 0)
        assert rmse == pytest.approx(meta["action_rmse_deg"], abs=1e-9)

    overlay = joint_overlay(rows)
    for k, pred, gt in zip(overlay["keys"], overlay["pred"], overlay["gt"]):
        np.testing.assert_allclose(pred, metas[tags[k]]["actions_pred"], atol=1e-4)
        np.testing.assert_allclose(gt, metas[tags[k]]["actions_gt"], atol=1e-4)


def test_html_figures_draw_the_metas_numbers(fixture_report, metas):
    rows = fixture_report["rollouts"]
    page = render_report_html(fixture_report)
    (chart,) = _charts(_figure(page, "per-step-rmse"))
    curves = _curves(chart)
    tol = _pixel(chart[0], "y") * 0.06  # drawn to 0.1 px
    samples = {rows[int(key)]["tag"]: (x, y) for cls, key, x, y in curves if key is not None}
    assert set(samples) == set(SINGLE)
    for tag, (x, y) in samples.items():
        np.testing.assert_allclose(x, np.arange(24), atol=_pixel(chart[0], "x") * 0.06)
        np.testing.assert_allclose(y, np.sqrt(metas[tag]["per_step_mse"]), atol=tol)
    (mean,) = [y for cls, key, x, y in curves if cls == "mean"]
    np.testing.assert_allclose(mean, np.mean([np.sqrt(m["per_step_mse"]) for m in metas.values()], axis=0), atol=tol)

    (chart,) = _charts(_figure(page, "rmse-by-position"))
    dots = re.findall(r'<circle class="pt [^"]+" data-key="(\d+)" cx="([^"]+)" cy="([^"]+)"', chart[1])
    assert len(dots) == len(SINGLE)
    for key, cx, cy in dots:
        x, y = _to_data(chart[0], float(cx), float(cy))
        meta = metas[rows[int(key)]["tag"]]
        assert x == pytest.approx(meta.get("frame_in_ep", 0), abs=_pixel(chart[0], "x") * 0.06)
        assert y == pytest.approx(meta["action_rmse_deg"], abs=_pixel(chart[0], "y") * 0.06)

    charts = _charts(_figure(page, "joint-overlay"))
    assert len(charts) == 6  # one panel per joint
    f084 = str(next(i for i, r in enumerate(rows) if r["tag"] == "f084"))
    meta = metas["f084"]
    for joint, chart in enumerate(charts):
        lines = [(cls, y) for cls, key, x, y in _curves(chart) if key == f084]
        (gt,) = [y for cls, y in lines if cls.endswith(" gt")]
        (pred,) = [y for cls, y in lines if not cls.endswith(" gt")]
        tol = _pixel(chart[0], "y") * 0.06 + 1e-4
        np.testing.assert_allclose(pred, np.array(meta["actions_pred"])[:, joint], atol=tol)
        np.testing.assert_allclose(gt, np.array(meta["actions_gt"])[:, joint], atol=tol)

    drift = _figure(page, "drift")  # the fixture's rollouts carry no GT joints
    assert "none with GT joints" in drift and "<svg" not in drift


def test_drift_figure_draws_every_rollout_and_marks_each_episode_end(demo_report):
    from inspector.data.lerobot_dataset import open_dataset
    from inspector.report.figures import MAX_LEGEND

    rows = demo_report["rollouts"]
    lengths = {i: open_dataset(DEMO / "dataset").episode(i).length for i in (0, 1)}
    auto = [i for i, r in enumerate(rows) if r["kind"] == "autoregressive"]
    page = render_report_html(demo_report)
    charts = _charts(_figure(page, "drift"))
    assert len(charts) == 2  # time-aligned, best-match beside it
    # beyond the legend's colours the curves are drawn to whole pixels (a page of 1,000 stays small)
    tol = 0.06 if len(auto) <= MAX_LEGEND else 0.51
    for chart, metric in zip(charts, ["time_aligned_drift", "best_match_drift"]):
        by_key: dict[str, list] = {}
        for cls, key, x, y in _curves(chart):
            if key is not None:  # a rollout's curve (marks such as completion carry no key)
                by_key.setdefault(key, []).append((cls, x, y))
        assert sorted(map(int, by_key)) == auto
        for key, parts in by_key.items():
            r = rows[int(key)]
            x = np.concatenate([p[1] for p in parts])
            y = np.concatenate([p[2] for p in parts])
            order = np.unique(np.round(x, 3), return_index=True)[1]  # the post-episode part repeats its joint
            expected = np.array(r[metric]["per_chunk"])
            np.testing.assert_allclose(x[order], np.arange(len(expected)) + 0.5, atol=_pixel(chart[0], "x") * tol)
            np.testing.assert_allclose(y[order], expected, atol=_pixel(chart[0], "y") * tol)
            post = [p for p in parts if "post" in p[0].split()]
            assert bool(post) == bool(r["post_episode_chunks"])
        # one dashed line per episode end: (episode length - start frame) / steps per chunk
        ends = [float(m) for m in re.findall(r'<path class="end" d="M([\d.]+),', chart[1])]
        ends_data = sorted(_to_data(chart[0], np.array(ends), np.zeros(len(ends)))[0])
        expected_ends = sorted({lengths[rows[i]["episode_index"]] / rows[i]["steps_per_chunk"] for i in auto})
        np.testing.assert_allclose(ends_data, expected_ends, atol=_pixel(chart[0], "x") * 0.06)
        assert "end ep 0" in chart[1] and "end ep 1" in chart[1]


def test_video_action_figure_draws_each_rollouts_median_lag(demo_report):
    rows = demo_report["rollouts"]
    expected = {(str(i), view): entry["lag_s_median"] for i, r in enumerate(rows)
                for view, entry in (r["video_action"] or {}).items() if entry["lag_s_median"] is not None}
    assert expected  # the demo's views have GT video and GT joints
    page = render_report_html(demo_report)
    [chart] = _charts(_figure(page, "video-action"))
    mapping, svg = chart
    drawn = {}
    views = sorted({view for _, view in expected})
    for m in re.finditer(r'<circle class="pt (c\d)" data-key="(\d+)" cx="([\d.]+)" cy="([\d.]+)"', svg):
        x, y = _to_data(mapping, np.array([float(m.group(3))]), np.array([float(m.group(4))]))
        view = views[int(m.group(1)[1:])]
        drawn[(m.group(2), view)] = float(y[0])
        assert x[0] == pytest.approx(int(m.group(2)), abs=_pixel(mapping, "x") * 0.6)
    assert drawn.keys() == expected.keys()
    for key, lag in expected.items():
        assert drawn[key] == pytest.approx(lag, abs=_pixel(mapping, "y") * 0.6)


def test_rows_know_their_episode_length(demo_report):
    from inspector.data.lerobot_dataset import open_dataset

    ds = open_dataset(DEMO / "dataset")
    for r in demo_report["rollouts"]:
        assert r["episode_length"] == ds.episode(r["episode_index"]).length
        assert r["steps_per_chunk"] == (24 if r["kind"] == "single_chunk" else 9)
        assert (r["chunk_joints"] is None) == (r["kind"] == "autoregressive")


# ----------------------------------------------------------------------------------------------
# The SVG helper


def test_nice_ticks():
    assert nice_ticks(0, 1) == [0, 0.2, 0.4, 0.6, 0.8, 1.0]
    assert nice_ticks(0, 23, n=6) == [0, 5, 10, 15, 20, 25]
    assert nice_ticks(-3.2, 91) == [-20, 0, 20, 40, 60, 80, 100]
    assert nice_ticks(5, 5) == [5, 6, 7, 8, 9, 10]


def test_lines_break_at_missing_values_and_read_back():
    ax = Axes(x_min=0, x_max=10, y_min=0, y_max=100)
    ys = [0.0, 12.345, None, 50.0, 61.2, float("nan"), 99.9]
    ax.line(range(0, 7), ys, "c0", key="3", title="a <b>")
    svg = ax.svg()
    assert "a &lt;b&gt;" in svg
    (chart,) = _charts(f'<figure id="f">{svg}</figure>')
    (cls, key, x, y) = _curves(chart)[0]
    assert (cls, key) == ("c0", "3")
    d = re.search(r' d="([^"]+)"', chart[1].split('class="ln')[1]).group(1)
    assert d.count("M") == 3  # three runs of finite values
    np.testing.assert_allclose(y, [0.0, 12.345, 50.0, 61.2, 99.9], atol=_pixel(chart[0], "y") * 0.06)
    # decimals=0 rounds each point, never the steps between them: no drift along a long curve
    ax = Axes(x_min=0, x_max=1000, y_min=0, y_max=1)
    ax.line(np.arange(1001), np.full(1001, 0.3337), "many", decimals=0)
    (chart,) = _charts(f'<figure id="f">{ax.svg()}</figure>')
    y = _curves(chart)[0][3]
    assert np.abs(y - 0.3337).max() <= _pixel(chart[0], "y") * 0.5 + 1e-12


def test_legend_is_html_with_keys():
    html = legend_html([("c1", "run <1>", "line", "7"), ("band", "min..max", "band", None)])
    assert 'data-key="7"' in html and "run &lt;1&gt;" in html and "<rect" in html


def _tick_texts(svg: str) -> list[str]:
    return re.findall(r'<line class="tick"[^>]*/><text[^>]*>([^<]*)</text>', svg)


def test_named_ticks_stand_for_the_numbers_and_slant_when_long():
    ax = Axes(x_min=0.5, x_max=3.5, width=420, x_ticks=[(1, "step-72000"), (2, "step-64000"), (3, "a<b")])
    ax.points([1, 2, 3], [0.1, 0.2, 0.3], "c0")
    svg = ax.svg()
    assert _tick_texts(svg) == ["step-72000", "step-64000", "a&lt;b"]  # no 0.5, 1.5 ... ticks
    assert "rotate(-35" not in svg
    mapping = _charts(f'<figure id="f">{svg}</figure>')[0][0]
    xs = [float(x) for x in re.findall(r'<line class="tick" x1="([^"]+)"', svg)]
    x0, x1, px0, px1 = mapping["x"]
    np.testing.assert_allclose([x0 + (x - px0) / (px1 - px0) * (x1 - x0) for x in xs], [1, 2, 3], atol=0.01)
    # names longer than their room are slanted, and the plot gives them the height they take
    long = Axes(x_min=0.5, x_max=3.5, width=420, x_ticks=[(i, f"checkpoint-{i}-of-a-long-run") for i in (1, 2, 3)])
    long.points([1, 2, 3], [0.1, 0.2, 0.3], "c0")
    slanted = long.svg()
    assert slanted.count("rotate(-35") == 3
    plot_bottom = lambda svg: float(re.search(r'data-y="\S+ \S+ (\S+)', svg).group(1))  # noqa: E731
    assert plot_bottom(slanted) < plot_bottom(svg) - 40


def test_long_session_names_stay_apart_on_the_ranking_axis():
    rows = [{"session": f"dreamzero-so101-finetune-run-a-step-{k}000", "model": "m", "success_rate": 0.5, "low": 0.2,
             "high": 0.8, "successes": 2, "episodes": 4} for k in (8, 16, 24)]
    svg = ranking_figure({"method": "success_rate", "note": "", "ranking": rows})
    names = _tick_texts(svg)
    assert len(set(names)) == 3 and all(n.endswith(f"step-{k}000") and n.startswith("dreamz") for n, k in zip(names, (8, 16, 24)))


def test_markers_tell_points_apart_by_shape_in_the_chart_and_its_legend():
    ax = Axes(x_min=0, x_max=1, y_min=0, y_max=1)
    for i, shape in enumerate(("circle", "square", "triangle", "diamond")):
        ax.points([i / 4], [0.5], "c1", keys=[shape], label=shape, marker=shape)
    svg, legend = ax.svg(), legend_html(ax.legend)
    assert re.search(r'<circle class="pt c1" data-key="circle"', svg) and re.search(r'<rect class="pt c1" data-key="square"', svg)
    triangle = re.search(r'<path class="pt c1" data-key="triangle" d="([^"]+)"', svg).group(1)
    diamond = re.search(r'<path class="pt c1" data-key="diamond" d="([^"]+)"', svg).group(1)
    assert triangle.count("L") == 2 and diamond.count("L") == 3
    assert [m for m in re.findall(r"<(circle|rect|path) class=\"pt", legend)] == ["circle", "rect", "path", "path"]


def test_more_lines_than_colours_are_told_apart_by_dashes():
    styles = [series_style(i) for i in range(2 * N_COLOURS)]
    assert len(set(styles)) == 2 * N_COLOURS
    assert styles[0] == ("c0", "line") and styles[N_COLOURS] == ("c0 alt", "dash")


def test_where_the_dream_breaks_names_every_rollout(demo_report):
    rows = [r for r in demo_report["rollouts"] if r.get("video_degradation")]
    rows = (rows + [{**r, "tag": f"{r['tag']}_copy"} for r in rows])[:2 * N_COLOURS]  # more than the colours
    fig = degradation_figure(rows, [str(i) for i in range(len(rows))])
    assert fig is not None and len(rows) > N_COLOURS
    named = {key: label for _, label, _, key in fig.legend if key is not None}
    assert named == {str(i): r["tag"] for i, r in enumerate(rows)}
    assert len({(cls, style) for cls, _, style, _ in fig.legend}) == len(fig.legend)  # no two alike
    for panel in fig.panels:  # each curve carries its rollout's key, and its legend entry's colour and dash
        for cls, key in re.findall(r'<path class="ln ([^"]+)" data-key="([^"]+)"', panel.svg):
            assert (cls, "dash" if "alt" in cls else "line") in {(c, s) for c, _, s, k in fig.legend if k == key}
    many = degradation_figure(rows + rows[:1])  # beyond twice the colours: alike, as "each rollout"
    assert many is not None and [label for _, label, _, _ in many.legend] == ["break threshold (2x the first chunk)",
                                                                              "each rollout"]


def test_the_verdict_table_wraps_its_long_columns():
    tests = [{"test": "joint coherence", "verdict": "partial", "figure": "a " * 200, "threshold": "b " * 100}]
    html = verdict_table(tests, "sanity 0/1")
    assert '<div class="table-wrap"><table id="sanity" class="wrap">' in html and html.count('<th class="long">') == 2
    css = (Path(__file__).resolve().parents[1] / "inspector" / "report" / "assets" / "report.css").read_text()
    assert "table.wrap td { white-space: normal;" in css


# ----------------------------------------------------------------------------------------------
# The command, and the size of the page


def _cli(*argv) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "inspector", *map(str, argv)], capture_output=True, text=True,
                          timeout=900)


@pytest.fixture(scope="module")
def demo_page(tmp_path_factory) -> Path:
    """``report sessions/demo --html`` with one rollout exported beside the page."""
    out = tmp_path_factory.mktemp("html")
    exported = _cli("export", DEMO, "-o", out, "--rollout", "bias_elbow", "--views", "front")
    assert exported.returncode == 0, exported.stderr
    assert (out / "bias_elbow.rrd").is_file()
    run = _cli("report", DEMO, "--html", out / "report.html")
    assert run.returncode == 0, run.stderr
    assert run.stdout == ""  # the page was asked for: the text tables only with --text or --json
    assert run.stderr.strip().splitlines()[-1] == f"wrote {out / 'report.html'}"
    return out / "report.html"


def test_report_html_is_self_contained_and_links_exported_rrd(demo_page):
    page = demo_page.read_text()
    assert page.count('<tr data-key="') == 17
    assert re.findall(r'<a href="([^"]+)"', page) == ["bias_elbow.rrd"]
    # nothing that a browser would fetch: no external src/href/url(), no @import
    assert not re.search(r'(src|href)\s*=\s*"(?!bias_elbow\.rrd)', page)
    assert "url(" not in page.replace("url(#clip", "") and "@import" not in page
    assert "http://" not in page and "https://" not in page
    assert demo_page.stat().st_size < 200_000


def test_report_html_bad_output_is_one_line_exit_2(tmp_path):
    run = _cli("report", DEMO / "rollouts" / "single_f000", "--html", tmp_path, "--jobs", "1")
    assert run.returncode == 2 and run.stderr.startswith("error: ") and len(run.stderr.splitlines()) == 1
    assert str(tmp_path) in run.stderr and "directory" in run.stderr


def test_page_for_1000_rollouts_stays_small(demo_report):
    """1,000 autoregressive rows (the demo's, varied) plus 100 single-chunk ones."""
    rng = np.random.default_rng(0)
    base = [r for r in demo_report["rollouts"] if r["kind"] == "autoregressive"]
    single = [r for r in demo_report["rollouts"] if r["kind"] == "single_chunk"]
    rows = []
    for i in range(1000):
        r = copy.deepcopy(base[i % len(base)])
        r["tag"] = f"ep{i:04d}"
        for metric in ("time_aligned_drift", "best_match_drift", "dtw_drift"):
            r[metric]["per_chunk"] = [round(v * rng.uniform(0.8, 1.2), 6) for v in r[metric]["per_chunk"]]
        rows.append(r)
    for i in range(100):
        r = copy.deepcopy(single[i % len(single)])
        r["tag"] = f"single{i:03d}"
        rows.append(r)
    report = {"rollouts": rows, "aggregate": demo_report["aggregate"]}
    page = render_report_html(report)
    drift = _charts(_figure(page, "drift"))[0]
    assert len({key for _, key, _, _ in _curves(drift) if key is not None}) == 1000
    assert len(page.encode()) < 3_000_000, len(page.encode())  # the sanity measures' columns included


# ----------------------------------------------------------------------------------------------
# In a real browser, offline

_reason = skip_reason()


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.skipif(_reason is not None, reason=_reason or "")
def test_report_opens_offline_in_chromium(demo_page, tmp_path, browser):
    requests, problems = [], []
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    try:
        page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
        page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}")
                if m.type in ("error", "warning") else None)

        def route(r):
            if r.request.url.startswith("file://"):
                r.continue_()
            else:
                requests.append(r.request.url)
                r.abort()
        page.route("**/*", route)
        page.goto(demo_page.as_uri())
        page.wait_for_selector("html[data-ready]", timeout=30_000)

        # every figure drew: visible lines or dots, and pixels that are not a flat colour
        shot = page.screenshot(full_page=True)
        for key, n_charts in [("per-step-rmse", 1), ("rmse-by-position", 1), ("joint-overlay", 6), ("drift", 2)]:
            fig = page.locator(f"#{key}")
            assert fig.locator("svg.chart").count() == n_charts, key
            marks = fig.locator("svg.chart path.ln, svg.chart circle.pt")
            assert marks.count() > 0, key
            box = marks.first.bounding_box()
            assert box and (box["width"] > 1 or box["height"] > 1), key
            fb = fig.bounding_box()
            scroll = page.evaluate("() => window.scrollY")
            region = (int(fb["x"]), int(fb["y"] + scroll), int(fb["x"] + fb["width"]), int(fb["y"] + scroll + fb["height"]))
            assert canvas_is_drawn(shot, region), key
        (tmp_path / "report.png").write_bytes(shot)

        # the table: one row per rollout, sortable, filterable
        rows = page.locator("#rollouts tbody tr")
        assert rows.count() == 17
        headers = page.locator("#rollouts thead th")
        names = [h.strip() for h in headers.all_inner_texts()]
        col = names.index("RMSE")

        def column() -> list[float]:
            return [float(t) for t in page.eval_on_selector_all(
                "#rollouts tbody tr:not([hidden])", f"rs => rs.map(r => r.cells[{col}].textContent)")]
        headers.nth(col).click()
        assert column() == sorted(column()) and headers.nth(col).get_attribute("aria-sort") == "ascending"
        headers.nth(col).click()
        assert column() == sorted(column(), reverse=True)
        assert page.eval_on_selector("#rollouts tbody tr", "r => r.cells[0].textContent") == "tempo_0.8x"
        page.fill("#filter", "single")
        wait_until(lambda: page.text_content("#shown") == "6", what="the filter")
        assert len(column()) == 6
        page.fill("#filter", "")

        # hovering a row lights up its curves
        page.hover('#rollouts tbody tr:has-text("bias_elbow")')
        key = page.get_attribute('#rollouts tbody tr:has-text("bias_elbow")', "data-key")
        wait_until(lambda: page.locator(f'#drift path.ln.on[data-key="{key}"]').count() == 2,
                   what="the highlighted curves")
    finally:
        page.close()
    assert requests == [], f"the page tried the network: {requests}"
    assert problems == [], problems


@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_written_outputs_get_the_umasks_mode(tmp_path, umask):
    """The page, a metrics cache entry and a decimated mesh are written through a temporary file
    renamed into place: they get the mode open() gives (0666 less the umask), not mkstemp's 0600,
    so a page meant to be shared is readable as the umask allows."""
    import os
    import stat
    from typing import Any

    from inspector.cache import MetricsCache
    from inspector.report.html import write_report_html
    from inspector.robot.meshes import _write_stl_atomic

    report = build_report([str(DEMO / "rollouts" / "single_f000")], jobs=1, use_cache=False)
    old = os.umask(umask)
    try:
        page = write_report_html(report, tmp_path / "report.html")
        cache = MetricsCache(tmp_path / "cache")
        cache.put("k" * 64, {"x": 1}, Any)
        entries = [p for p in (tmp_path / "cache").rglob("*") if p.is_file()]
        mesh = tmp_path / "part.stl"
        _write_stl_atomic(mesh, np.eye(3), np.array([[0, 1, 2]]))
    finally:
        os.umask(old)
    assert len(entries) == 1
    for path in (page, entries[0], mesh):
        assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask, path


@pytest.mark.browser
@pytest.mark.skipif(_reason is not None, reason=_reason or "")
def test_the_rollout_table_fits_a_1400_px_window(demo_report, tmp_path, browser):
    """Every column, the prompt's included, within a 1400 px window: no horizontal scroll; a long
    prompt is cut to one line, the whole of it in the cell's tooltip."""
    report = copy.deepcopy(demo_report)
    long_prompt = "Pick the red cube, lift it over the blue bowl, then " * 6 + "place it in the bowl"
    report["rollouts"][0]["prompt"] = long_prompt
    out = tmp_path / "report.html"
    out.write_text(render_report_html(report))
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    try:
        page.goto(out.as_uri())
        page.wait_for_selector("html[data-ready]", timeout=30_000)
        page.locator("#rollouts").scroll_into_view_if_needed()
        page.screenshot(path=str(tmp_path / "table.png"))
        got = page.evaluate("""() => {
            const table = document.querySelector('#rollouts'), wrap = table.parentElement;
            const head = [...table.querySelectorAll('thead th')].find(th => th.textContent.trim() === 'prompt');
            const cell = table.querySelector('tbody tr td.prompt');
            return {right: head.getBoundingClientRect().right, width: head.getBoundingClientRect().width,
                    view: document.documentElement.clientWidth, wrapRight: wrap.getBoundingClientRect().right,
                    scroll: wrap.scrollWidth - wrap.clientWidth, cellTitle: cell.title,
                    cellHeight: cell.getBoundingClientRect().height, cut: cell.scrollWidth > cell.clientWidth};
        }""")
    finally:
        page.close()
    assert got["scroll"] <= 0, got  # no horizontal scroll
    assert got["right"] <= got["wrapRight"] <= got["view"], got  # the prompt column's right edge in view
    assert got["width"] >= 120, got  # and room to read it
    assert got["cellTitle"] == long_prompt and got["cut"] and got["cellHeight"] < 30, got  # one line, whole in its tooltip
