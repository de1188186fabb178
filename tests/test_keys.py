"""Every key of the app is listed where a user looks for it: the Keys table of docs/app.md, the
README's keys sentence, and the hints in the app's panels (Timeline, Label, A/B); and every key
the app binds is in the table."""

from __future__ import annotations

import re
from pathlib import Path

from inspector.app._ab_mode import AB_HINT
from inspector.app._keys import HOTKEYS, LABEL_HOTKEYS, TIMELINE_KEYS_HINT
from inspector.app._label_panel import KEYS_HELP

ROOT = Path(__file__).resolve().parents[1]
# The table's names for what the hotkeys call otherwise (Mantine's notation)
SPELLED = {"pageup": "PageUp", "pagedown": "PageDown"}


def _docs_keys() -> list[str]:
    """The keys of docs/app.md's Keys table, one name each ("1 - 9" gives 1 and 9)."""
    text = (ROOT / "docs" / "app.md").read_text(encoding="utf-8")
    table = text.split("## Keys", 1)[1].split("\n## ", 1)[0]
    keys = []
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 2 or cells[0] in ("key", "") or set(cells[0]) <= {"-"}:
            continue
        keys += [k.strip() for k in re.split(r" / |, | - ", cells[0]) if k.strip()]
    return keys


def _names(text: str, key: str) -> bool:
    """``text`` names ``key`` as a word of its own (a letter in a word is no key)."""
    return re.search(rf"(?<![\w-]){re.escape(key)}(?![\w-])", text) is not None


def _readme_keys_sentence() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    start = text.index("Keys: ")
    return text[start:text.index("\n\n", start)].replace("\n", " ")


def test_the_docs_table_lists_every_key_the_app_binds():
    keys = _docs_keys()
    assert {"J", "L", "K", "PageUp", "PageDown", "W", "X", "S", "F", "T", "N", "0", "A", "B", "="} <= set(keys)
    for hotkey in (*HOTKEYS.values(), *LABEL_HOTKEYS.values()):
        name = SPELLED.get(hotkey, hotkey)
        assert name in keys or (name.isdigit() and "1" in keys and "9" in keys), name


def test_the_readme_and_the_panels_name_every_key_of_the_docs():
    sentence = _readme_keys_sentence()
    hints = " ".join((TIMELINE_KEYS_HINT, re.sub(r"<[^>]+>", "", KEYS_HELP), AB_HINT))
    for key in _docs_keys():
        if key.startswith("arrow keys"):
            assert "arrow keys" in sentence and "arrows on a slider" in hints
            continue
        assert _names(sentence, key), f"the README's keys sentence lacks {key}"
        # the panels write a digit range as "1-9"
        assert _names(hints, key) or (key in "19" and "1-9" in hints), f"no panel's hint names {key}"
