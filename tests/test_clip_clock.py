"""The clip clock: the server's side of "the arms follow the clip the page plays" (no browser;
tests/test_app_browser.py measures it in a page)."""

from __future__ import annotations

import json

import pytest

from inspector.app._clip_clock import BACK_STEPS, SILENT_AFTER_S, ClipClock, parse_report

FPS = 30.0


def report(clip, t, playing=True, ended=False, shown=None) -> str:
    return json.dumps({"clip": clip, "t": t, "playing": playing, "ended": ended, "shown": shown, "n": 1})


def following(start=100, end=400, step=130, now=0.0) -> ClipClock:
    clock = ClipClock()
    clock.report('{"clip": null}')  # the page says it keeps the clock
    clock.shown(7, start, end, FPS, step, now=now)
    return clock


def test_a_page_that_never_reports_keeps_the_servers_clock():
    clock = ClipClock()
    clock.shown(1, 0, 300, FPS, 0, now=0.0)
    assert clock.step(now=0.5) is None


def test_the_swap_step_holds_until_the_clip_plays_then_the_clip_leads():
    clock = following()
    assert clock.step(now=1.0) == 130  # the clip is loading in the page: the arms wait for it
    assert clock.report(report(7, 1.0, playing=False), received=1.2)
    assert clock.step(now=1.5) == 130  # not playing yet: where the clip stands
    assert clock.report(report(7, 1.0), received=2.0)
    assert clock.step(now=2.0) == 130
    assert clock.step(now=2.5) == 130 + 15  # between reports: ahead at the clip's rate
    assert clock.step(now=4.0) == 130 + 60  # however busy the page is


def test_silence_gives_the_clock_back_to_the_server():
    clock = following()
    assert clock.step(now=SILENT_AFTER_S + 0.1) is None  # the clip never started in the page
    clock.report(report(7, 1.0), received=10.0)
    assert clock.step(now=10.0) == 130
    assert clock.step(now=10.0 + SILENT_AFTER_S + 0.1) is None  # the page fell silent


def test_reports_of_another_clip_or_hostile_ones_are_ignored():
    clock = following()
    for text in ["", "nan", "[]", "{}", '{"clip": "7", "t": 1}', '{"clip": 7, "t": -1}',
                 '{"clip": 7, "t": NaN}', '{"clip": 7, "t": Infinity}', '{"clip": true, "t": 1}',
                 '{"clip": 7, "t": "1"}', report(6, 1.0), "x" * 10_000]:
        assert not clock.report(text, received=1.0), text
    assert clock.step(now=1.0) == 130
    assert parse_report(report(7, 2.0, shown=True), 0.0).shown is None  # a bool is no step


def test_the_end_of_the_clip_moves_playback_on_and_the_arms_never_step_back_for_jitter():
    clock = following()
    clock.report(report(7, 10.0, playing=False, ended=True), received=1.0)
    assert clock.step(now=1.1) == 400
    assert ClipClock.follow(200, 198) == 200
    assert ClipClock.follow(200, 200 - BACK_STEPS - 1) == 200 - BACK_STEPS - 1  # a restarted clip
    assert ClipClock.follow(200, 230) == 230


def test_the_lead_is_the_lag_the_page_shows_steps_with_and_pause_takes_the_clip_itself():
    clock = following()
    clock.report(report(7, 1.0), received=1.0)
    sent = {}
    now = 1.0
    while now < 4.0:  # the play loop sends a step every 1/30 s; the page shows each 0.3 s later
        step = clock.step(now=now)
        clock.sent(step, now)
        sent.setdefault(step, now)
        shown = max((s for s, t in sent.items() if t <= now - 0.3), default=None)
        if round(now * 30) % 3 == 0:  # a report every 0.1 s
            clock.report(report(7, now, shown=shown), received=now)
        now += 1 / 30
    assert clock.lead_s == pytest.approx(0.3, abs=0.05)
    assert clock.step(now=now) - clock.step(now=now, lead=False) == pytest.approx(0.3 * FPS, abs=2)
    clock.stop()
    assert clock.step(now=now) is None
