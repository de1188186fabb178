"""``inspector rank``: sessions (checkpoints) ranked from blind pairwise votes, or by success rate.

With votes (``votes.json`` in the sessions, written by the app's A/B mode) the ranking is the
Bradley-Terry fit of :mod:`inspector.stats.ranking`; without any it is the success rate with its
Wilson interval, and the result says so (``method``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..data.session import Session
from ..errors import InspectorError
from ..said.votes import Vote, merged_votes, votes_path
from ..stats.ranking import DEFAULT_BOOTSTRAP, LOSS, TIE, WIN, rank_sessions
from .outcome_values import judged, model_label, open_sessions, session_labels, session_outcomes

CONFIDENCE = 0.95
_SCORE = {"a": WIN, "b": LOSS, "tie": TIE}


def build_ranking(paths: Sequence[str | Path], *, n_bootstrap: int = DEFAULT_BOOTSTRAP, seed: int = 0) -> dict[str, Any]:
    """The ranking of the sessions at ``paths``, best first (see ``docs/metrics.md``, "Ranking").

    Raises:
        InspectorError: a path is not a session; a vote file is malformed or names a rollout the
            session does not have; fewer than two sessions.
    """
    sessions = open_sessions(paths)
    if len(sessions) < 2:
        raise InspectorError(paths[0] if paths else "PATH", "ranking needs at least two sessions")
    labels = session_labels(sessions)
    index = {s.root.resolve(): i for i, s in enumerate(sessions)}
    votes = merged_votes([s.root for s in sessions])
    used: list[tuple[int, int, float]] = []
    progress: dict[int, list[float]] = {i: [] for i in range(len(sessions))}  # scores given in votes [%]
    resolved: dict[str, int | None] = {}  # votes name a few sessions many times: resolve each once

    def session_index(path: str) -> int | None:
        if path not in resolved:
            resolved[path] = index.get(Path(path).resolve())
        return resolved[path]

    for vote in votes:
        ia, ib = session_index(vote.a.session), session_index(vote.b.session)
        if ia is None or ib is None or ia == ib:
            continue  # a comparison with a session not ranked here
        _check_rollouts(vote, sessions[ia], sessions[ib])
        used.append((ia, ib, _SCORE[vote.answer]))
        for i, side in ((ia, vote.a), (ib, vote.b)):
            if side.progress is not None:
                progress[i].append(side.progress)
    base = {"sessions": [{"session": label, "path": str(s.root), "model": model_label(s)}
                         for label, s in zip(labels, sessions)],
            "votes": len(used), "votes_elsewhere": len(votes) - len(used), "confidence": CONFIDENCE}
    if not used:
        return {**base, **_by_success(sessions, labels)}
    first, second, score = (list(col) for col in zip(*used))
    fit = rank_sessions(len(sessions), first, second, score, n_bootstrap=n_bootstrap, confidence=CONFIDENCE,
                        seed=seed)
    wins = fit.wins
    tied = np.zeros(len(sessions))  # half a tie per session per tie it took part in
    for a, b, s in used:
        if s == TIE:
            tied[[a, b]] += 0.5
    ranking = []
    for i in fit.order():
        ties = float(tied[i])
        ranking.append({"session": labels[i], "model": model_label(sessions[i]), "strength": float(fit.strength[i]),
                        "low": float(fit.low[i]), "high": float(fit.high[i]), "votes": int(fit.votes[i].sum()),
                        "wins": float(wins[i].sum() - ties), "losses": float(wins[:, i].sum() - ties),
                        "ties": int(2 * ties),
                        "progress_mean": float(np.mean(progress[i])) if progress[i] else None,
                        "progress_scores": len(progress[i])})
    return {**base, "method": "bradley_terry",
            "note": "Bradley-Terry strengths (log odds, mean 0) from blind pairwise votes; ties count half a "
                    f"win to each side; {CONFIDENCE:.0%} bootstrap intervals over votes ({fit.n_bootstrap} replicates"
                    f"{'' if fit.n_bootstrap == n_bootstrap else f' of the {n_bootstrap} asked: see docs/ranking.md'})",
            "bootstrap": fit.n_bootstrap, "ranking": ranking,
            "win_matrix": {"sessions": labels, "wins": wins.tolist(), "votes": fit.votes.tolist()}}


def _check_rollouts(vote: Vote, a: Session, b: Session) -> None:
    for side, session in ((vote.a, a), (vote.b, b)):
        if side.rollout not in session.rollouts and side.rollout not in session.errors:
            raise InspectorError(votes_path(session.root), f"the vote of {vote.time}: rollout {side.rollout!r} is not in "
                                                           f"session {session.name!r} ({session.root})")


def _by_success(sessions: Sequence[Session], labels: Sequence[str]) -> dict[str, Any]:
    from ..stats import wilson_interval  # scipy.stats: seconds of imports that a ranking from votes does without

    rows: list[dict[str, Any]] = []
    for label, session in zip(labels, sessions):
        outcomes = session_outcomes(session)
        verdicts = [judged(outcomes, tag, r).success for tag, r in session.rollouts.items()]
        known = [s for s in verdicts if s is not None]
        successes = sum(known)
        if known:
            low, high = wilson_interval(successes, len(known), CONFIDENCE)
            rate = successes / len(known)
        else:
            low = high = rate = None  # type: ignore[assignment]
        rows.append({"session": label, "model": model_label(session), "success_rate": rate, "low": low,
                     "high": high, "successes": successes, "episodes": len(known)})
    rows.sort(key=lambda r: (r["success_rate"] is None, -(r["success_rate"] or 0.0), -r["episodes"]))
    return {"method": "success_rate",
            "note": f"no votes between these sessions: ranked by success rate, {CONFIDENCE:.0%} Wilson intervals",
            "ranking": rows}


def format_ranking(result: dict[str, Any]) -> str:
    lines = [result["note"]]
    if result["method"] == "bradley_terry":
        lines.append(f"{'#':>2}  {'session':<24} {'model':<24} {'strength':>8}  {'95% interval':<17} {'votes':>5}  "
                     "W-L-T")
        for i, r in enumerate(result["ranking"], 1):
            lines.append(f"{i:>2}  {r['session'][:24]:<24} {r['model'][:24]:<24} {r['strength']:>+8.2f}  "
                         f"[{r['low']:+.2f}, {r['high']:+.2f}]{'':<2} {r['votes']:>5}  "
                         f"{r['wins']:g}-{r['losses']:g}-{r['ties']}")
        matrix = result["win_matrix"]
        lines.append("")
        lines.append("wins of row over column (votes):")
        width = max(8, *(len(s[:16]) for s in matrix["sessions"]))
        lines.append(" " * (width + 1) + " ".join(f"{s[:16]:>{width}}" for s in matrix["sessions"]))
        for name, wins, votes in zip(matrix["sessions"], matrix["wins"], matrix["votes"]):
            cells = [("—" if v == 0 else f"{w:g} ({v})") for w, v in zip(wins, votes)]
            lines.append(f"{name[:16]:<{width}} " + " ".join(f"{c:>{width}}" for c in cells))
    else:
        lines.append(f"{'#':>2}  {'session':<24} {'model':<24} {'success':>8}  {'95% interval':<15} episodes")
        for i, r in enumerate(result["ranking"], 1):
            rate = "—" if r["success_rate"] is None else f"{r['success_rate']:.0%}"
            interval = "—" if r["low"] is None else f"[{r['low']:.0%}, {r['high']:.0%}]"
            lines.append(f"{i:>2}  {r['session'][:24]:<24} {r['model'][:24]:<24} {rate:>8}  {interval:<15} "
                         f"{r['successes']}/{r['episodes']}")
    if result.get("votes_elsewhere"):
        lines.append(f"({result['votes_elsewhere']} votes compare with sessions not given here; not used)")
    return "\n".join(lines)

