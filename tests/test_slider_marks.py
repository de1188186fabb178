"""Marks set on a slider already on the page reach the page as ``add_slider(marks=...)`` sends them.

viser has no public way to change a slider's marks after it is added; ``inspector.app._slider_marks``
uses its private ``_build_slider_marks`` and the handle's ``_marks`` prop. These tests run the
installed viser, with a real websocket client reading what the page would get, so a viser release
that renames or reshapes either fails here rather than leaving the chunk slider silently unmarked.
"""

from __future__ import annotations

import pytest

viser = pytest.importorskip("viser")

from inspector.app._headless import HeadlessClient  # noqa: E402
from inspector.app._slider_marks import set_slider_marks  # noqa: E402

pytestmark = pytest.mark.slow  # a viser server and a websocket client

MARKS = ((0, "0"), (3, "seam"), (7, "done"))


@pytest.fixture
def page():
    """A viser server and a client reading its GUI messages as a page would."""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        with HeadlessClient(server.get_port(), observe=True) as client:
            client.wait_until(lambda: len(server.get_clients()) == 1, timeout=60, what="the client")
            yield server, client
    finally:
        server.stop()


def test_marks_set_later_reach_the_page_as_add_slider_sends_them(page):
    server, client = page
    reference = server.gui.add_slider("Reference", 0, 10, 1, 0, marks=MARKS)
    slider = server.gui.add_slider("Chunk", 0, 10, 1, 0)
    client.wait_for_control("Chunk")
    sent = client.control(client.wait_for_control("Reference"))["props"]["_marks"]
    assert sent and len(sent) == len(MARKS), "add_slider sends no marks: viser changed how marks are sent"
    assert client.control(client.find_control("Chunk"))["props"].get("_marks") is None

    set_slider_marks(slider, MARKS)
    assert slider._marks == reference._marks  # the same objects add_slider made of the same marks
    client.wait_until(lambda: client.control(client.find_control("Chunk"))["props"].get("_marks") == sent,
                      timeout=60, what="the marks on the page")

    set_slider_marks(slider, ())  # no marks: none on the page
    client.wait_until(lambda: client.control(client.find_control("Chunk"))["props"].get("_marks") is None,
                      timeout=60, what="the marks removed from the page")


def test_unchanged_marks_send_nothing(page, monkeypatch):
    server, _ = page
    slider = server.gui.add_slider("Chunk", 0, 10, 1, 0)
    set_slider_marks(slider, MARKS)
    queued: list[tuple[str, object]] = []
    monkeypatch.setattr(slider, "_queue_update", lambda name, value: queued.append((name, value)))
    set_slider_marks(slider, MARKS)
    assert queued == []
    set_slider_marks(slider, MARKS[:1])
    assert [name for name, _ in queued] == ["_marks"]
