"""Scripts the app runs in each page, delivered with the GUI.

A script rides in the panel title's HTML as an image's ``onerror`` (an empty data URL fails at
once), so it arrives with the GUI: viser applies a batch of GUI messages at once, but holds a batch
that carries anything else (a ``RunJavascript`` message) until the 3D canvas draws a frame, seconds
in software WebGL. The title is never re-rendered, and each script also guards itself by name, so
it runs once per page.
"""

from __future__ import annotations

import json
from html import escape


def page_script_html(name: str, js: str) -> str:
    """An invisible element that runs ``js`` (a function body) once per page; ``name`` tells the
    page's scripts apart."""
    flag = json.dumps(f"__inspector_{name}")
    body = f"if (window[{flag}]) return;\nwindow[{flag}] = true;\n{js}"
    return f'<img src="data:," alt="" hidden onerror="{escape(body, quote=True)}">'
