"""Temporary siblings of files and directories being written, with the mode a plain ``open()`` or
``mkdir()`` would give them; reading a file a user names, bounded and only if it is a regular file;
JSON read as the standard defines it and written atomically; and the one locked read-check-change-
replace that every file people write through the app (annotations, outcomes, votes) goes through.

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
import json
import math
import os
import stat
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from .errors import InspectorError, require
from .schema import json_text

# The largest JSON document read whole (metadata: session.json, rollout.json, info.json, ...; none
# is more than a few MB). Parsed JSON takes up to ~25 times its size in objects (``[[],[],...]``),
# so this keeps any one document's objects well under a GB [bytes].
MAX_JSON_BYTES = 32 * 1024 * 1024

Document = TypeVar("Document")
Result = TypeVar("Result")


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


# ----------------------------------------------------------------------------------------------
# JSON files


def read_json(path: Path) -> Any:
    """Parse a JSON file as the standard defines JSON; every failure is an :class:`InspectorError`
    naming the file (and the field, for a NaN or Infinity, which JSON does not have).

    Raises:
        InspectorError: missing, not a regular file, unreadable, not UTF-8, not JSON, nested past
            the parser's depth, an integer past Python's digit limit, or a non-finite number.
    """
    return parse_json(path, read_json_bytes(path))


def read_json_bytes(path: Path) -> bytes:
    """The bytes of a JSON file :func:`read_json` would parse (the same checks before reading).

    Raises:
        InspectorError: missing, not a regular file (a FIFO is never waited on, a device never
            read), too large or unreadable.
    """
    return read_regular_file(path, MAX_JSON_BYTES, "metadata file")


def parse_json(path: Path, raw: bytes) -> Any:
    """:func:`read_json` of bytes already read from ``path`` (named in the errors).

    Raises:
        InspectorError: not UTF-8, not JSON, nested past the parser's depth, an integer past
            Python's digit limit, or a non-finite number.
    """
    return parse_json_text(path, raw)


def parse_json_text(path: Path, text: str | bytes, where: str = "") -> Any:
    """:func:`parse_json` of one JSON text inside ``path`` (``where`` it is, e.g. ``"line 12"`` of a
    JSON-lines file, starts every error).

    Raises:
        InspectorError: not UTF-8, not JSON, nested past the parser's depth, an integer past
            Python's digit limit, or a non-finite number (naming its field).
    """
    at = f"{where}: " if where else ""
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:  # bad UTF-8, bad JSON, an int of 5000 digits, [[[[...
        raise InspectorError(path, f"{at}invalid JSON ({type(exc).__name__}: {exc})") from None
    found = _first_non_finite(data)
    if found is not None:
        raise InspectorError(path, f"{at}{found[0]}: non-finite number {found[1]} (JSON has no NaN or Infinity)")
    return data


def check_json_size(path: Path) -> None:
    """Refuse a JSON document past :data:`MAX_JSON_BYTES` before it is read.

    Raises:
        InspectorError: naming the file and its size.
    """
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise InspectorError(path, f"cannot read ({exc.strerror or exc})") from None
    require(size <= MAX_JSON_BYTES, path, f"{size:,} bytes: larger than any metadata file "
                                          f"(at most {MAX_JSON_BYTES:,} bytes are read)")


def json_too_large(path: Path) -> bool:
    """True for a file past :data:`MAX_JSON_BYTES` (a layout's detection, which reads a JSON file
    to tell whose it is, leaves it to the reader, whose :func:`check_json_size` refuses it)."""
    try:
        return path.stat().st_size > MAX_JSON_BYTES
    except OSError:
        return False


def read_json_object(path: Path) -> dict[str, Any]:
    """:func:`read_json` of a file that must hold an object."""
    data = read_json(path)
    require(isinstance(data, dict), path, f"expected a JSON object, found {type(data).__name__}")
    return data


def _first_non_finite(data: Any) -> tuple[str, float] | None:
    """(field, value) of the first NaN/Infinity in document order, e.g. ``("per_joint_rmse[2]", nan)``.

    Iterative: a document as deep as the parser allows must not exhaust the stack here.
    """
    stack: list[tuple[str, Any]] = [("(top level)", data)]
    while stack:
        where, value = stack.pop()
        if isinstance(value, float) and not math.isfinite(value):
            return where, value
        top = "" if where == "(top level)" else where
        if isinstance(value, dict):
            stack.extend((f"{top}.{k}" if top else str(k), v) for k, v in reversed(list(value.items())))
        elif isinstance(value, list):
            stack.extend((f"{top}[{i}]", v) for i, v in reversed(list(enumerate(value))))
    return None


def json_bytes(data: Any) -> bytes:
    """The text :func:`write_json_atomic` writes: indented strict JSON (null, never NaN), one newline."""
    return (json_text(data, indent=2) + "\n").encode()


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON so that the file is either the old one or the complete new one."""
    write_bytes_atomic(path, json_bytes(data))


def write_bytes_atomic(path: Path, raw: bytes) -> None:
    """Write ``raw`` so that the file is either the old one or the complete new one (synced to
    disk before it replaces the old one)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = mkstemp_sibling(path)  # as open() would create it, not mkstemp's 0600
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


# ----------------------------------------------------------------------------------------------
# Files people write through the app: one locked read-check-change-replace


def refuse_link_out(path: Path, base: Path | None = None, outside: str = "its directory") -> None:
    """Refuse a ``path`` that is a symbolic link resolving outside ``base`` (default: its own
    directory): a link planted there would have a write land anywhere the user may write.

    Args:
        outside: how the error names ``base`` (``"its directory"``, ``"the served roots"``).

    Raises:
        InspectorError: naming ``path`` and where it leads.
    """
    if os.path.islink(path):  # False, not an error, for a name too long to exist (ENAMETOOLONG)
        target, within = path.resolve(), (path.parent if base is None else base).resolve()
        if not target.is_relative_to(within):
            raise InspectorError(path, f"resolves outside {outside} (to {target}); not reading or writing it")


def remove_stale_temps(path: Path) -> None:
    """Drop the ``.<name>.*.tmp`` siblings that writers killed mid-write left beside ``path`` (call
    holding the file's lock: no live writer then has one)."""
    for tmp in path.parent.glob(f".{path.name}.*.tmp"):
        with contextlib.suppress(OSError):
            tmp.unlink()


def locked_update(path: Path, read: Callable[[Path], Document], change: Callable[[Document], Result],
                  encode: Callable[[Document], bytes], *, lock: Path | None = None,
                  outside: str = "its directory") -> Result:
    """Read, check, change and atomically replace one file that several writers share.

    Two tabs or two app processes may change one file at once: each change is a read-modify-write
    under an exclusive ``flock`` on ``lock`` (default ``.<name>.lock`` beside ``path``), so neither
    loses the other's change. ``read`` reads and checks the file as it is on disk now (an empty
    document when there is none) and raises for one that does not parse or breaks its layout:
    nothing is then written, so a file a user edited by hand is never overwritten. ``change``
    edits the document in place; ``encode`` gives the new file's bytes, written to a temporary
    sibling and renamed over the old file (a reader sees the old or the new file, never half).
    A ``path`` that is a symbolic link leading outside its directory is neither read nor written
    (:func:`refuse_link_out`); the lock file is never followed through a link.

    Returns:
        What ``change`` returned.

    Raises:
        InspectorError: ``path`` leads outside its directory, the lock file is a link, or ``read``
            refused the file.
    """
    refuse_link_out(path, outside=outside)
    with exclusive_lock(path.parent / f".{path.name}.lock" if lock is None else lock):
        remove_stale_temps(path)
        refuse_link_out(path, outside=outside)  # again under the lock: it may have been planted since
        document = read(path)
        result = change(document)
        write_bytes_atomic(path, encode(document))
        return result
