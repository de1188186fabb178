"""The Overview of one tab: every served rollout in one table, with the aggregate figures.

Layout: the table, the compare summary and the figures fill a wide floating panel over the 3D
scene (a 350 px side panel does not fit a table); search, sort, filters, "compare with session"
and the row to open sit in an "Overview" folder at the top of the left panel, since viser's HTML
cannot call back into Python: a row opens through a real control (``Row to open`` + ``Open
rollout``). Opening a row, or picking a rollout in the picker, closes the overview and shows that
rollout in the tab's normal view; the ``Overview`` button brings it back. The rollout a tab opens
with, behind the overview, decodes no video while the rows are computed (that CPU is theirs): its videos start when
the overview steps aside or the last row is in.

The rows are the app's (:class:`~._overview_rows.OverviewRows`, shared by every tab); a tab keeps
only its controls' state and redraws when rows arrive (at most every :data:`REDRAW_EVERY_S`).
Flags and notes are read from each session's annotations.json at each redraw, so notes saved in
any tab show up.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace

from ..errors import InspectorError
from ..said.annotations import read_annotations
from ._cards import error_card
from ._host import OverviewHost
from ._overview_outcomes import row_outcomes, success_rate_html
from ._overview_table import (
    ALL_OUTCOMES,
    ALL_SESSIONS,
    KIND_FILTERS,
    MAX_TABLE_ROWS,
    NO_COMPARE,
    PICKER_ORDER,
    SCOPE,
    Note,
    Query,
    compare_with_session,
    comparison_html,
    figures_html,
    header_html,
    outcome_filters,
    overview_css,
    select_rows,
    sort_options,
    table_html,
)
from ._panels import LEFT_PANEL_PX

# Rows arriving redraw a tab's table at most this often, its figures less often (a thousand
# rollouts' figures are most of a megabyte of SVG for the browser to lay out) [s].
REDRAW_EVERY_S = 1.0
FIGURES_EVERY_S = 5.0
# The floating panel, over the scene (the right panel steps aside), beside the left panel; the user
# may move and resize it [px]. viser sizes a floating panel in pixels and keeps only its height
# inside the window, so the page's style caps its width at what the window leaves beside the left
# panel: it fills a 1920 px window and fits a 1280 px one, its table scrolling sideways in its box.
PANEL_X, PANEL_Y, PANEL_WIDTH, PANEL_HEIGHT = 8, 8, 1600, 1100
# viser draws the left panel 4 px wider than the width set (its padding) [px]
LEFT_DOCK_PX = LEFT_PANEL_PX + 4
FIT_WINDOW_CSS = (
    f"<style>[data-floating-window]:has(.{SCOPE}) {{"
    f"max-width: calc(100% - {LEFT_DOCK_PX + 2 * PANEL_X}px) !important;"
    f"max-height: calc(100% - {2 * PANEL_Y}px) !important; }}</style>")
NO_ROWS = "(no rows)"


class OverviewPanel:
    """The overview of one tab (see the module docstring).

    Args:
        tab: the tab; its ``controls.show_overview`` button opens the overview.

    Attributes:
        visible: the overview is shown.
        shown: the rows the table shows, in order (for tests).
    """

    def __init__(self, tab: OverviewHost) -> None:
        self.tab = tab
        self.store = tab.app.overview_rows
        self.visible = False
        self.shown: list = []
        self._lock = threading.RLock()
        self._option_to_key: dict[str, str] = {}
        self._picked_key: str | None = None  # the row the user chose in "Row to open"
        self._figures_for: tuple | None = None  # the rows the figures were drawn for
        self._last_draw = self._last_figures = 0.0
        self._redraw_timer: threading.Timer | None = None
        client, gui, c = tab.client, tab.client.gui, tab.controls
        sessions = self.store.session_names()
        many = len(sessions) > 1
        c.show_overview.visible = len(self.store) > 0
        with client.atomic():
            # between the Overview button and the picker
            with gui.add_folder("Overview", order=(c.show_overview.order + c.picker.order) / 2,
                                visible=False) as self.folder:
                self.search = gui.add_text("Search prompts", "", hint="words of the prompt or tag")
                self.sort = gui.add_dropdown("Sort by", sort_options([]), initial_value=PICKER_ORDER)
                self.descending = gui.add_checkbox("Descending", False)
                self.kind = gui.add_dropdown("Kind", tuple(KIND_FILTERS))
                self.session = gui.add_dropdown("Session", (ALL_SESSIONS, *sessions), visible=many)
                self.flagged = gui.add_checkbox("Flagged only", False)
                self.outcome = gui.add_dropdown("Outcome", (ALL_OUTCOMES,), hint="unlabelled, failed, by failure tag")
                self.violations = gui.add_checkbox("With limit violations", False)
                self.compare = gui.add_dropdown("Compare with session", (NO_COMPARE, *sessions), visible=many,
                                                hint="B: pairs the table's rows with this session's")
                self.row = gui.add_dropdown("Row to open", (NO_ROWS,))
                self.open_row = gui.add_button("Open rollout", icon="external-link")
                self.close = gui.add_button("Close overview", icon="x", color="gray")
            self.panel = gui.add_panel(visible=False)
            with self.panel.add_tab("Overview", icon="table"):
                self.style = gui.add_html(overview_css() + FIT_WINDOW_CSS)
                self.header = gui.add_html("")
                self.compare_info = gui.add_html("", visible=False)
                self.table = gui.add_html("")
                self.figures = gui.add_html("")
            self.panel.float(x=PANEL_X, y=PANEL_Y, width=PANEL_WIDTH, height=PANEL_HEIGHT)
        self._wire()
        self.store.add_listener(self._rows_arrived)
        if len(self.store) > 1:  # the whole evaluation first when there is more than one rollout
            self.show()

    # ------------------------------------------------------------------------------------------
    # Showing

    def show(self) -> None:
        """Show the overview (and start computing rows, once per app)."""
        with self._lock:
            self.visible = True
            self.store.start()
            with self.tab.client.atomic():
                self.tab.controls.show_overview.visible = False
                self.folder.visible = True
                self.tab.right_panel.visible = False
                self.panel.visible = True
                self.draw()

    def hide(self, start_frames: bool = True) -> None:
        """Hide the overview; ``start_frames``: the rollout it covered is shown, so its videos,
        held meanwhile, decode now (not where another rollout opens next)."""
        with self._lock:
            self.visible = False
            with self.tab.client.atomic():
                self.panel.visible = False
                self.tab.right_panel.visible = True
                self.folder.visible = False
                self.tab.controls.show_overview.visible = len(self.store) > 0
        if start_frames:
            self.tab.start_frames()

    def open_selected(self) -> bool:
        """Open the row chosen in ``Row to open`` in the tab's normal view."""
        key = self._option_to_key.get(self.row.value)
        if key is None:
            return False
        self.hide(start_frames=False)  # the row's rollout opens instead of the one behind
        return self.tab.open(key)

    # ------------------------------------------------------------------------------------------
    # Drawing

    def query(self) -> Query:
        return Query(sort=self.sort.value, descending=self.descending.value, search=self.search.value,
                     kind=self.kind.value, session=self.session.value, flagged_only=self.flagged.value,
                     violations_only=self.violations.value, compare_with=self.compare.value,
                     outcome=self.outcome.value)

    def draw(self, rows_arrived: bool = False) -> None:
        """Redraw the table, the compare summary and (when their rows changed) the figures.

        Args:
            rows_arrived: the redraw is for rows computed meanwhile (the figures may wait).
        """
        with self._lock:
            if not self.visible or self._client_gone():
                return
            self._last_draw = time.monotonic()
            rows = self.store.rows()
            notes, notes_error = _notes(rows)
            outcomes, outcomes_error = row_outcomes(rows, self.tab.app.catalog)
            notes = {k: replace(notes.get(k, Note()), outcome=outcomes.get(k), outcome_read=k in outcomes)
                     for k in {*notes, *outcomes}}
            notes_error = notes_error or outcomes_error
            q = self.query()
            comparison = compare_with_session(rows, q, notes)
            shown = select_rows(rows, q, notes, comparison)
            self.shown = shown
            with self.tab.client.atomic():
                outcome_options = outcome_filters(notes)
                if list(self.outcome.options) != outcome_options:  # failure tags appear as they are used
                    chosen = self.outcome.value
                    self.outcome.options = outcome_options
                    self.outcome.value = chosen if chosen in outcome_options else ALL_OUTCOMES
                options = sort_options(rows, comparison is not None)
                if list(self.sort.options) != options:
                    self.sort.options = options  # PSNR views appear with their rows
                self.header.content = header_html(rows, shown, self.store.n_cached) + success_rate_html(
                    shown, outcomes) + (
                    error_card("annotations or outcomes unreadable: not shown", notes_error)
                    if notes_error is not None else "")
                self.compare_info.visible = comparison is not None
                if comparison is not None:
                    self.compare_info.content = comparison_html(comparison)
                self.table.content = table_html(rows, shown, notes, comparison, self.tab.key)
                self._set_row_options(shown)
            # The figures after the table has gone out, not with it: a thousand rows' figures take
            # about half a second to draw, which the table need not wait for.
            drawn_for = tuple((r.key, r.summary is not None) for r in shown)
            figures_due = (not rows_arrived or self.store.done.is_set()
                           or time.monotonic() - self._last_figures >= FIGURES_EVERY_S)
            if drawn_for != self._figures_for and figures_due:  # sorting alone keeps the figures
                self._figures_for = drawn_for
                self._last_figures = time.monotonic()
                self.figures.content = figures_html(shown)

    def _client_gone(self) -> bool:
        """The tab closed, or its connection did (viser lists a client until its connection
        ends, then tells the app, which closes the tab: rows may arrive in between)."""
        return self.tab.closed.is_set() or self.tab.client_id not in self.tab.app.server.get_clients()

    def _set_row_options(self, shown) -> None:
        """``Row to open`` lists the table's rows, numbered as in the table."""
        chosen = self._picked_key
        self._option_to_key = {f"{i + 1} · {r.key}": r.key for i, r in enumerate(shown[:MAX_TABLE_ROWS])}
        options = tuple(self._option_to_key) or (NO_ROWS,)
        if tuple(self.row.options) != options:
            self.row.options = options
            # the rollout the user chose stays chosen when the order changes; else the first row
            self.row.value = next((o for o, k in self._option_to_key.items() if k == chosen), options[0])

    def _rows_arrived(self) -> None:
        """Rows arrived (on the computing thread): redraw now or a little later, not more often."""
        if self.tab.closed.is_set():
            self.store.remove_listener(self._rows_arrived)
            return
        if self.store.done.is_set():
            self.tab.start_frames()  # every row is in: the rollout behind may decode now
        with self._lock:
            if not self.visible:
                return
            done = self.store.done.is_set()
            # the last rows are drawn at once, not at the next tick (a second after the one before)
            wait = 0.0 if done else self._last_draw + REDRAW_EVERY_S - time.monotonic()
            if self._redraw_timer is not None:
                if not done:
                    return
                self._redraw_timer.cancel()  # one that has fired already draws once more: harmless
            elif wait <= 0 and not done:
                self.draw(rows_arrived=True)
                return
            self._redraw_timer = threading.Timer(max(wait, 0.0), self._timed_draw)
            self._redraw_timer.daemon = True
            self._redraw_timer.start()

    def _timed_draw(self) -> None:
        with self._lock:
            self._redraw_timer = None
            self.draw(rows_arrived=True)

    # ------------------------------------------------------------------------------------------
    # Wiring

    def _wire(self) -> None:
        def user(fn):
            """Run ``fn()`` for the user's own changes only (ours fire callbacks too, client None)."""
            def cb(event) -> None:
                if event.client is not None and not self.tab.closed.is_set():
                    fn()
            return cb

        for control in (self.search, self.sort, self.descending, self.kind, self.session, self.flagged,
                        self.violations, self.compare, self.outcome):
            control.on_update(user(self.draw))
        self.row.on_update(user(lambda: setattr(self, "_picked_key", self._option_to_key.get(self.row.value))))
        self.open_row.on_click(user(self.open_selected))
        self.close.on_click(user(self.hide))
        self.tab.controls.show_overview.on_click(user(self.show))
        # picking a rollout in the picker shows it: the overview steps aside
        self.tab.controls.picker.on_update(user(self.hide))


def _notes(rows) -> tuple[dict[str, Note], InspectorError | None]:
    """Flags and notes of the rows, one annotations.json read per session (and the first error)."""
    by_session: dict = {}
    for r in rows:
        by_session.setdefault(r.session_root, []).append(r)
    notes: dict[str, Note] = {}
    error = None
    for root, session_rows in by_session.items():
        try:
            entries = read_annotations(root)["rollouts"]
        except InspectorError as exc:
            error = error or exc
            continue
        for r in session_rows:
            e = entries.get(r.tag)
            if e:
                notes[r.key] = Note(bool(e.get("flag", False)), str(e.get("note", "")))
    return notes, error
