"""What ``inspector export`` says about the files it writes, without rerun: the driver of an
export in worker processes (or on Ray) names and sizes recordings but never writes one, so it
does not import the writer (rerun's SDK: ~0.45 s of CPU at every start)."""

from __future__ import annotations

RRD_SUFFIX = ".rrd"


def format_size(n_bytes: int) -> str:
    """``2_900_000`` -> ``"2.9 MB"`` (decimal units)."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.1f} {unit}"
    return f"{n_bytes} B"
