"""Did the task succeed: one outcome record per rollout and source, kept beside the session's
annotations, and the one rule that picks the outcome tables use.

Sources, side by side on a rollout:

- ``label``: a person, in the app (saved at once, on every key press);
- ``file``: a JSON-lines or CSV file a judge, a run sheet or a script wrote
  (``inspector outcomes import FILE PATH``);
- ``sim``: a simulated evaluation's verdict (lerobot-eval's ``eval_info.json``, as imported);
- ``recording``: a LeRobot dataset's ``next.success`` / ``next.reward`` columns of the rollout's
  episode.

``label`` and ``file`` are stored in ``<session>/outcomes.json``; a raw directory that is imported
in memory (another tool's output, never written into) keeps them in a sidecar beside it,
``<dir>.inspector-outcomes.json``. ``sim`` and ``recording`` are read from the data each time.
The effective outcome is the first source in :data:`PRECEDENCE` that says anything (success,
progress or a failure tag); ``--outcome-source`` names one source instead.

The stored records are kept by :mod:`inspector.said` (``outcome_record``, ``outcome_store``),
beside annotations and votes: read-modify-write under an exclusive ``fcntl.flock`` on a lock file
beside the outcomes file, replaced atomically; concurrent writers (two tabs, two app processes)
never lose each other's records, and a file that exists but does not parse is reported and never
overwritten.

Layout::

    {"schema": "inspector.outcomes/1",
     "failure_tags": ["knocked_over"],              # the session's own tags, beside FAILURE_TAGS
     "rollouts": {"<tag>": {"label": {<OutcomeRecord>}, "file": {<OutcomeRecord>}}}}
"""

from __future__ import annotations

from ..said.outcome_record import FAILURE_TAGS as FAILURE_TAGS
from ..said.outcome_record import FIELDS as FIELDS
from ..said.outcome_record import PRECEDENCE as PRECEDENCE
from ..said.outcome_record import SOURCES as SOURCES
from ..said.outcome_record import STORED_SOURCES as STORED_SOURCES
from ..said.outcome_record import OutcomeRecord as OutcomeRecord
from ..said.outcome_record import OutcomesDocument as OutcomesDocument
from ..said.outcome_record import Source as Source
from ..said.outcome_record import check_fields as check_fields
from ..said.outcome_record import effective_outcome as effective_outcome
from ..said.outcome_record import make_record as make_record
from ..said.outcome_record import says_something as says_something
from ..said.outcome_store import OUTCOMES_FILE as OUTCOMES_FILE
from ..said.outcome_store import SIDECAR_SUFFIX as SIDECAR_SUFFIX
from ..said.outcome_store import known_failure_tags as known_failure_tags
from ..said.outcome_store import outcomes_path as outcomes_path
from ..said.outcome_store import read_outcomes as read_outcomes
from ..said.outcome_store import sidecar_path as sidecar_path
from ..said.outcome_store import store_records as store_records
from ..said.outcome_store import update_outcome as update_outcome
from ._command import Imported as Imported
from ._command import import_outcomes as import_outcomes
from ._import_file import FileRow as FileRow
from ._import_file import ImportResult as ImportResult
from ._import_file import match_rows as match_rows
from ._import_file import read_outcome_file as read_outcome_file
from ._sources import SessionOutcomes as SessionOutcomes
from ._sources import load_session_outcomes as load_session_outcomes
from ._sources import recording_outcomes as recording_outcomes
from ._sources import rollout_sources as rollout_sources
from ._sources import session_recording_outcomes as session_recording_outcomes
from ._sources import sim_record as sim_record

__all__ = [
    "FAILURE_TAGS", "FIELDS", "OUTCOMES_FILE", "PRECEDENCE", "SIDECAR_SUFFIX", "SOURCES", "STORED_SOURCES",
    "FileRow", "ImportResult", "Imported", "import_outcomes", "OutcomeRecord", "OutcomesDocument", "SessionOutcomes", "Source",
    "check_fields", "effective_outcome", "known_failure_tags", "load_session_outcomes", "make_record",
    "match_rows", "outcomes_path", "read_outcome_file", "read_outcomes", "recording_outcomes",
    "rollout_sources", "says_something", "session_recording_outcomes", "sidecar_path", "sim_record", "store_records", "update_outcome",
]
