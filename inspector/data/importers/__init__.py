"""Other labs' evaluation outputs, read as sessions (in memory, or written by ``inspector import``):
the registry of the formats, one :class:`Format` each.

A format is one importer module, named here and nowhere else, that offers the same five
functions (:class:`Importer`): whether a path is in its layout, ``inspector info``'s description
and its text, ``inspector import NAME``, and the temporary session ``report``, ``serve`` and
``export`` read a raw directory as. :data:`FORMATS` lists them in the order a path is tried; the
"no layout recognised" line is made from it. Each module loads on first use, so a command that
touches no format pays for none.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, cast

from ..._lazy import attach
from ...errors import InspectorError

if TYPE_CHECKING:
    from .in_memory import InMemory


class Importer(Protocol):
    """What a format's module offers (its functions, called through :class:`Format`)."""

    def recognises(self, path: Path) -> bool:
        """``path`` (an existing file or directory) is in this layout."""

    def describe(self, src: Path, calibration: str | None = None) -> dict[str, Any]:
        """``inspector info --json``'s record; its ``format`` is the format's name."""

    def format_description(self, info: dict[str, Any]) -> str:
        """:meth:`describe`'s record as ``inspector info``'s lines."""

    def import_command(self, src: str, dest: str, *, overwrite: bool = False, **options: Any) -> Path:
        """``inspector import NAME SRC -o DEST``, with the format's own flags as ``options``."""

    def load_in_memory(self, src: Path, dataset: str | Path | None = None) -> InMemory:
        """``src`` imported into a temporary session (bad rollouts left out, among its errors)."""


@dataclass(frozen=True)
class Format:
    """One input format.

    Args:
        name: ``inspector import NAME``, and ``inspector info``'s ``format``.
        module: the importer module (an :class:`Importer`), relative to this package.
        title: what the "no layout recognised" line calls it.
        hint: what marks the layout on disk, in that line.
        one: a directory of it, for "it holds one ...".
        summary: ``inspector import NAME``'s help.
        src_help: the help of its SRC.
    """

    name: str
    module: str
    title: str
    hint: str
    one: str
    summary: str
    src_help: str

    @property
    def importer(self) -> Importer:
        return cast(Importer, importlib.import_module(self.module, __name__))


# The formats, in the order a path is tried (GR00T-Dreams first: its dump holds meta/info.json
# as a LeRobot dataset does, and is opened as a dataset, not imported in memory).
FORMATS: tuple[Format, ...] = (
    Format("groot-dreams", ".groot_dreams", "GR00T-Dreams neural trajectories", "IDM_dump: meta/modality.json",
           "GR00T-Dreams dump",
           "a GR00T-Dreams (DreamGen) IDM_dump output: neural trajectories",
           "the dump's directory (meta/, data/, videos/)"),
    Format("dreamzero-offline", ".dreamzero_offline", "DreamZero-SO101 offline-inference runs",
           "predicted_actions.csv", "DreamZero-SO101 offline-inference run directory",
           "DreamZero-SO101 offline_inference.py runs (predicted_actions.csv)",
           "a run directory or a parent of several (searched recursively)"),
    Format("lerobot-eval", ".lerobot_eval", "lerobot-eval outputs", "eval_info.json", "lerobot-eval output directory",
           "a lerobot-eval output directory (eval_info.json, videos/, recordings/)",
           "the evaluation's output directory"),
    Format("dreamzero-served", ".dreamzero_served", "DreamZero served predictions",
           "NNNNNN_<prompt>_<time>.mp4", "DreamZero served-predictions directory",
           "DreamZero's served predictions (video_pred_output/NNNNNN_<prompt>_<time>.mp4)",
           "the server's video_pred_output directory, or one of its videos"),
    Format("dreamzero-so101", ".dreamzero_so101_info", "DreamZero-SO101 evaluation",
           "meta.json + action_trace.npy or actions_pred", "DreamZero-SO101 evaluation directory",
           "DreamZero-SO101 evaluation directories",
           "a rollout directory or a parent of several (searched recursively)"),
)
# What a PATH may be besides the formats, for the line a path none of them fits gets.
NATIVE_LAYOUTS = ("a session (session.json)", "a LeRobot dataset (meta/info.json)")
# The most entries of a directory looked into for the one layout it holds (a bound on the time a
# wrong path costs).
MAX_ENTRIES_LOOKED_INTO = 256


def format_named(name: str) -> Format | None:
    return next((f for f in FORMATS if f.name == name), None)


def recognised(path: Path) -> Format | None:
    """The first format whose layout ``path`` (an existing file or directory) is in, or None."""
    return next((f for f in FORMATS if f.importer.recognises(path)), None)


def no_layout_fits(path: Path) -> InspectorError:
    """The one line for a path no layout fits: it names every layout (the whole list, within an
    error's length: a test holds it there), or the one layout a directory holds right under it."""
    inside = _the_one_inside(path)
    if inside is not None:
        fmt, child = inside
        return InspectorError(path, f"no layout recognised; it holds one {fmt.one}: {child.name}/ — pass that")
    known = [*NATIVE_LAYOUTS, *(f"{f.title} ({f.hint})" for f in FORMATS)]
    what = f"no layout recognised; known: {', '.join(known)}"
    return InspectorError(path, what)


def _the_one_inside(path: Path) -> tuple[Format, Path] | None:
    """(format, directory) when exactly one directory right under ``path`` is in a layout."""
    try:
        with os.scandir(path) as entries:
            children = sorted(Path(e.path) for _, e in zip(range(MAX_ENTRIES_LOOKED_INTO), entries)
                              if e.is_dir(follow_symlinks=False))
    except OSError:
        return None
    found = []
    for child in children:
        try:
            fmt = recognised(child)
        except OSError:  # unreadable: not the one to name
            continue
        if fmt is not None:
            found.append((fmt, child))
    return found[0] if len(found) == 1 else None


# The package's face: what other packages read of the formats (each loads on first use).
__getattr__, __dir__, __all__ = attach(__name__, {
    "NeuralTrajectories": ".groot_dreams",
    "open_trajectories": ".groot_dreams",
    "GROOT_DREAMS": ".groot_dreams",
})
__all__ += ["FORMATS", "Format", "Importer", "NATIVE_LAYOUTS", "format_named", "no_layout_fits", "recognised"]

if TYPE_CHECKING:
    from .groot_dreams import GROOT_DREAMS as GROOT_DREAMS
    from .groot_dreams import NeuralTrajectories as NeuralTrajectories
    from .groot_dreams import open_trajectories as open_trajectories
