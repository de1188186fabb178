"""Temporary siblings of files and directories being written, with the mode a plain ``open()`` or
``mkdir()`` would give them; and reading a file a user names, bounded and only if it is a regular file.

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
import stat
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


# What a file a user names is, when it is not a regular file: said in the one error line.
_KINDS = ((stat.S_ISDIR, "is a directory, not a file"), (stat.S_ISFIFO, "is a FIFO (named pipe), not a regular file"),
          (stat.S_ISCHR, "is a character device, not a regular file"),
          (stat.S_ISBLK, "is a block device, not a regular file"), (stat.S_ISSOCK, "is a socket, not a regular file"))


def not_regular(mode: int) -> str | None:
    """Why a file of ``mode`` (``st_mode``) is not read as a regular file, or None when it is."""
    if stat.S_ISREG(mode):
        return None
    return next((what for test, what in _KINDS if test(mode)), "is not a regular file")


def read_regular_file(path: str | Path, max_bytes: int, what: str = "file") -> bytes:
    """The bytes of a regular file of at most ``max_bytes``, every check made before a byte is read.

    A file a user names may be anything: a link to ``/dev/zero`` (read until memory runs out), a
    FIFO with no writer (a read that never returns). ``os.stat`` (following links) must find a
    regular file no larger than ``max_bytes``; the file is opened without blocking (a FIFO put in
    its place since is refused by ``fstat``, not waited on) and read to at most ``max_bytes``.

    Raises:
        InspectorError: missing, not a regular file, larger than ``max_bytes`` (``what`` names what
            the file was meant to be), or unreadable.
    """
    path = Path(path)
    try:
        _check_regular(path, os.stat(path), max_bytes, what)  # before opening: opening a device can act
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except (FileNotFoundError, NotADirectoryError):
        raise InspectorError(path, "file not found") from None
    except OSError as exc:
        raise InspectorError(path, f"cannot read ({exc.strerror or exc})") from None
    try:
        _check_regular(path, os.fstat(fd), max_bytes, what)  # what was opened, if it was replaced since
        chunks: list[bytes] = []
        left = max_bytes + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
    except OSError as exc:
        raise InspectorError(path, f"cannot read ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    if left <= 0:  # grew while it was read
        raise InspectorError(path, f"larger than any {what} (at most {max_bytes:,} bytes are read)")
    return b"".join(chunks)


def _check_regular(path: Path, st: os.stat_result, max_bytes: int, what: str) -> None:
    problem = not_regular(st.st_mode)
    if problem:
        raise InspectorError(path, problem)
    if st.st_size > max_bytes:
        raise InspectorError(path, f"{st.st_size:,} bytes: larger than any {what} (at most {max_bytes:,} bytes are read)")


def short_name(name: str) -> str:
    """A name short enough to prefix a temporary name (NAME_MAX is 255 bytes)."""
    return name.encode("utf-8", "surrogateescape")[:64].decode("utf-8", "ignore")
