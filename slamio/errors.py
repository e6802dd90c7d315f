"""The one exception base class of the project.

Every error a user can cause (a bad log line, an unknown scenario, a bad option) is an
``FgslamError``; the CLI prints its message and exits non-zero instead of a traceback:
status 1 for a mistake in the command, status 2 for an input file that cannot be used
(:class:`InputFileError`).
"""


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
    symbolic-link loop, larger than :data:`slamio.safe_input.MAX_TEXT_BYTES`) or is not
    UTF-8 (:func:`decode_utf8` with ``expected``). Never blocks on a FIFO."""
    from slamio.safe_input import read_bytes

    return decode_utf8(path, read_bytes(path, what, error=error), expected, error)
