"""Marks on a slider that is already on the page (the chunk slider's flagged seams, completion and
video breaks change with the rollout and as its video metrics arrive).

viser takes a slider's marks only as an argument of ``add_slider``; there is no public way to
change them after. Its private ``_build_slider_marks`` is what ``add_slider`` makes of that
argument, and the handle's private ``_marks`` prop holds it: assigning the prop sends the update
to the page like any public one. ``tests/test_slider_marks.py`` checks both on the installed
viser, so a viser that changes them fails there, not silently on the page.
"""

from __future__ import annotations

from typing import Any

from viser._gui_api import _build_slider_marks


def set_slider_marks(slider: Any, marks: tuple[tuple[int, str], ...]) -> None:
    """Show ``marks`` (``(value, label)`` pairs; none: no marks) on ``slider`` (a viser slider
    handle), as ``add_slider(..., marks=marks)`` would have; unchanged marks send nothing."""
    wanted = _build_slider_marks(marks) or None
    if slider._marks != wanted:
        slider._marks = wanted
