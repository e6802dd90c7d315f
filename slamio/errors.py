"""The one exception base class of the project, and the reading of a user's file whole.

Every error a user can cause (a bad log line, an unknown scenario, a bad option) is an
``FgslamError``; the CLI prints its message and exits non-zero instead of a traceback:
status 1 for a mistake in the command, status 2 for an input file that cannot be used
(:class:`InputFileError`).

:func:`read_text` and :func:`read_bytes` (with :func:`check_regular` and
:func:`open_regular`) live here, beside the errors they raise, so that this module imports
nothing of fgslam's; :mod:`slamio.safe_input` adds the parsers. :func:`content_lines` reads
the small line-based text formats (TUM trajectories and frame lists).
"""

from __future__ import annotations

import os
import stat
from typing import Iterator

#: The largest text file (noise model, calibration, trials, camera, landmark, tolerance or
#: waypoint file) read whole: 16 MiB, a thousand times what any of them holds.
MAX_TEXT_BYTES = 16 * 2**20


class FgslamError(Exception):
    """Base class of every error fgslam raises on purpose."""


class InputFileError(FgslamError):
    """An input file fgslam cannot use: missing or unreadable, not a regular file (a FIFO,
    a device, a symbolic-link loop), too large, or holding something it refuses (bad syntax,
    a value out of range, nesting or numbers no such file has). The message names the file,
    and the line and field where the format has them; ``fgslam`` exits with status 2."""

    exit_status = 2


def decode_utf8(path, raw: bytes, expected: str, error: type[FgslamError] = InputFileError) -> str:
    """``raw`` (the bytes of the file at ``path``) as UTF-8 text, or one ``error`` line naming
    the file, the line and column of the first bad byte and ``expected`` (what kind of file
    it should be and how to make one), as the run-log reader reports a damaged log."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        column = exc.start - raw.rfind(b"\n", 0, exc.start)
        raise error(
            f"{path}:{line}: not UTF-8 text: byte 0x{raw[exc.start]:02x} at column {column} ({exc.reason}); "
            f"{expected} — was the file damaged, or is this not the right file?"
        ) from None


def read_text(path, what: str, expected: str, error: type[FgslamError] = InputFileError) -> str:
    """The text of the user's file at ``path`` (a ``what``: "trials file", "camera file", ...):
    one ``error`` line when it cannot be read (and why: missing, a FIFO or device, a
    symbolic-link loop, larger than :data:`MAX_TEXT_BYTES`) or is not
    UTF-8 (:func:`decode_utf8` with ``expected``). Never blocks on a FIFO."""
    return decode_utf8(path, read_bytes(path, what, error=error), expected, error)


# --------------------------------------------------------------------------- opening files


_KINDS = (
    (stat.S_ISFIFO, "a named pipe (FIFO)"),
    (stat.S_ISCHR, "a character device (like /dev/zero)"),
    (stat.S_ISBLK, "a block device (a disk)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a folder"),
)


# --------------------------------------------------------------------------- opening files


def _not_regular(path: str, what: str, mode: int, error: type[FgslamError]) -> FgslamError | None:
    if stat.S_ISREG(mode):
        return None
    kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
    fix = ("give the file inside it" if stat.S_ISDIR(mode)
           else "fgslam reads only regular files: save the data to a file and give that")
    return error(f"{path}: the {what} is {kind}, not a regular file; {fix}")


def _os_error(path: str, what: str, exc: OSError, error: type[FgslamError]) -> FgslamError:
    import errno

    if exc.errno == errno.ELOOP:
        return error(f"{path}: cannot read the {what}: a loop of symbolic links (a link that leads, through "
                     "others, back to itself); point the link at the real file")
    hint = {errno.ENOENT: "check the path", errno.ENOTDIR: "a part of the path is a file, not a folder",
            errno.EACCES: "check its permissions"}.get(exc.errno or 0)
    return error(f"{path}: cannot read the {what}: cannot open it ({exc.strerror or exc})" + (f"; {hint}" if hint else ""))


def check_regular(path: str | os.PathLike[str], what: str, error: type[FgslamError] = InputFileError) -> int:
    """The size of the regular file at ``path``; one ``error`` line naming it when it is
    missing, a FIFO, a device, a socket, a folder or a loop of symbolic links. For files
    another library opens (numpy, rosbags); :func:`open_regular` when fgslam reads them."""
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the name
        raise (_os_error(path, what, exc, error) if isinstance(exc, OSError)
               else error(f"{path!r}: not a file name ({exc})")) from None
    bad = _not_regular(path, what, st.st_mode, error)
    if bad is not None:
        raise bad
    return st.st_size


def open_regular(path: str | os.PathLike[str], what: str, error: type[FgslamError] = InputFileError) -> int:
    """A file descriptor open for reading on the regular file at ``path`` (see
    :func:`check_regular`). Never blocks: a FIFO swapped in after the first look is opened
    without waiting and refused by a second look at what was opened."""
    path = os.fspath(path)
    check_regular(path, what, error)
    flags = os.O_RDONLY
    for name in ("O_NONBLOCK", "O_NOCTTY", "O_CLOEXEC", "O_BINARY"):
        flags |= getattr(os, name, 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise _os_error(path, what, exc, error) from None
    bad = _not_regular(path, what, os.fstat(fd).st_mode, error)
    if bad is not None:
        os.close(fd)
        raise bad
    return fd


def _too_large(path: str, what: str, size: int | None, limit: int, error: type[FgslamError]) -> FgslamError:
    shown = f"{size} bytes" if size is not None else f"more than {limit} bytes"
    return error(f"{path}: the {what} is {shown}, more than the {_mib(limit)} fgslam reads; "
                 "is this the right file? (split a long recording into several)")


def _mib(n: int) -> str:
    return f"{n / 2**30:g} GiB" if n >= 2**30 else f"{n / 2**20:g} MiB"


def read_bytes(path: str | os.PathLike[str], what: str, *, limit: int = MAX_TEXT_BYTES,
               error: type[FgslamError] = InputFileError) -> bytes:
    """The whole regular file at ``path`` (:func:`open_regular`), at most ``limit`` bytes;
    larger is one ``error`` line saying so."""
    path = os.fspath(path)
    fd = open_regular(path, what, error)
    with os.fdopen(fd, "rb") as f:
        size = os.fstat(fd).st_size
        if size > limit:
            raise _too_large(path, what, size, limit, error)
        try:
            data = f.read(limit + 1)  # the file may grow while it is read
        except OSError as exc:
            raise _os_error(path, what, exc, error) from None
    if len(data) > limit:
        raise _too_large(path, what, None, limit, error)
    return data


def content_lines(path: str | os.PathLike[str]) -> Iterator[tuple[int, str]]:
    """``(line number, stripped text)`` of each line of a UTF-8 text file that is neither
    blank nor a ``#`` comment."""
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            text = line.strip()
            if text and not text.startswith("#"):
                yield number, text
