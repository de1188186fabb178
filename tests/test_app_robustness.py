"""The app under stress and attack: simultaneous browser clients, what it reads, where it listens,
and annotation writers killed mid-write (DESIGN §6 and §9).

- Four real Chromium pages on one server keep four timelines; closing them mid-playback leaves
  no playback thread behind, and the server logs no exception.
- A rollout (or a file in it, or ``annotations.json``) that is a symbolic link out of the served
  session is refused before it is read; the other rollouts keep working.
- ``inspector serve`` listens on loopback only unless ``--host``; a share URL only on ``--share``.
- An annotations writer SIGKILLed at any moment leaves a complete ``annotations.json``.

Reuses the fixtures of ``test_app`` (the bundled demo's rollouts copied into sessions) and the page
helpers of ``test_app_browser``.
"""

from __future__ import annotations

import contextlib
import html
import ipaddress
import json
import logging
import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path

import pytest
from browser import (
    PAGE_TIMEOUT_S,
    SCENE_OFF_SCREEN_JS,
    app_url,
    frame_sources,
    open_page,
    skip_reason,
    slider_thumb,
    wait_until,
)
from test_app import (  # noqa: F401  (app and sessions are fixtures)
    BROKEN,
    CARRIED_GT,
    LIMITS,
    LONG,
    NOVEL,
    OTHER_SINGLE,
    SINGLE,
    TRAIN,
    app,
    connect,
    key,
    sessions,
)
from test_app_browser import open_in_page, page_tab

from inspector.app import HeadlessClient, serve
from inspector.data.sources import check_confined, open_sources
from inspector.errors import InspectorError
from inspector.said.annotations import read_annotations, update_annotation

pytestmark = pytest.mark.slow  # browser pages, served apps and commands killed mid-write

ESCAPE = "resolves outside the served roots"


# ----------------------------------------------------------------------------------------------
# Server-side errors


@pytest.fixture
def server_errors(monkeypatch):
    """Every exception the server reports, however it reports it.

    viser prints the exceptions of GUI callbacks and connect/disconnect handlers with
    ``traceback.print_exception``; a dying thread goes through ``threading.excepthook``; asyncio
    and websockets log at ERROR. All three are recorded (and still reported as before).
    """
    errors: list[str] = []
    print_exception = traceback.print_exception

    def record_print(exc, *args, **kwargs):
        value = args[0] if args and isinstance(args[0], BaseException) else exc
        errors.append(f"traceback.print_exception: {value!r}")
        return print_exception(exc, *args, **kwargs)

    excepthook = threading.excepthook

    def record_thread(args):
        errors.append(f"thread {args.thread.name if args.thread else '?'}: {args.exc_value!r}")
        excepthook(args)

    class Record(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            errors.append(f"log {record.name}: {record.getMessage()}")

    monkeypatch.setattr(traceback, "print_exception", record_print)
    monkeypatch.setattr(threading, "excepthook", record_thread)
    handler = Record(level=logging.ERROR)
    logging.getLogger().addHandler(handler)
    try:
        yield errors
    finally:
        logging.getLogger().removeHandler(handler)


def play_threads(client_ids) -> list[threading.Thread]:
    names = {f"inspector-play-{cid}" for cid in client_ids}
    return [t for t in threading.enumerate() if t.name in names and t.is_alive()]


# ----------------------------------------------------------------------------------------------
# 2. Four simultaneous browser clients

_browser_reason = skip_reason()
WIDTH, HEIGHT = 1024, 700  # small pages: four of them render WebGL in software


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.skipif(_browser_reason is not None, reason=_browser_reason or "")
def test_three_browser_pages_hold_their_own_timelines(browser, app, server_errors, capfd):  # noqa: F811
    chunk, step = re.compile(r"^Chunk$"), re.compile(r"^Step$")
    # Per page: the rollout picked in its picker (None: the one it opens with), the slider it
    # scrubs with the keyboard, how many steps right, and where that puts it (rollout, step).
    # Pages 0 and 2 show the same rollout: each holds its own step and frame.
    default = app.catalog.default_key()
    plan = [(None, chunk, 3, default, 3 * 9), (SINGLE, step, 4, key(app, SINGLE), 4),
            (None, chunk, 10, default, 10 * 9)]
    # Three pages (one context each) load at once.
    pages, page_errors = [], []
    for n in range(len(plan)):
        page = open_page(browser, WIDTH, HEIGHT)
        page.on("pageerror", lambda exc, n=n: page_errors.append(f"page {n}: {exc}"))
        page.add_init_script(SCENE_OFF_SCREEN_JS)  # timelines, not the 3D view (see browser.open_app)
        page.goto(app_url(app.url))
        pages.append(page)
    for page in pages:  # (what browser.open_app waits for)
        page.wait_for_selector("text=SO-101 rollout inspector", timeout=PAGE_TIMEOUT_S * 1000)
        page.wait_for_selector("canvas", timeout=PAGE_TIMEOUT_S * 1000)
    tabs = [page_tab(page, app) for page in pages]
    assert len({t.client_id for t in tabs}) == 3
    for page, tab, (tag, *_) in zip(pages, tabs, plan):
        if tag is not None:
            open_in_page(page, tab, app, tag)
        else:  # the default rollout is open behind the Overview a page starts with
            page.get_by_role("button", name="Close overview").click()
    for page, (_, label, presses, *_) in zip(pages, plan):
        slider_thumb(page, label).focus()
        for _ in range(presses):
            page.keyboard.press("ArrowRight")

    tabs = [page_tab(page, app) for page in pages]  # (the tab serving each page now)
    for n, (tab, (*_, k, s)) in enumerate(zip(tabs, plan)):
        wait_until(lambda: tab.key == k and tab.step == s, timeout=90,
                   what=f"page {n} at {k} step {s} (it is at {tab.key} step {tab.step})")
    # Server side: three tabs, each at its own rollout and step.
    assert len({id(t) for t in tabs}) == 3 and len({t.client_id for t in tabs}) == 3
    assert [(t.key, t.step) for t in tabs] == [(k, s) for *_, k, s in plan]
    assert [t.chunk for t in tabs] == [3, 0, 10]
    # Client side: each page's slider and video show its own position.
    for page, (_, label, presses, *_) in zip(pages, plan):
        assert slider_thumb(page, label).get_attribute("aria-valuenow") == str(presses)

    def shows_own_frame(page, tab) -> bool:
        src = frame_sources(page).get("front/imagined")
        return bool(src) and src in tab.video.html.content

    for n, (page, tab) in enumerate(zip(pages, tabs)):
        wait_until(lambda: shows_own_frame(page, tab), timeout=90, what=f"page {n} to show its tab's frame")
    fronts = [frame_sources(page)["front/imagined"] for page in pages]
    assert len(set(fronts)) == 3, "two pages show the same imagined frame"

    # Play on every page, then close them all while they play.
    for page in pages:
        page.get_by_role("button", name="Play").click()
    ids = [t.client_id for t in tabs]
    autoregressive = [t for t in tabs if t.loaded.timeline.kind == "autoregressive"]
    wait_until(lambda: all(t.playing for t in autoregressive) and len(play_threads(ids)) >= len(autoregressive),
               what="the autoregressive pages to play")
    playing = play_threads(ids)
    for page in pages:
        page.close()
    wait_until(lambda: all(t.closed.is_set() for t in tabs), timeout=60, what="the server to close the tabs")
    wait_until(lambda: not play_threads(ids), timeout=60, what="the playback threads to stop")
    assert playing and not any(t.is_alive() for t in playing)
    assert not set(ids) & set(app.tabs)
    frozen = [t.step for t in tabs]
    time.sleep(0.3)
    assert [t.step for t in tabs] == frozen and not any(t.playing for t in tabs)

    assert not server_errors, "\n".join(server_errors)
    assert not page_errors, "\n".join(page_errors)
    err = capfd.readouterr().err
    assert "Traceback" not in err, err


# ----------------------------------------------------------------------------------------------
# 3. Paths: only under the served roots, never from the browser


class OpenedFiles:
    """Paths opened by this process (``open`` audit events) while ``active``."""

    active: list[str] | None = None
    _installed = False

    @classmethod
    def start(cls) -> list[str]:
        if not cls._installed:  # an audit hook cannot be removed: install one, inert when idle
            def hook(event: str, args) -> None:
                if event == "open" and cls.active is not None and isinstance(args[0], (str, bytes, os.PathLike)):
                    cls.active.append(os.fsdecode(args[0]))
            sys.addaudithook(hook)
            cls._installed = True
        cls.active = []
        return cls.active

    @classmethod
    def stop(cls) -> None:
        cls.active = None


def _under(path: str, root: Path) -> bool:
    p = Path(path)
    return p.resolve().is_relative_to(root.resolve()) if p.is_absolute() else False


INSIDE = BROKEN  # (it loads: only the broken session's copy of it is broken)
PLANTED = (SINGLE, OTHER_SINGLE, CARRIED_GT, INSIDE)


def _all_rollouts_but(keep: tuple[str, ...]):
    """A ``copytree`` ignore that leaves out every rollout but ``keep``."""
    def ignore(directory: str, names: list[str]) -> list[str]:
        return [n for n in names if n not in keep] if Path(directory).name == "rollouts" else []
    return ignore


def plant_links(good: Path, tmp: Path) -> tuple[Path, Path]:
    """A copy of ``good`` with links out of it planted, and the directory they point into.

    - ``rollouts/escaped`` links to a complete rollout outside (a copy of ``OTHER_SINGLE``);
    - ``rollouts/<SINGLE>/video/wrist.mp4`` links to a video outside;
    - ``rollouts/<CARRIED_GT>/gt`` links to a GT directory outside;
    - ``annotations.json`` links to a file outside;
    - ``rollouts/alias`` links to ``INSIDE`` (inside: allowed).

    Only the single-chunk rollouts are copied: the point is which files are read, and the app
    reads (and its Overview computes rows for) every rollout it serves.
    """
    served, outside = tmp / "served" / "sess", tmp / "outside"
    shutil.copytree(good, served, symlinks=True, ignore=_all_rollouts_but(PLANTED))
    outside.mkdir()
    rollouts = served / "rollouts"
    shutil.copytree(rollouts / OTHER_SINGLE, outside / "other_copy")
    (rollouts / "escaped").symlink_to(outside / "other_copy", target_is_directory=True)
    wrist = rollouts / SINGLE / "video" / "wrist.mp4"
    shutil.move(wrist, outside / "wrist.mp4")
    wrist.symlink_to(outside / "wrist.mp4")
    shutil.move(rollouts / CARRIED_GT / "gt", outside / "gt")
    (rollouts / CARRIED_GT / "gt").symlink_to(outside / "gt", target_is_directory=True)
    (outside / "annotations.json").write_text('{"rollouts": {"planted": {"note": "outside"}}}\n')
    (served / "annotations.json").symlink_to(outside / "annotations.json")
    (rollouts / "alias").symlink_to(INSIDE, target_is_directory=True)
    return served, outside


def test_links_out_of_the_served_root_are_refused(sessions, tmp_path):  # noqa: F811
    served, outside = plant_links(sessions[0], tmp_path)
    before = {p: p.read_bytes() for p in outside.rglob("*") if p.is_file()}
    opened = OpenedFiles.start()
    try:
        served_app = serve([served], port=0, block=False)
        try:
            errors = {e.tag: e.error for e in served_app.catalog.entries.values()}
            for tag, where in (("escaped", "rollouts/escaped"), (SINGLE, f"rollouts/{SINGLE}/video/wrist.mp4"),
                               (CARRIED_GT, f"rollouts/{CARRIED_GT}/gt")):
                assert isinstance(errors[tag], InspectorError) and ESCAPE in str(errors[tag]), errors[tag]
                assert errors[tag].file.endswith(where), errors[tag].file
            ok = {t for t, e in errors.items() if e is None}
            assert ok == {"alias", INSIDE, OTHER_SINGLE}
            client, tab = connect(served_app)
            with client:
                for tag, name in (("escaped", "escaped"), (SINGLE, "wrist.mp4"), (CARRIED_GT, "gt")):
                    assert not tab.open(key(served_app, tag))
                    card = tab.controls.error.content
                    assert tab.controls.error.visible and ESCAPE in card and name in card, card
                for tag in (INSIDE, "alias"):
                    assert tab.open(key(served_app, tag)), tab.error
                    assert tab.loaded.frames.done.wait(180)
                # annotations.json leads out: the notes say so, and nothing is read or written there.
                assert ESCAPE in tab.controls.notes_info.content
                assert not tab.save_notes(rollout_flag=True, rollout_note="mine")
                assert ESCAPE in tab.controls.notes_info.content
                assert (served / "annotations.json").is_symlink()
                # A link planted after start-up is refused when the rollout is first opened.
                video = served / "rollouts" / OTHER_SINGLE / "video" / "front.mp4"
                shutil.move(video, outside / "late.mp4")
                video.symlink_to(outside / "late.mp4")
                assert not tab.open(key(served_app, OTHER_SINGLE))
                assert ESCAPE in tab.controls.error.content and "front.mp4" in tab.controls.error.content
                assert tab.open(key(served_app, INSIDE))  # and the others still work
        finally:
            served_app.stop()
    finally:
        OpenedFiles.stop()
    assert {p: p.read_bytes() for p in before} == before  # nothing outside was written
    read_outside = sorted({p for p in opened if _under(p, outside)})
    assert not read_outside, f"opened outside the served root: {read_outside}"
    assert any(_under(p, served) for p in opened)  # (the hook did see the reads inside)


def test_check_confined_walks_links_once_and_names_the_entry(tmp_path):
    root, outside = tmp_path / "root", tmp_path / "outside"
    (root / "a" / "b").mkdir(parents=True)
    outside.mkdir()
    (root / "a" / "b" / "loop").symlink_to("../..", target_is_directory=True)  # a cycle inside
    (root / "a" / "self").symlink_to("self")  # a link to itself (dangling, inside)
    check_confined(root / "a", [root])  # terminates, and inside is fine
    (root / "a" / "b" / "dangling").symlink_to(outside / "missing")
    with pytest.raises(InspectorError, match=ESCAPE) as info:
        check_confined(root / "a", [root])
    assert info.value.file == str(root / "a" / "b" / "dangling")
    (root / "a" / "b" / "dangling").unlink()
    (root / "a" / "b" / "up").symlink_to("../../..", target_is_directory=True)  # out through '..'
    with pytest.raises(InspectorError, match=ESCAPE):
        check_confined(root / "a", [root])


def test_unconfined_open_still_follows_links(sessions, tmp_path):  # noqa: F811
    """``report`` and ``export`` open what the user points at; only the app confines."""
    served, outside = plant_links(sessions[0], tmp_path)
    opened = OpenedFiles.start()
    try:
        sources = open_sources([served])
    finally:
        OpenedFiles.stop()
    try:
        assert "escaped" in sources.sessions[0].rollouts and SINGLE in sources.sessions[0].rollouts
    finally:
        sources.close()
    # (which shows the audit hook of the test above does see reads through such links)
    assert any(_under(p, outside) for p in opened)
    sources = open_sources([served], confine=True)
    try:
        assert sources.serves(served / "rollouts" / INSIDE) and not sources.serves(tmp_path / "outside")
        assert {"escaped", SINGLE, CARRIED_GT} <= set(sources.sessions[0].errors)
    finally:
        sources.close()


def test_annotations_lock_link_is_not_followed(tmp_path):
    outside = tmp_path / "outside.txt"
    outside.write_text("keep")
    root = tmp_path / "s"
    root.mkdir()
    (root / ".annotations.lock").symlink_to(outside)
    with pytest.raises(InspectorError, match="symbolic link"):
        update_annotation(root, "r", flag=True)
    assert outside.read_text() == "keep" and not (root / "annotations.json").exists()


# Hand-edited or hostile annotations.json files, and what the reader says about each.
HOSTILE_ANNOTATIONS = {
    "nested-100k-deep": ("[" * 100_000, "invalid JSON (RecursionError"),
    "5000-digit-integer": ('{"rollouts": {}, "n": 1' + "0" * 5000 + "}", "invalid JSON (ValueError: Exceeds the limit"),
    "chunks-a-list": (json.dumps({"rollouts": {SINGLE: {"chunks": [1, 2]}}}),
                      f"rollouts.{SINGLE}.chunks: expected an object, found list"),
    "flag-a-string": (json.dumps({"rollouts": {SINGLE: {"flag": "yes"}}}),
                      f"rollouts.{SINGLE}.flag: expected true or false, found 'yes'"),
    "chunk-key-not-an-index": (json.dumps({"rollouts": {OTHER_SINGLE: {"chunks": {"x": {}}}}}),
                               "expected chunk indexes as keys, found 'x'"),
    "rollouts-a-string": ('{"rollouts": "all"}', "rollouts: expected an object, found 'all'"),
    "nan": ('{"rollouts": {}, "score": NaN}', "score: non-finite number nan"),
    "not-utf8": (b"\xff\xfe\x00{", "invalid JSON"),
    "a-directory": (None, "is a directory, not a file"),
}


def _plant_annotations(root: Path, content: str | bytes | None) -> None:
    path = root / "annotations.json"
    if path.is_dir():
        path.rmdir()
    elif path.exists():
        path.unlink()
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content.encode() if isinstance(content, str) else content)


def _snapshot(path: Path) -> bytes | str:
    return "<directory>" if path.is_dir() else path.read_bytes()


@pytest.mark.parametrize("name", HOSTILE_ANNOTATIONS)
def test_hostile_annotations_are_reported_and_kept(tmp_path, name):
    content, message = HOSTILE_ANNOTATIONS[name]
    _plant_annotations(tmp_path, content)
    before = _snapshot(tmp_path / "annotations.json")
    for call in (lambda: read_annotations(tmp_path), lambda: update_annotation(tmp_path, "f084", flag=True)):
        with pytest.raises(InspectorError) as err:
            call()
        assert err.value.file == str(tmp_path / "annotations.json")
        assert message in err.value.what and err.value.what.endswith("not overwriting it"), err.value.what
        assert "\n" not in str(err.value)
    assert _snapshot(tmp_path / "annotations.json") == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [".annotations.lock", "annotations.json"]


def test_app_shows_hostile_annotations_on_the_notes_panel(sessions, tmp_path, server_errors):  # noqa: F811
    """Each hostile ``annotations.json`` in a served session: the Notes panel shows the error,
    saving notes is refused and leaves the file as it was, and the rest of the app works (the
    rollout opens and scrubs; the server logs no exception)."""
    served = tmp_path / "sess"
    shutil.copytree(sessions[0], served)
    for tag in (LONG, TRAIN, NOVEL, LIMITS, CARRIED_GT, BROKEN):
        shutil.rmtree(served / "rollouts" / tag)
    served_app = serve([served], port=0, block=False)
    try:
        client, tab = connect(served_app)
        with client:
            for i, (name, (content, message)) in enumerate(HOSTILE_ANNOTATIONS.items()):
                _plant_annotations(served, content)
                before = _snapshot(served / "annotations.json")
                tag = (SINGLE, OTHER_SINGLE)[i % 2]  # a rollout opened anew reads the notes anew
                assert tab.open(key(served_app, tag)), (name, tab.error)
                notes = tab.controls.notes_info.content
                assert "inspector-error-card" in notes and "annotations.json" in notes, (name, notes)
                assert html.escape(message, quote=True) in notes, (name, notes)
                assert not tab.save_notes(rollout_flag=True, rollout_note="mine", chunk_flag=True)
                assert "notes not saved" in tab.controls.notes_info.content, name
                assert _snapshot(served / "annotations.json") == before, name
                assert tab.set_step(5) == 5 and tab.chunk == 0  # the rest keeps working
            # a sound file again: notes save
            _plant_annotations(served, '{"rollouts": {}}')
            assert tab.open(key(served_app, SINGLE)) and tab.save_notes(rollout_flag=True, rollout_note="ok")
            assert read_annotations(served)["rollouts"][SINGLE]["note"] == "ok"
    finally:
        served_app.stop()
    assert server_errors == []


def test_browser_names_sent_over_the_wire_are_not_paths(app, sessions):  # noqa: F811
    """What a hostile page could send to the picker and compare dropdowns: never opened as a path."""
    client, tab = connect(app)
    with client:
        compared: list[str | None] = []
        set_compare = tab.set_compare
        tab.set_compare = lambda k: (compared.append(k), set_compare(k))[1]  # (what the dropdown calls)
        files = OpenedFiles.start()
        try:
            values = ("../../../../etc/passwd", "/etc/passwd", str(sessions[0] / "rollouts" / SINGLE),
                      "demo / ../../etc")
            for value in values:
                client.set_gui_value(tab.controls.picker._impl.uuid, value)
                client.set_gui_value(tab.controls.compare._impl.uuid, value)
            # every hostile value handled (viser runs callbacks on a pool: a straggler that snaps
            # the picker back must not land after the real choice below)
            wait_until(lambda: len(compared) >= len(values), timeout=60, what="the hostile values to reach the tab")
            time.sleep(1.0)
            # Then a real choice, sent the same way: the tab opens it, and only it.
            target = key(app, SINGLE)
            client.set_gui_value(tab.controls.picker._impl.uuid, tab.controls.key_to_option[target])
            wait_until(lambda: tab.key == target and tab.loaded is not None, timeout=60, what=f"{SINGLE} to open")
            time.sleep(0.5)  # (stragglers on viser's pool)
        finally:
            OpenedFiles.stop()
        assert set(compared) <= {*values, None} and tab.compare is None  # (None: "no compare")
        assert tab.key == target and tab.controls.picker.value == tab.controls.key_to_option[target]
        assert not [p for p in files if "passwd" in p or p.endswith("/etc")]


# ----------------------------------------------------------------------------------------------
# 4. Loopback by default; the share link only on --share


def listening(pid: int | None = None, port: int | None = None) -> set[tuple[str, int]]:
    """``(address, port)`` of the TCP sockets in LISTEN, from /proc/net/tcp and tcp6.

    Args:
        pid: only the sockets this process holds (its /proc/<pid>/fd links).
        port: only this port.
    """
    inodes = None
    if pid is not None:
        inodes = set()
        for fd in Path(f"/proc/{pid}/fd").iterdir():
            with contextlib.suppress(OSError):
                if m := re.fullmatch(r"socket:\[(\d+)\]", os.readlink(fd)):
                    inodes.add(m.group(1))
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except FileNotFoundError:
            continue
        for row in rows:
            fields = row.split()
            address, hex_port = fields[1].split(":")
            if fields[3] != "0A":  # TCP_LISTEN
                continue
            if (port is not None and int(hex_port, 16) != port) or (inodes is not None and fields[9] not in inodes):
                continue
            raw = bytes.fromhex(address)
            # The kernel prints each 32-bit word in host (little-endian) order.
            raw = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
            found.add((str(ipaddress.ip_address(raw)), int(hex_port, 16)))
    return found


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _ctrl_c_as_at_a_terminal() -> None:
    """In the child before exec: SIGINT at its default. A shell that runs the tests as a background
    job hands its children SIGINT ignored, and Python then never turns it into KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start_cli_serve(session: Path, *extra: str, env: dict[str, str] | None = None,
                    ) -> tuple[subprocess.Popen, list[str], threading.Thread]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "inspector", "serve", str(session), "--port", str(free_port()), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, preexec_fn=_ctrl_c_as_at_a_terminal,
        env=dict(os.environ, PYTHONUNBUFFERED="1", **(env or {})))
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()
    return proc, lines, reader


def served_port(proc, lines) -> int:
    def port():
        match = re.search(r"inspector: serving .* at http://[^:]+:(\d+)", "".join(lines))
        assert proc.poll() is None or match, "".join(lines)
        return int(match.group(1)) if match else None

    return wait_until(port, timeout=180, what="inspector serve to start")


def stop_cli(proc, reader, how: signal.Signals = signal.SIGINT) -> None:
    """Ctrl-C (or ``kill``'s SIGTERM), as a user stops ``inspector serve``: the app stops and the
    process exits at once, without waiting for its background decoding (a busy machine may still
    take a while to run even that: the deadline is generous, and a process that misses it is
    killed, failing the test's exit-code check)."""
    if proc.poll() is None:
        proc.send_signal(how)
        try:
            proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
    reader.join(timeout=10)


@pytest.mark.skipif(not Path("/proc/net/tcp").is_file(), reason="needs Linux /proc/net/tcp")
def test_serve_binds_loopback_unless_host_is_given(sessions):  # noqa: F811
    default, default_lines, default_reader = start_cli_serve(sessions[0])
    exposed, exposed_lines, exposed_reader = start_cli_serve(sessions[0], "--host", "0.0.0.0")
    try:
        port = served_port(default, default_lines)
        assert wait_until(lambda: listening(port=port), what="the default server's socket")
        # Every socket the server process listens on is loopback (never 0.0.0.0 or ::).
        sockets = listening(pid=default.pid)
        assert {p for _, p in sockets} == {port} and {a for a, _ in sockets} <= {"127.0.0.1", "::1"}, sockets
        assert listening(port=port) == sockets  # and no one else took the port
        with HeadlessClient(port):  # it does serve, on loopback
            time.sleep(0.5)
        # --host 0.0.0.0 binds every interface (only looked at; no traffic sent there).
        port2 = served_port(exposed, exposed_lines)
        assert wait_until(lambda: listening(port=port2), what="the exposed server's socket")
        sockets2 = listening(pid=exposed.pid)
        assert {a for a, _ in sockets2} & {"0.0.0.0", "::"}, sockets2
    finally:
        stop_cli(default, default_reader)
        stop_cli(exposed, exposed_reader)
    for lines in (default_lines, exposed_lines):
        assert "share URL" not in "".join(lines), "".join(lines)
    for proc, lines in ((default, default_lines), (exposed, exposed_lines)):
        assert proc.returncode in (0, 130), "".join(lines)
    assert not listening(port=port) and not listening(port=port2)


def test_sigterm_stops_serve_and_removes_imported_sessions(dz_layout, tmp_path):
    """``kill`` / ``docker stop`` stop the server as Ctrl-C does: exit status 0, and the temporary
    session a raw model output was imported into is gone from the temp folder."""
    temp = tmp_path / "tmp"
    temp.mkdir()
    proc, lines, reader = start_cli_serve(dz_layout / "demo", env={"TMPDIR": str(temp)})
    try:
        served_port(proc, lines)
        imported = [p.name for p in temp.iterdir()]
        assert any(name.startswith("inspector-session-") for name in imported), (imported, "".join(lines))
    finally:
        stop_cli(proc, reader, how=signal.SIGTERM)
    assert proc.returncode == 0, "".join(lines)
    assert [p.name for p in temp.iterdir()] == [], "".join(lines)


HANGING_STOP = """
import sys, threading
import inspector.app._server as server
from inspector.cli import main

server.STOP_GRACE_S = 3.0
server.InspectorApp.stop = lambda self: threading.Event().wait()  # a close that never returns
sys.exit(main(["serve", sys.argv[1], "--port", sys.argv[2]]))
"""


def test_ctrl_c_ends_serve_even_when_the_app_hangs_stopping(sessions):  # noqa: F811
    """A stop that hangs (a thread holding a tab forever) does not keep ``inspector serve``
    running after Ctrl-C: it exits after its grace period, printing where every thread was."""
    proc = subprocess.Popen([sys.executable, "-c", HANGING_STOP, str(sessions[0]), str(free_port())],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=_ctrl_c_as_at_a_terminal, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()
    try:
        served_port(proc, lines)
    finally:
        stop_cli(proc, reader)
    out = "".join(lines)
    assert proc.returncode == 1, out
    assert "most recent call first" in out and "<lambda>" in out, out  # the stuck thread's stack


THREADS_COMING_AND_GOING = """
import sys, threading
from inspector.app._stop_watchdog import exit_if_stopping_hangs

def short_lived():
    def deep(n):
        return 0 if n == 0 else deep(n - 1) + 1
    deep(30)

def churn():  # threads start and end while the stacks are printed
    while True:
        threads = [threading.Thread(target=short_lived) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()

threading.Thread(target=churn, daemon=True).start()
exit_if_stopping_hangs(float(sys.argv[1]))
threading.Event().wait()  # the stop that never returns
"""


def test_a_hung_stop_prints_its_stacks_and_exits_while_other_threads_come_and_go():
    """The stacks of a hung stop are read while other threads stand still: read from under
    running threads (faulthandler's C watchdog), a thread ending mid-read crashed the process
    (SIGSEGV, about one exit in four here) instead of exiting 1 with every stack printed."""
    codes = []
    for attempt in range(12):
        done = subprocess.run([sys.executable, "-c", THREADS_COMING_AND_GOING, f"{0.1 + 0.02 * attempt:.2f}"],
                              capture_output=True, text=True, timeout=120)
        codes.append(done.returncode)
        assert done.returncode == 1 and "most recent call first" in done.stderr, (codes, done.stderr[-2000:])


def test_share_url_only_on_share(sessions, monkeypatch):  # noqa: F811
    import viser

    import inspector.app as app_module
    from inspector.cli import main

    asked: list[int] = []
    monkeypatch.setattr(viser.ViserServer, "request_share_url",
                        lambda self, verbose=True: asked.append(self.get_port()))  # no network
    for share in (False, True):
        served_app = serve([sessions[0]], port=0, share=share, block=False)
        try:
            assert served_app.host == "127.0.0.1"
            assert asked == ([served_app.port] if share else []), (share, asked)
        finally:
            served_app.stop()
        asked.clear()
    # The command line passes loopback and no share unless asked.
    calls = []
    monkeypatch.setattr(app_module, "serve", lambda *a, **kw: calls.append(kw))
    assert main(["serve", str(sessions[0])]) == 0
    assert main(["serve", str(sessions[0]), "--share", "--host", "0.0.0.0"]) == 0
    assert [(c["host"], c["share"]) for c in calls] == [("127.0.0.1", False), ("0.0.0.0", True)]


# ----------------------------------------------------------------------------------------------
# 5. Annotations: concurrent writers, and a writer killed mid-write

WRITER = r"""
import json, os, sys, time
from pathlib import Path
from inspector.said.annotations import update_annotation

root, tag, start, mode = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3]), sys.argv[4]
stop = int(sys.argv[5]) if len(sys.argv) > 5 else None
if mode == "half":  # stop with half the new document in the temporary file
    class HalfWritten:  # the temporary file's handle: writes half of what it is given, then hangs
        def __init__(self, fh):
            self.fh = fh
        def __enter__(self):
            return self
        def __exit__(self, *exc):
            return self.fh.__exit__(*exc)
        def write(self, data):
            self.fh.write(data[: len(data) // 2])
            self.fh.flush()
            print("in-write", flush=True)
            time.sleep(600)
    real_fdopen = os.fdopen
    os.fdopen = lambda fd, *a, **kw: HalfWritten(real_fdopen(fd, *a, **kw))
elif mode == "before-replace":  # stop with the complete new document not yet in place
    def fsync(fd):
        print("in-write", flush=True)
        time.sleep(600)
    os.fsync = fsync
print("ready", flush=True)
i = start
while stop is None or i < stop:
    update_annotation(root, tag, chunk=i, flag=True, note=f"n{i}:" + "x" * 3000)
    print(i, flush=True)
    i += 1
"""


def start_writer(root: Path, tag: str, start: int, mode: str, stop: int | None = None):
    args = [sys.executable, "-c", WRITER, str(root), tag, str(start), mode] + ([str(stop)] if stop else [])
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(line.strip() for line in proc.stdout), daemon=True)
    reader.start()
    return proc, lines, reader


def temps(root: Path) -> list[Path]:
    return sorted(root.glob(".annotations.json.*.tmp"))


def test_writer_killed_mid_write_leaves_the_previous_file(tmp_path):
    rng = random.Random(1234)
    update_annotation(tmp_path, "r", chunk=0, flag=True, note="n0:first")
    acked: set[int] = {0}  # every chunk a writer reported written
    start = 1
    modes = ["half", "before-replace"] + ["random"] * 6
    stale_seen = 0
    for mode in modes:
        before = (tmp_path / "annotations.json").read_bytes() if (tmp_path / "annotations.json").exists() else None
        proc, lines, reader = start_writer(tmp_path, "r", start, mode)
        try:
            if mode == "random":
                wait_until(lambda: any(x.isdigit() for x in lines), timeout=120, what="the writer's first write")
                time.sleep(rng.uniform(0.0, 0.25))
            else:
                wait_until(lambda: "in-write" in lines, timeout=120, what="the writer to stop mid-write")
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
            reader.join(timeout=5)
        written = {int(x) for x in lines if x.isdigit()}
        acked |= written
        text = (tmp_path / "annotations.json").read_bytes() if (tmp_path / "annotations.json").exists() else None
        if mode != "random":
            assert text == before, "a write killed before its replace changed the file"
            left = temps(tmp_path)
            assert left, "the killed writer left no temporary file (did it stop mid-write?)"
            if mode == "half":
                with pytest.raises(json.JSONDecodeError):
                    json.loads(left[0].read_text())
        data = json.loads(text)  # always a complete document
        chunks = data["rollouts"]["r"]["chunks"]
        assert set(json.loads(before)["rollouts"]["r"]["chunks"]) <= set(chunks)  # the previous content
        assert {str(i) for i in acked} <= set(chunks), "a reported write is missing"
        assert all(chunks[str(i)]["note"].startswith(f"n{i}:") for i in acked)
        assert all(0 <= int(c) <= max(acked | {start}) + 1 for c in chunks)  # nothing but our writes
        assert read_annotations(tmp_path) == data  # the reader takes the file, never a leftover temp
        stale_seen += bool(temps(tmp_path))
        start = max(int(c) for c in chunks) + 1
    assert stale_seen >= 2
    # The next writer clears what the killed ones left behind.
    update_annotation(tmp_path, "r", flag=True, note="after the crashes")
    assert not temps(tmp_path)
    assert read_annotations(tmp_path)["rollouts"]["r"]["note"] == "after the crashes"


def test_two_writer_processes_both_survive(tmp_path):
    writers = [start_writer(tmp_path, "r", k * 100, "run", k * 100 + 30) for k in range(2)]
    for proc, _, reader in writers:
        assert proc.wait(timeout=300) == 0
        reader.join(timeout=5)
    chunks = read_annotations(tmp_path)["rollouts"]["r"]["chunks"]
    assert set(chunks) == {str(k * 100 + i) for k in range(2) for i in range(30)}
    assert not temps(tmp_path)
