"""What people said about rollouts, each kept in a file of its session and written through one
locked read-check-change-replace (:func:`inspector._files.locked_update`): two tabs or two app
processes never lose each other's change, a file that does not parse is never overwritten, and a
file that is a symbolic link leading outside its directory is neither read nor written.

Layout::

    sessions/<session>/
      annotations.json    flags and notes per rollout and chunk, from the app (``annotations``)
      outcomes.json       did the task succeed: a label per rollout from the app, or records
                          from an imported file (``outcome_record``, ``outcome_store``); a raw
                          directory imported in memory keeps them beside it instead, in
                          ``<dir>.inspector-outcomes.json``
      votes.json          blind pairwise votes between rollouts of two sessions (``votes``)
      .<name>.lock        what writers of each file take turns on

Where outcomes come from besides these files, and how a file of them is imported:
:mod:`inspector.outcomes`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "read_annotations": ".annotations",
    "rollout_annotations": ".annotations",
    "update_annotation": ".annotations",
    "OutcomeRecord": ".outcome_record",
    "OutcomesDocument": ".outcome_record",
    "read_outcomes": ".outcome_store",
    "update_outcome": ".outcome_store",
    "store_records": ".outcome_store",
    "Side": ".votes",
    "Vote": ".votes",
    "new_vote": ".votes",
    "save_vote": ".votes",
    "read_votes": ".votes",
    "merged_votes": ".votes",
    "readable_votes": ".votes",
})

if TYPE_CHECKING:
    from .annotations import read_annotations as read_annotations
    from .annotations import rollout_annotations as rollout_annotations
    from .annotations import update_annotation as update_annotation
    from .outcome_record import OutcomeRecord as OutcomeRecord
    from .outcome_record import OutcomesDocument as OutcomesDocument
    from .outcome_store import read_outcomes as read_outcomes
    from .outcome_store import store_records as store_records
    from .outcome_store import update_outcome as update_outcome
    from .votes import Side as Side
    from .votes import Vote as Vote
    from .votes import merged_votes as merged_votes
    from .votes import new_vote as new_vote
    from .votes import read_votes as read_votes
    from .votes import readable_votes as readable_votes
    from .votes import save_vote as save_vote
