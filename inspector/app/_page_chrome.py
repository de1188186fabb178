"""The page around the app: its title, and viser's "Software WebGL rendering detected" notice.

viser titles every page "Viser", so a browser's tabs and history could not tell a rollout from the
Overview or from an A/B session: the page's script titles it by the app and what is open
("inspector · demo / seam_jump", "inspector · Overview", "inspector · A/B"), read from the page
itself (the picker's rollout, the Overview's panel being shown), so no message of the server's
has to carry it.

viser shows its notice of software WebGL at the top left of the scene on every load, where it
covered the Overview's table header until closed by hand. The page shows it once per browser (a
flag in its ``localStorage``), at the bottom of the window, and closes it after
:data:`NOTICE_SHOWN_S`; later loads close it at once.

The scripts ride in the panel title's HTML (see ``._page_script``).
"""

from __future__ import annotations

import json

from ._page_script import page_script_html

APP_NAME = "inspector"
AB_TITLE = f"{APP_NAME} · A/B"
OVERVIEW = "Overview"
NOTICE_ID = "webgl-software-rendering"  # viser's id of the notice (BrowserWarning.tsx)
NOTICE_SEEN_KEY = "inspector.webglNoticeSeen"  # localStorage
NOTICE_SHOWN_S = 12.0

_TITLE_JS = r"""
const NAME = __NAME__, OVERVIEW = __OVERVIEW__, PICKER = __PICKER__, FIXED = __FIXED__;
const what = () => {
  const overview = document.querySelector('.inspector-overview');
  if (overview && overview.getClientRects().length) return OVERVIEW;
  const label = [...document.querySelectorAll('label[for]')].find((l) => l.textContent.trim() === PICKER);
  let input = label && document.getElementById(label.htmlFor);
  if (input && !(input instanceof HTMLInputElement)) input = input.querySelector('input');
  // while the user types into the picker to search it, the title keeps the rollout open
  if (!input || input === document.activeElement) return null;
  return input.value || null;
};
setInterval(() => {
  const open = FIXED === null ? what() : null;
  const title = FIXED !== null ? FIXED : open === null ? null : NAME + ' \u00b7 ' + open;
  if (title !== null && document.title !== title) document.title = title;
}, 300);
"""

_NOTICE_JS = r"""
const ID = __ID__, KEY = __KEY__, SHOWN_MS = __SHOWN_MS__;
let seen = false;
try { seen = localStorage.getItem(KEY) === '1'; localStorage.setItem(KEY, '1'); } catch (e) {}
const style = document.createElement('style');
style.textContent = seen
  ? `#${ID} { display: none !important; }`
  // Mantine's notifications sit top left of the scene, over the Overview's table header
  : `.mantine-Notifications-root:has(#${ID}) { top: auto !important; bottom: 1em !important; }`;
document.head.appendChild(style);
const close = () => document.querySelector(`#${ID} button`)?.click();
const started = Date.now();
const poll = setInterval(() => {  // the notice may come a moment after this script
  const notice = document.getElementById(ID);
  if (notice && seen) { close(); clearInterval(poll); }
  else if (notice) { clearInterval(poll); setTimeout(close, SHOWN_MS); }
  else if (Date.now() - started > 30000) clearInterval(poll);
}, 200);
"""


def page_title_html(picker_label: str | None = None, fixed: str | None = None) -> str:
    """The script titling the page: ``fixed``, or the app and what is open (the rollout of the
    dropdown labelled ``picker_label``, or the Overview while it is shown)."""
    js = (_TITLE_JS.replace("__NAME__", json.dumps(APP_NAME)).replace("__OVERVIEW__", json.dumps(OVERVIEW))
          .replace("__PICKER__", json.dumps(picker_label)).replace("__FIXED__", json.dumps(fixed)))
    return page_script_html("title", js)


WEBGL_NOTICE_HTML = page_script_html("webgl_notice", _NOTICE_JS.replace("__ID__", json.dumps(NOTICE_ID))
                                     .replace("__KEY__", json.dumps(NOTICE_SEEN_KEY))
                                     .replace("__SHOWN_MS__", str(int(NOTICE_SHOWN_S * 1000))))
