"""``inspector report``, ``compare``, ``rank`` and ``agreement``: text, HTML and decisions over the
rows of :mod:`inspector.rows`: the report as tables or JSON (``build``), the HTML page (``html`` and
its figures), two evaluations side by side (``compare``), and the decisions between checkpoints
(``ranking``, ``agreement``).

Every module, one line each, is on the map in docs/development.md ("Layout of the code"),
which tests/test_layout.py checks against the package.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "build_report": ".build",
    "format_report": ".build",
    "build_comparison": ".compare",
    "compare_reports": ".compare",
    "format_comparison": ".compare",
    "pair_rows": ".compare",
    "render_report_html": ".html",
    "write_report_html": ".html",
    "report_figures": ".figures",
})

if TYPE_CHECKING:
    from .build import build_report as build_report
    from .build import format_report as format_report
    from .compare import build_comparison as build_comparison
    from .compare import compare_reports as compare_reports
    from .compare import format_comparison as format_comparison
    from .compare import pair_rows as pair_rows
    from .figures import report_figures as report_figures
    from .html import render_report_html as render_report_html
    from .html import write_report_html as write_report_html
