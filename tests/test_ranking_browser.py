"""Ranking in a real browser (Debian Chromium via Playwright): blind A/B mode on two copies of the
demo, one with a planted worse checkpoint (votes cast by keys; ``inspector rank`` puts the planted
one last, and no session or model name reaches the page before its vote); and the pages of
``rank --html`` and ``agreement --html`` drawing their figures.

The planted worse checkpoint imagines the wrong camera: each rollout's imagined ``front`` video is
the good copy's ``wrist`` video. The test plays the evaluator: the side whose imagined video is a
good copy's ``front`` video is the better one.
"""

from __future__ import annotations

import base64
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from browser import SCENE_OFF_SCREEN_JS, app_url, open_page, skip_reason, wait_until

from inspector.app import serve
from inspector.data.session import SessionWriter
from inspector.outcomes import OUTCOMES_FILE, store_records
from inspector.report.agreement import build_agreement
from inspector.report.decision_html import write_agreement_html, write_ranking_html
from inspector.report.ranking import build_ranking
from inspector.said.votes import read_votes

_reason = skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.slow] + ([pytest.mark.skip(reason=_reason)] if _reason else [])

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
GOOD = {"dir": "run_k7", "name": "ckpt_alpha_7731", "model": "alpha-model-x"}
WORSE = {"dir": "run_q2", "name": "ckpt_omega_1942", "model": "omega-model-y"}
SECRETS = [GOOD["name"], GOOD["model"], WORSE["name"], WORSE["model"], GOOD["dir"], WORSE["dir"]]
VOTES = 6  # the last one a tie
REVEALED = "() => document.querySelector('[data-ab-revealed]')?.textContent || ''"  # the names shown after a vote


def _copy(dest: Path, who: dict) -> Path:
    shutil.copytree(DEMO, dest, ignore=shutil.ignore_patterns("votes.json", "outcomes.json", ".*.lock"))
    meta = json.loads((dest / "session.json").read_text())
    meta["name"], meta["model"] = who["name"], {"name": who["model"]}
    (dest / "session.json").write_text(json.dumps(meta))
    return dest


def _uri(path: Path) -> str:
    return "data:video/mp4;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def test_blind_votes_by_keys_rank_the_planted_worse_checkpoint_last(tmp_path, browser):
    good, worse = _copy(tmp_path / GOOD["dir"], GOOD), _copy(tmp_path / WORSE["dir"], WORSE)
    for rollout in (worse / "rollouts").iterdir():
        shutil.copyfile(good / "rollouts" / rollout.name / "video" / "wrist.mp4", rollout / "video" / "front.mp4")
    good_front = {_uri(r / "video" / "front.mp4") for r in (good / "rollouts").iterdir()}

    app = serve([good, worse], port=0, block=False, ab=True)
    try:
        page = open_page(browser, 1400, 900)
        page.add_init_script(SCENE_OFF_SCREEN_JS)  # votes and figures, not the 3D view (see browser.open_app)
        page.goto(app_url(app.url))
        page.wait_for_selector("[data-ab-pair='1'] [data-ab-side='B'] video")
        for side in ("A", "B"):  # each side's arm: six joint lines drawn
            lines = page.locator(f"[data-ab-joints='{side}'] svg.chart path.ln")
            assert lines.count() == 6 and lines.first.bounding_box()["width"] > 50
        # each side's arms, predicted and GT (the demo has GT), in the page's 3D view
        tab = wait_until(lambda: next(iter(app.ab_tabs.values()), None), what="the A/B tab")
        assert tab.arms is not None and all(d is not None and d.q_gt is not None for d in tab.arms.data.values())
        assert page.locator("canvas").first.bounding_box()["width"] > 200
        html = page.content()
        assert not [s for s in SECRETS if s in html], "a name reached the page before the vote"
        for k in range(1, VOTES + 1):
            pair = page.locator(f"[data-ab-pair='{k}']")
            pair.wait_for()
            assert not [s for s in SECRETS if s in pair.inner_html()]
            src = {side: page.locator(f"[data-ab-side='{side}'] video[data-ab-video='imagined']").get_attribute("src")
                   for side in ("A", "B")}
            better = "A" if src["A"] in good_front else "B"
            assert (src["B"] in good_front) == (better == "B")  # exactly one side is the good copy
            if k == 1:  # a progress score for A, typed, then the focus back on the page
                page.get_by_label("progress A [%]").fill("80")
                page.get_by_label("progress A [%]").press("Tab")
                page.evaluate("document.activeElement && document.activeElement.blur()")
            page.keyboard.press("=" if k == VOTES else better.lower())
            # the names show beside the pair just judged, and go when the next pair comes
            wait_until(lambda: all(s in page.evaluate(REVEALED) for s in (GOOD["name"], WORSE["name"])),
                       what=f"pair {k}'s names")
            wait_until(lambda: page.locator(f"[data-ab-pair='{k + 1}']").count() == 1, what=f"pair {k + 1}")
            wait_until(lambda: page.evaluate(REVEALED) == "", what=f"no names beside pair {k + 1}")
        page.close()
    finally:
        app.stop()

    votes = read_votes(good)
    assert len(votes) == VOTES and [v.id for v in votes] == [v.id for v in read_votes(worse)]
    assert votes[0].a.progress == 80.0 and votes[-1].answer == "tie"
    for v in votes[:-1]:  # every decisive vote went to the good copy
        winner = v.a if v.answer == "a" else v.b
        assert winner.name == GOOD["name"]
    run = subprocess.run([sys.executable, "-m", "inspector", "rank", str(good), str(worse), "--json",
                          "--bootstrap", "200"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    ranking = json.loads(run.stdout)["ranking"]
    assert [r["session"] for r in ranking] == [GOOD["name"], WORSE["name"]]


# imagined and real success out of 4 rollouts per checkpoint (one task)
RATES = {"c1": (4, 3), "c2": (2, 2), "c3": (1, 0), "c4": (3, 4)}


def _judged_session(dest: Path, checkpoint: str, successes: int) -> Path:
    with SessionWriter.create(dest, model={"name": checkpoint}) as writer:
        for i in range(4):
            writer.add_rollout(f"r{i}", kind="single_chunk", actions=np.zeros((1, 9, 6)), prompt="pick", start_frame=i)
    store_records(dest / OUTCOMES_FILE, {f"r{i}": {"success": i < successes} for i in range(4)}, source="file",
                  set_by="judge")
    return dest


def _drawn_points(page) -> list[dict]:
    """The figure's dots as drawn: their centres in data units, read back through the SVG's mapping."""
    return page.evaluate("""() => {
      const svg = document.querySelector('svg.chart');
      const [x0, x1, px0, px1] = svg.dataset.x.split(' ').map(Number);
      const [y0, y1, py0, py1] = svg.dataset.y.split(' ').map(Number);
      return [...svg.querySelectorAll('circle')].map((c) => {
        const box = c.getBoundingClientRect();
        const cx = Number(c.getAttribute('cx')), cy = Number(c.getAttribute('cy'));
        return {x: x0 + (cx - px0) / (px1 - px0) * (x1 - x0), y: y0 + (cy - py0) / (py1 - py0) * (y1 - y0),
                w: box.width, key: c.closest('[data-key]') ? c.closest('[data-key]').dataset.key : c.dataset.key};
      });
    }""")


def test_agreement_and_ranking_pages_draw_their_figures(tmp_path, browser):
    imagined = [_judged_session(tmp_path / f"i_{c}", c, n) for c, (n, _) in RATES.items()]
    real = [_judged_session(tmp_path / f"r_{c}", c, n) for c, (_, n) in RATES.items()]
    pages = {"agreement": write_agreement_html(build_agreement(imagined, real, n_bootstrap=200),
                                               tmp_path / "agreement.html"),
             "rank": write_ranking_html(build_ranking(real, n_bootstrap=200), tmp_path / "rank.html")}
    page = open_page(browser, 1000, 800)
    page.goto(pages["agreement"].as_uri())
    dots = _drawn_points(page)
    assert len(dots) == len(RATES) and all(d["w"] > 0 for d in dots)
    got = sorted((d["x"], d["y"]) for d in dots)
    expected = sorted((i / 4, r / 4) for i, r in RATES.values())
    assert np.allclose(got, expected, atol=0.005), (got, expected)
    assert page.locator("svg.chart path, svg.chart polyline").count() >= 1  # the diagonal
    page.goto(pages["rank"].as_uri())
    dots = _drawn_points(page)
    # best first: x is the rank, y the success rate
    assert np.allclose([d["y"] for d in sorted(dots, key=lambda d: d["x"])], [1.0, 0.75, 0.5, 0.0], atol=0.005)
    assert all(d["w"] > 0 for d in dots)
    page.close()
