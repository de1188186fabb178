"""Temporary siblings of files and directories being written, with the mode a plain ``open()`` or
``mkdir()`` would give them.

Everything inspector writes goes through a temporary sibling renamed into place, so a reader sees
the old file or the complete new one. ``tempfile.mkstemp`` creates its file 0600 and ``mkdtemp``
its directory 0700, and the rename keeps that mode: a report page, a session, a recording meant to
be shared would be readable by their owner only. These give them the umask's mode instead, as every
other output has.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from .errors import InspectorError


def process_umask() -> int:
    """The process's umask, read without changing it (setting it, even briefly, races other threads)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)  # no /proc (not Linux): the classic read-back
    os.umask(mask)
    return mask


def mkstemp_sibling(dest: Path, prefix: str | None = None, suffix: str = ".tmp") -> tuple[int, str]:
    """``(fd, path)`` of a new temporary file beside ``dest`` (``.<name>.<random><suffix>``, or
    ``prefix`` in place of ``.<name>.``) with the mode ``open()`` would give it: 0666 less the umask."""
    fd, tmp = tempfile.mkstemp(prefix=f".{short_name(dest.name)}." if prefix is None else prefix, suffix=suffix,
                               dir=dest.parent)
    try:
        os.fchmod(fd, 0o666 & ~process_umask())
    except BaseException:
        os.close(fd)
        Path(tmp).unlink(missing_ok=True)
        raise
    return fd, tmp


def mkdtemp_sibling(dest: Path, suffix: str = ".partial") -> Path:
    """A fresh hidden sibling directory of ``dest`` to build it in (``.<name>.<random><suffix>``),
    with the mode ``mkdir()`` would give it: 0777 less the umask."""
    staged = Path(tempfile.mkdtemp(prefix=f".{short_name(dest.name)}.", suffix=suffix, dir=dest.parent))
    try:
        os.chmod(staged, 0o777 & ~process_umask())
    except BaseException:
        staged.rmdir()
        raise
    return staged


@contextlib.contextmanager
def exclusive_lock(lock: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on ``lock`` (created if missing): writers of one file (two tabs,
    two processes) take turns at read-modify-write, so neither loses the other's change.

    Raises:
        InspectorError: ``lock`` is a symbolic link (it would let the lock file land elsewhere).
    """
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InspectorError(lock, "is a symbolic link; refusing to follow it") from None
        raise
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def short_name(name: str) -> str:
    """A name short enough to prefix a temporary name (NAME_MAX is 255 bytes)."""
    return name.encode("utf-8", "surrogateescape")[:64].decode("utf-8", "ignore")
