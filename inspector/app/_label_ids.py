"""Tie every control's label to its field in the page, for assistive tech.

viser 1.1.1 renders a control's label as ``<label for=UUID>`` and gives checkboxes and sliders that
id, but not text inputs (Mantine generates its own id there). So "Rollout note" labels nothing: a
screen reader reads an unnamed field, and ``get_by_label`` finds none. Each page runs the script
below once; it gives such a field the id its label points to, and again whenever the panel is
re-rendered (a folder opened, a control shown again). React leaves an id it did not change alone,
so typing into the field keeps it.

The script rides in the panel's title HTML (see ``._page_script``).
"""

from __future__ import annotations

from ._page_script import page_script_html

# A field is looked for only within a few levels above its label (label < p < div < the control's
# row), and only one without a label of its own, so a label never claims another control's field.
LABEL_IDS_JS = r"""
const FIELDS = 'input:not([type]), input[type=text], textarea';
const labelled = (el) => el.id && document.querySelector(`label[for="${CSS.escape(el.id)}"]`);
const link = () => {
  for (const label of document.querySelectorAll('label[for]')) {
    const id = label.htmlFor;
    if (!id || document.getElementById(id)) continue;
    let row = label.parentElement;
    for (let up = 0; row && up < 4 && !row.querySelector(FIELDS); up++) row = row.parentElement;
    const field = row && [...row.querySelectorAll(FIELDS)].find((el) => !labelled(el));
    if (field) field.id = id;
  }
};
let queued = false;
new MutationObserver(() => {
  if (queued) return;
  queued = true;
  setTimeout(() => { queued = false; link(); }, 0);
}).observe(document.body, { childList: true, subtree: true });
link();
"""

LABEL_IDS_HTML = page_script_html("label_ids", LABEL_IDS_JS)
