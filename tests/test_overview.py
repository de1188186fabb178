"""The app's Overview: every served rollout in one table, the report's figures, compare with a session.

Rows are computed once per app from the report machinery and its metrics cache; the table is
drawn by plain functions (checked here without a browser) and shown in a real browser (Debian
Chromium driven by Playwright). The browser tests serve the bundled demo beside a copy of it
("checkpoint_b") whose ``prompt_train`` and ``single_f000`` predictions are planted 3 deg off
(B must lose those two and tie the rest), and the app tests' copy of the demo with a broken rollout.
Set ``INSPECTOR_DOCS_SCREENSHOT=1`` to also refresh ``docs/overview.png`` (the demo alone).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from browser import hide_software_webgl_notice, open_app, open_page, select_option, wait_until

from inspector.app import serve
from inspector.app._catalog import Catalog
from inspector.app._overview_outcomes import row_outcomes
from inspector.app._overview_rows import OverviewRow, OverviewRows
from inspector.app._overview_table import (
    DELTA_RMSE,
    Note,
    Query,
    compare_with_session,
    comparison_html,
    effective_of,
    figures_html,
    outcome_filters,
    scoped_css,
    select_rows,
    table_html,
)
from inspector.cache import MetricsCache
from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset
from inspector.data.session import SessionWriter
from inspector.data.sources import BUNDLED_DEMO, open_sources
from inspector.jobs.pool import default_jobs
from inspector.outcomes import make_record, store_records
from inspector.rows.tasks import plan_tasks
from inspector.units import DEFAULT_LIMIT_MARGIN_DEG

DOCS_SCREENSHOT = Path(__file__).resolve().parents[1] / "docs" / "overview.png"
OFFSET_DEG = 3.0
OFFSET_TAGS = ("prompt_train", "single_f000")
PAIR_COPY_TAGS = (*OFFSET_TAGS, "bias_elbow", "single_f153", "prompt_novel")
ROWS_TIMEOUT_S = 600.0  # computing every demo row (videos included) on a busy 2-core machine


def _demo_copy(dest: Path, name: str, offset_tags=(), broken_tag: str | None = None,
               keep: tuple[str, ...] | None = None) -> Path:
    """A copy of the bundled demo named ``name`` (only the rollouts ``keep`` when given):
    ``offset_tags`` predict OFFSET_DEG more on shoulder_pan; ``broken_tag`` has a truncated actions.npy."""
    def left_out(folder: str, names: list[str]) -> list[str]:
        return [n for n in names if keep is not None and Path(folder).name == "rollouts" and n not in keep]

    shutil.copytree(BUNDLED_DEMO, dest, ignore=left_out)
    meta = json.loads((dest / "session.json").read_text())
    (dest / "session.json").write_text(json.dumps({**meta, "name": name}))
    for tag in offset_tags:
        path = dest / "rollouts" / tag / "actions.npy"
        actions = np.load(path)
        actions[..., 0] += OFFSET_DEG
        np.save(path, actions)
    if broken_tag is not None:
        path = dest / "rollouts" / broken_tag / "actions.npy"
        path.write_bytes(path.read_bytes()[:200])
    return dest


def _catalog(paths, cache: MetricsCache, outcome_source: str | None = None) -> Catalog:
    return Catalog(open_sources(paths, confine=True, datasets=True), None, {}, metrics_cache=cache,
                   outcome_source=outcome_source)


# ----------------------------------------------------------------------------------------------
# Rows, without a browser


@pytest.mark.slow
def test_rows_are_computed_once_then_listed_from_the_cache(tmp_path, monkeypatch):
    # the bad one, the slowed one, one past its joint limits and two single chunks
    kept = ("bias_elbow", "tempo_0.8x", "limits_wrist", "single_f000", "single_f153")
    session = _demo_copy(tmp_path / "demo", "demo", broken_tag="bias_elbow", keep=kept)
    cache = MetricsCache(tmp_path / "cache")
    catalog = _catalog([session], cache)
    first = OverviewRows(catalog)
    assert len(first) == len(kept) and all(r.pending or r.error for r in first.rows())  # listed before computing
    first.start()
    assert first.done.wait(ROWS_TIMEOUT_S)
    rows = {r.tag: r for r in first.rows()}
    assert "actions.npy" in rows["bias_elbow"].error  # one bad rollout: its error row, the rest computed
    assert first.n_computed == len(kept) - 1 and first.n_cached == 0
    assert rows["tempo_0.8x"].summary["tempo"] == pytest.approx(0.8, abs=0.05)

    # A second app on the same cache lists every row without computing any.
    import inspector.rows.tasks as report_jobs

    def no_computing(*args, **kwargs):
        raise AssertionError("a cached row was computed again")

    monkeypatch.setattr(report_jobs, "_compute", no_computing)
    second = OverviewRows(_catalog([session], cache))
    second.start()
    assert second.done.wait(120)
    assert second.n_cached == len(kept) - 1 and second.n_computed == 0
    again = {r.tag: r for r in second.rows()}
    assert all(again[t].cached for t in rows if t != "bias_elbow")
    assert again["limits_wrist"].summary == rows["limits_wrist"].summary


@pytest.mark.slow
def test_rows_without_video_are_reports_rows_computed_by_a_worker_per_core(tmp_path):
    """Rollouts without video (an evaluation's joints against the demo's GT episode) are computed
    as ``report`` computes them, in report's tasks on one worker per core: every row equals
    ``report --json``'s row of the same rollout (``--jobs 1``: report's rows do not depend on its
    workers, and a pool of its own would only compute the same rows again on the same cores)."""
    n = 8  # several tasks shared among the workers (two each on two cores)
    base = np.load(BUNDLED_DEMO / "rollouts" / "overrun_60chunks" / "actions.npy")
    rng = np.random.default_rng(3)
    session = tmp_path / "eval"
    with SessionWriter.create(session, name="eval", dataset=str(BUNDLED_DEMO / "dataset")) as w:
        for i in range(n):
            w.add_rollout(f"ep000_{i:04d}", kind="autoregressive", episode_index=0, start_frame=0,
                          actions=base + rng.normal(scale=0.3, size=base.shape).cumsum(axis=0),
                          prompt="Pick the red cube" if i % 2 else "Lift the red cube")
    rows = OverviewRows(_catalog([session], MetricsCache(tmp_path / "cache")))
    tasks, workers = rows._plan()
    assert workers == default_jobs() and len(tasks) == len(plan_tasks(list(rows._sessions.values()), workers, DEFAULT_LIMIT_MARGIN_DEG))
    rows.start()
    assert rows.done.wait(ROWS_TIMEOUT_S)
    assert rows.n_computed == n and not [r.error for r in rows.rows() if r.error]
    done = subprocess.run([sys.executable, "-m", "inspector", "report", str(session), "--json", "--no-cache",
                           "--jobs", "1"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    reported = {r["tag"]: r for r in json.loads(done.stdout)["rollouts"]}
    assert len(reported) == n
    for row in rows.rows():
        summary = json.loads(json.dumps(row.summary))  # as --json writes it
        assert summary == {k: reported[row.tag][k] for k in summary}, row.tag
        assert summary["time_aligned_drift"]["per_chunk"]  # a computed row, not an empty one


def _row(key: str, rmse: float | None, kind: str = "single_chunk", prompt: str = "pick", session: str = "a",
         limit_steps: int = 0, error: str | None = None, tag: str | None = None) -> OverviewRow:
    tag = tag or key.rsplit("/", 1)[-1].strip()
    summary = None if error else {
        "tag": tag, "session": session, "kind": kind, "prompt": prompt, "episode_index": 0, "start_frame": 0,
        "rmse_deg": rmse, "per_step_mse": None, "chunk_joints": None, "n_chunks": 1, "steps_per_chunk": 24,
        "episode_length": None, "time_aligned_drift": {"mean": rmse, "final": rmse, "per_chunk": [rmse]},
        "best_match_drift": None, "tempo": None, "ee_error_mm": None, "post_episode_chunks": 0,
        "limit_violations": {"steps": limit_steps}, "video_psnr_db": {"front": 18.0}}
    return OverviewRow(key, session, tag, kind, prompt, Path("/nowhere") / session, summary, error)


def test_sorting_and_filters_select_rows():
    rows = [_row("a / r1", 2.0), _row("a / r2", None, kind="autoregressive"), _row("a / r3", 1.0, prompt="Pick BLUE"),
            _row("a / r4", 3.0, limit_steps=5), _row("a / bad", None, error="actions.npy: truncated")]
    notes = {"a / r3": Note(flag=True, note="look")}

    def keys(**q) -> list[str]:
        return [r.key for r in select_rows(rows, Query(**q), notes)]

    assert keys() == ["a / r1", "a / r2", "a / r3", "a / r4", "a / bad"]
    assert keys(sort="RMSE") == ["a / r3", "a / r1", "a / r4", "a / r2", "a / bad"]  # no value: last
    assert keys(sort="RMSE", descending=True) == ["a / r4", "a / r1", "a / r3", "a / r2", "a / bad"]
    assert keys(kind="autoregressive") == ["a / r2"]
    assert keys(kind="errors") == ["a / bad"]
    assert keys(search="blue pick") == ["a / r3"]
    assert keys(flagged_only=True) == ["a / r3"]
    assert keys(violations_only=True) == ["a / r4"]
    html = table_html(rows, select_rows(rows, Query(), notes), notes)
    assert html.count("<tr data-key=") == 5 and "actions.npy: truncated" in html and "look" in html


def test_outcome_filters_sorting_and_columns():
    """Rows filter by outcome (unlabelled, failed, a failure tag) and sort by success and progress;
    the table shows the outcome's columns."""
    rows = [_row(f"a / r{i}", 1.0) for i in range(5)]
    notes = {"a / r0": Note(outcome=make_record("label", success=True, progress=100.0)),
             "a / r1": Note(outcome=make_record("label", success=False, progress=20.0, failure="dropped")),
             "a / r2": Note(outcome=make_record("sim", success=False)),
             "a / r3": Note(flag=True)}

    def keys(**q) -> list[str]:
        return [r.key for r in select_rows(rows, Query(**q), notes)]

    assert outcome_filters(notes)[-1] == "failure: dropped"
    assert keys(outcome="without a label") == ["a / r2", "a / r3", "a / r4"]
    assert keys(outcome="failed") == ["a / r1", "a / r2"]
    assert keys(outcome="failure: dropped") == ["a / r1"]
    assert keys(sort="progress", descending=True)[:2] == ["a / r0", "a / r1"]
    assert keys(sort="success")[:3] == ["a / r1", "a / r2", "a / r0"]
    html = table_html(rows, select_rows(rows, Query(), notes), notes)
    assert "data-col='failure'>dropped" in html and "data-col='source'>sim" in html
    a = [_row(f"a / r{i}", 1.0, session="a", tag=f"r{i}") for i in range(20)]
    b = [_row(f"b / r{i}", 2.0, session="b", tag=f"r{i}") for i in range(20)]
    labels = {**{f"a / r{i}": Note(outcome=make_record("label", success=i < 18)) for i in range(20)},
              **{f"b / r{i}": Note(outcome=make_record("label", success=i < 4)) for i in range(20)}}
    comparison = compare_with_session(a + b, Query(compare_with="b"), labels)
    verdicts = {t["metric"]: t["verdict"] for t in comparison.result["tests"]}
    assert verdicts["success"] == "A better" and verdicts["rmse_deg"] == "A better"
    assert "<b>A better</b> at 95%" in comparison_html(comparison)


@pytest.mark.slow
def test_row_outcomes_agree_with_report_and_follow_the_outcome_source(tmp_path):
    """A session whose GT dataset records next.success: its rows show the recording's outcome where
    no one labelled, a label over it, each as ``report --json`` has it; with ``--outcome-source``
    (the catalog's) one source alone, and a row without it shows none (not a sim verdict instead)."""
    rng = np.random.default_rng(1)
    episodes = []
    for success in (False, True, True):
        joints = rng.normal(0, 10, size=(12, 6))
        flags = np.zeros(12, bool)
        flags[-1] = success
        episodes.append(EpisodeData("Pick the red cube", joints, joints, {"front": np.zeros((12, 32, 48, 3), np.uint8)},
                                    columns={"next.success": flags, "next.reward": flags.astype(np.float32)}))
    dataset = write_lerobot_dataset(tmp_path / "ds", episodes, fps=10)
    session = tmp_path / "s"
    with SessionWriter.create(session, dataset=dataset) as w:
        for i in range(3):
            w.add_rollout(f"ep{i}", kind="single_chunk", actions=rng.normal(size=(1, 8, 6)), episode_index=i,
                          executed_per_chunk=8)
    store_records(session / "outcomes.json", {"ep1": {"success": False, "failure": "dropped"}}, source="label",
                  set_by="app")
    done = subprocess.run([sys.executable, "-m", "inspector", "report", str(session), "--json", "-j", "1",
                           "--no-cache"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    reported = {r["tag"]: r["task_outcome"] for r in json.loads(done.stdout)["rollouts"]}

    def shown(outcome_source=None) -> dict:
        catalog = _catalog([session], MetricsCache(tmp_path / "cache"), outcome_source)
        try:
            outcomes, error = row_outcomes(OverviewRows(catalog).rows(), catalog)
        finally:
            catalog.sources.close()
        assert error is None
        return {key.rsplit(" / ", 1)[1]: o for key, o in outcomes.items()}

    overview = shown()
    assert overview == reported
    assert [(overview[t]["source"], overview[t]["success"]) for t in ("ep0", "ep1", "ep2")] == \
        [("recording", False), ("label", False), ("recording", True)]
    assert [o and o["success"] for o in shown("recording").values()] == [False, True, True]
    only_labels = shown("label")
    assert only_labels["ep0"] is None and only_labels["ep1"]["failure"] == "dropped"
    sim_row = _row("a / r0", 1.0)
    sim_row.summary["outcome"] = {"success": True}  # type: ignore[index]
    assert effective_of(sim_row, {}) == make_record("sim", success=True, set_by="eval_info.json")
    assert effective_of(sim_row, {"a / r0": Note(outcome_read=True)}) is None


def test_compare_with_a_session_pairs_rows_and_counts_winners():
    a = [_row(f"a / r{i}", 1.0 + i, session="a", tag=f"r{i}") for i in range(4)]
    b = [_row(f"b / r{i}", 1.0 + i + (0.5 if i < 3 else 0.0), session="b", tag=f"r{i}") for i in range(4)]
    comparison = compare_with_session(a + b, Query(compare_with="b"), {})
    summary = comparison.result["summary"]
    assert (summary["n_pairs"], summary["a_better"], summary["b_better"], summary["ties"]) == (4, 3, 0, 1)
    assert comparison.pair_of["a / r0"][:2] == ("b / r0", pytest.approx(0.5))
    shown = select_rows(a + b, Query(compare_with="b", sort=DELTA_RMSE, descending=True), {}, comparison)
    assert [r.key for r in shown][-1] == "a / r3"  # B's rows are the other side, not table rows
    assert len(shown) == 4


def test_figures_and_styles_are_the_reports():
    html = figures_html([_row("a / r1", 2.0)])
    assert "rmse-by-position" in html and "<svg" in html
    css = scoped_css(".ln.c0, .pt { stroke: red; }\nsvg text { fill: #000 }")
    assert css.splitlines() == [".inspector-overview .ln.c0, .inspector-overview .pt {stroke: red;}",
                                ".inspector-overview svg text {fill: #000}"]


# ----------------------------------------------------------------------------------------------
# In a real browser


@pytest.fixture(scope="module")
def demo_pair_app(tmp_path_factory):
    """The demo and a planted copy of five of its rollouts, served together, every row computed.

    The copy holds the two planted ones, one that ties (``bias_elbow``), one more single chunk and
    the blue-cube prompt: what the tests below look for in it; each of its rows costs a second."""
    copy = _demo_copy(tmp_path_factory.mktemp("overview") / "checkpoint_b", "checkpoint_b", OFFSET_TAGS,
                      keep=PAIR_COPY_TAGS)
    app = serve([BUNDLED_DEMO, copy], port=0, block=False)
    # computing starts with the server, before any tab connects
    assert app.overview_rows.done.wait(ROWS_TIMEOUT_S), "the rows did not start with the server"
    yield app
    app.stop()


def _open(browser, app, width: int = 1600, height: int = 1000, draw_3d: bool = False):
    """A page on the app once the overview shows every row with its metrics, and its tab (the 3D
    view, which the Overview covers, never drawn unless ``draw_3d``)."""
    page = open_page(browser, width, height)
    open_app(page, app.url, draw_3d=draw_3d)
    assert app.overview_rows.done.wait(ROWS_TIMEOUT_S), "overview rows still computing"
    page.wait_for_selector("table.ov-table")
    wait_until(lambda: page.locator("table.ov-table tr.pending").count() == 0, what="every row drawn computed")
    client_id = int(page.locator("[data-inspector-client]").first.get_attribute("data-inspector-client"))
    tab = wait_until(lambda: app.tabs.get(client_id), what="the page's tab")
    return page, tab


def _table_keys(page) -> list[str]:
    return page.eval_on_selector_all("table.ov-table tbody tr", "rows => rows.map(r => r.dataset.key)")


def _cells(page, col: str) -> list[str]:
    return page.eval_on_selector_all(f"table.ov-table tbody td[data-col='{col}']", "cs => cs.map(c => c.textContent)")


def _text_field(page, label: str):
    """The input of the viser text field labelled ``label`` (its <label> names no element id)."""
    return page.locator(f"xpath=//label[normalize-space()='{label}']/ancestor::*[.//input][1]//input").first


def _wait_keys(page, condition, what: str) -> list[str]:
    return wait_until(lambda: condition(_table_keys(page)) and _table_keys(page), what=what)


def _numbers(cells: list[str]) -> list[float]:
    return [float(v) for v in cells if v not in ("", "–")]


# Each page action takes seconds on a busy machine (the 3D scene renders in software behind the
# overview): the browser tests do few, and check the rest on the server or in the unit tests above.
@pytest.mark.browser
@pytest.mark.slow
def test_overview_lists_sorts_filters_draws_and_opens(browser, demo_pair_app):
    app = demo_pair_app
    page, tab = _open(browser, app)
    # shown by default (more than one rollout served): every rollout of both sessions
    assert page.locator(".inspector-overview table").first.is_visible()
    assert sorted(_table_keys(page)) == sorted(k for k, e in app.catalog.entries.items() if e.session)
    assert len(_table_keys(page)) == 17 + len(PAIR_COPY_TAGS)

    select_option(page, "Sort by", "RMSE")
    wait_until(lambda: _numbers(_cells(page, "rmse")) == sorted(_numbers(_cells(page, "rmse")))
               and len(_numbers(_cells(page, "rmse"))) == 17 + len(PAIR_COPY_TAGS), what="rows ordered by RMSE")
    assert _table_keys(page)[-1].endswith("/ tempo_0.8x")  # the demo's largest RMSE: its slow rollout

    search = _text_field(page, "Search prompts")
    search.fill("blue cube")
    _wait_keys(page, lambda ks: sorted(ks) == ["checkpoint_b / prompt_novel", "demo / prompt_novel"],
               "the prompt search")
    search.fill("")
    select_option(page, "Kind", "single-chunk")
    keys = _wait_keys(page, lambda ks: len(ks) == 6 + 2, "the kind filter")  # the demo's six, the copy's two
    assert all("/ single_f" in k for k in keys)

    # the report's figures, drawn (from the rows the filters keep: the single-chunk samples)
    for figure in ("per-step-rmse", "rmse-by-position", "joint-overlay"):
        drawn = page.locator(f".inspector-overview figure#{figure} svg.chart path.ln, "
                             f".inspector-overview figure#{figure} svg.chart circle.pt")
        assert drawn.count() > 0, f"figure {figure} has nothing drawn"
    assert page.locator(".inspector-overview circle.pt").count() >= 6 + 2  # one dot per sample

    # a row opens in the tab's normal view
    option = next(o for o in tab.overview.row.options if o.endswith("demo / single_f153"))
    select_option(page, "Row to open", option)
    page.get_by_role("button", name="Open rollout").click()
    wait_until(lambda: tab.key == "demo / single_f153" and tab.loaded is not None, what="the row to open")
    page.locator(".inspector-overview table").first.wait_for(state="hidden")
    page.locator("img.inspector-frame").first.wait_for(state="visible")
    # the Overview button brings the table back, the open rollout marked
    page.get_by_role("button", name="Overview").click()
    page.locator("tr.open[data-key='demo / single_f153']").wait_for(state="visible")
    page.close()


@pytest.mark.browser
@pytest.mark.slow
def test_compare_with_a_session_shows_the_planted_winners_and_drift_figures(browser, demo_pair_app):
    page, tab = _open(browser, demo_pair_app)
    drift = page.locator(".inspector-overview figure#drift svg.chart").first.locator("path.ln:not(.post)")
    assert drift.count() >= 11 + 3  # every autoregressive rollout of both sessions
    select_option(page, "Compare with session", "checkpoint_b")
    info = page.locator(".inspector-overview .ov-compare").first
    info.wait_for(state="visible")
    text = info.inner_text()
    assert "5 pair(s) (5 by tag" in text
    # B predicts 3 deg off on two rollouts: A wins those, the other three tie
    assert "A better in 2, B better in 0, ties 3" in text
    keys = _wait_keys(page, lambda ks: len(ks) == 17, "B's rows set aside")
    assert all(k.startswith("demo / ") for k in keys)
    for tag in OFFSET_TAGS:
        delta = page.locator(f"tr[data-key='demo / {tag}'] td[data-col='delta']").inner_text()
        assert float(delta) > 0, f"{tag}: B should be worse"
    assert float(page.locator("tr[data-key='demo / bias_elbow'] td[data-col='delta']").inner_text()) == 0
    page.close()


@pytest.mark.browser
@pytest.mark.slow
def test_rollouts_are_listed_with_the_broken_one_as_an_error_row(browser, tmp_path_factory):
    from test_app import BROKEN, CARRIED_GT, OTHER_SINGLE, SINGLE

    # four single-chunk rollouts, one broken, make the point; the whole demo's rows need not be computed
    broken = _demo_copy(tmp_path_factory.mktemp("overview-broken") / "broken", "broken", broken_tag=BROKEN,
                        keep=(BROKEN, SINGLE, OTHER_SINGLE, CARRIED_GT))
    app = serve([broken], port=0, block=False)
    try:
        page, tab = _open(browser, app)
        keys = _table_keys(page)
        assert sorted(keys) == sorted(app.catalog.keys())
        error_row = page.locator("tr.error", has_text=BROKEN)
        assert error_row.count() == 1 and "actions.npy" in error_row.inner_text()
        # the single-chunk samples and their mean (the figure is drawn after the rows it shows)
        per_step = page.locator(".inspector-overview figure#per-step-rmse svg.chart path.ln")
        wait_until(lambda: per_step.count() >= 2, what="the per-step RMSE figure's lines")
        select_option(page, "Sort by", "RMSE")
        wait_until(lambda: _numbers(_cells(page, "rmse")) == sorted(_numbers(_cells(page, "rmse"))),
                   what="rows ordered by RMSE")
        page.close()
    finally:
        app.stop()


@pytest.mark.browser
@pytest.mark.slow
def test_overview_screenshot(browser, demo_app, tmp_path):
    """The demo's overview; refreshes docs/overview.png when INSPECTOR_DOCS_SCREENSHOT=1."""
    page, tab = _open(browser, demo_app, draw_3d=True)
    hide_software_webgl_notice(page)
    page.locator(".inspector-overview figure#drift svg.chart").first.wait_for(state="visible")
    page.wait_for_timeout(1000)  # let the layout settle
    out = tmp_path / "overview.png"
    page.screenshot(path=str(out))
    if os.environ.get("INSPECTOR_DOCS_SCREENSHOT"):
        DOCS_SCREENSHOT.write_bytes(out.read_bytes())
    page.close()


@pytest.mark.slow
def test_the_rollout_behind_the_overview_decodes_no_video_until_it_steps_aside(monkeypatch):
    """The rollout a tab opens with, behind its overview, stays undecoded while the rows are
    computed (held here until released, so nothing else can finish them); a rollout opened on
    purpose decodes at once, and hiding the overview starts the one it covered."""
    from test_app import connect

    release = threading.Event()
    compute = OverviewRows._run

    def held(rows):
        release.wait(120)
        compute(rows)

    monkeypatch.setattr(OverviewRows, "_run", held)
    app = serve([BUNDLED_DEMO], port=0, block=False)
    clients = []
    try:
        client, first = connect(app)
        clients.append(client)
        assert first.overview.visible and first.loaded is not None and first.loaded.frames.views
        behind = first.loaded
        assert not behind.frames.started and not behind.frames.decoded.is_set()

        client, second = connect(app)
        clients.append(client)
        other = next(k for k in app.catalog.keys() if k != first.key and app.catalog.get(k).error is None)
        assert second.overview.visible and second.open(other)
        assert second.loaded is not None and second.loaded.frames.views and second.loaded.frames.started
        assert not behind.frames.started and not app.overview_rows.done.is_set()

        first.overview.hide()
        assert behind.frames.started and behind.frames.decoded.wait(120)
        assert not app.overview_rows.done.is_set()
    finally:
        release.set()
        for client in clients:
            client.close()
        app.stop()
