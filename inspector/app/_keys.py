"""The app's keys, and keeping them from also moving the 3D view.

viser 1.1.1 moves its camera while W/A/S/D/Q/E or an arrow key is held anywhere but in a text
field: its listener sits on the document and knows neither a slider thumb with the focus nor the
app's own hotkeys. Stepping through the chunks with the arrow keys orbited the 3D view, and W
(worst chunk) flew the camera away from the arms; in a browser without a GPU every such key also
started a 3D redraw (~150 ms in software WebGL) before the step's frame could even be asked for.

The slider and the hotkeys handle the key first (React listens on its root element, inside
``<html>``; Mantine's hotkeys on ``<html>`` itself); the page's script then stops the event at
``<html>``, before the document. The script rides in the panel title's HTML (see ``._page_script``).

A pick in a dropdown (the rollout picker, Speed, Video, the Overview's) left the keyboard focus in
its input, where Mantine's hotkeys ignore keys: X typed "demo / seam_jumpx" into the picker. The
script takes the focus off a dropdown's input once an option is picked (by click or Enter), so the
keys reach the app after any pick; text fields being edited keep their keys.
"""

from __future__ import annotations

import json

from ._page_script import page_script_html

# Command label -> hotkey (Mantine's notation), bound by each tab.
HOTKEYS = {
    "Previous step": "J",
    "Next step": "L",
    "Play / pause": "K",
    "Previous chunk": "pageup",
    "Next chunk": "pagedown",
    "Worst chunk": "W",
    "Next flagged seam": "X",  # the chunk seams flagged as jumps (docs/metrics.md), in turn
}
# The Label panel's keys (see ._label_panel): command label -> hotkey.
LABEL_HOTKEYS = {
    "Label: success": "S",
    "Label: failure": "F",
    **{f"Label: progress {10 * k}%": str(k) for k in range(1, 10)},
    "Label: progress 100%": "0",
    "Label: next failure tag": "T",
    "Label: next unlabelled rollout": "N",
}
# Letters viser's keyboard camera moves by.
CAMERA_LETTERS = frozenset("WASDQE")

# What the Timeline folder says of its keys (every one of HOTKEYS).
TIMELINE_KEYS_HINT = ("keys: J / L step · K play · PageUp / PageDown chunk · W worst chunk · "
                      "X next flagged seam · arrows on a slider step it")

_KEYS_JS = r"""
const CLAIMED = new Set(__CLAIMED__);
document.documentElement.addEventListener('keydown', (e) => {
  const onSlider = e.key.startsWith('Arrow') && e.target instanceof Element && e.target.closest('[role="slider"]');
  const hotkey = CLAIMED.has(e.code) && !e.ctrlKey && !e.metaKey && !e.altKey;
  if (onSlider || hotkey) e.stopPropagation();
});
// a dropdown's input: Mantine's Select (its options listed in a listbox)
const isDropdown = (el) => el instanceof HTMLInputElement && el.getAttribute('aria-haspopup') === 'listbox';
const blurPicked = () => setTimeout(() => {
  const el = document.activeElement;
  if (isDropdown(el)) el.blur();
}, 0);
document.addEventListener('click', (e) => {
  if (e.target instanceof Element && e.target.closest('[role="option"]')) blurPicked();
}, true);
document.documentElement.addEventListener('keydown', (e) => {
  if (e.key === 'Enter' && isDropdown(e.target) && e.target.getAttribute('aria-expanded') === 'true') blurPicked();
}, true);
"""


def claimed_camera_codes() -> list[str]:
    """``KeyboardEvent.code`` of each hotkey that is also one of viser's camera keys."""
    keys = [*HOTKEYS.values(), *LABEL_HOTKEYS.values()]
    return sorted(f"Key{k}" for k in keys if k.upper() in CAMERA_LETTERS)


KEYS_HTML = page_script_html("keys", _KEYS_JS.replace("__CLAIMED__", json.dumps(claimed_camera_codes())))
