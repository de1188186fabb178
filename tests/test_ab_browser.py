"""Blind A/B mode in a real browser (Debian Chromium via Playwright): two copies of the demo, one
with a planted worse checkpoint; votes cast by keys; ``inspector rank`` puts the planted one last,
and no session or model name reaches the page before its vote.

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

import pytest
from browser import launch, open_page, skip_reason, wait_until

from inspector.app import serve
from inspector.data.votes import read_votes

_reason = skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.slow] + ([pytest.mark.skip(reason=_reason)] if _reason else [])

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
GOOD = {"dir": "run_k7", "name": "ckpt_alpha_7731", "model": "alpha-model-x"}
WORSE = {"dir": "run_q2", "name": "ckpt_omega_1942", "model": "omega-model-y"}
SECRETS = [GOOD["name"], GOOD["model"], WORSE["name"], WORSE["model"], GOOD["dir"], WORSE["dir"]]
VOTES = 6  # the last one a tie


def _copy(dest: Path, who: dict) -> Path:
    shutil.copytree(DEMO, dest, ignore=shutil.ignore_patterns("votes.json", "outcomes.json", ".*.lock"))
    meta = json.loads((dest / "session.json").read_text())
    meta["name"], meta["model"] = who["name"], {"name": who["model"]}
    (dest / "session.json").write_text(json.dumps(meta))
    return dest


def _uri(path: Path) -> str:
    return "data:video/mp4;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def test_blind_votes_by_keys_rank_the_planted_worse_checkpoint_last(tmp_path):
    good, worse = _copy(tmp_path / GOOD["dir"], GOOD), _copy(tmp_path / WORSE["dir"], WORSE)
    for rollout in (worse / "rollouts").iterdir():
        shutil.copyfile(good / "rollouts" / rollout.name / "video" / "wrist.mp4", rollout / "video" / "front.mp4")
    good_front = {_uri(r / "video" / "front.mp4") for r in (good / "rollouts").iterdir()}

    from playwright.sync_api import sync_playwright

    app = serve([good, worse], port=0, block=False, ab=True)
    try:
        with sync_playwright() as p:
            browser = launch(p)
            page = open_page(browser, 1400, 900)
            page.goto(app.url)
            page.wait_for_selector("[data-ab-pair='1'] [data-ab-side='B'] video")
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
                wait_until(lambda: page.locator(f"[data-ab-pair='{k + 1}']").count() == 1, what=f"pair {k + 1}")
                revealed = page.locator("[data-ab-revealed]").inner_text()
                assert GOOD["name"] in revealed and WORSE["name"] in revealed
            browser.close()
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
