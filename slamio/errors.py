"""The one exception base class of the project.

Every error a user can cause (a bad log line, an unknown scenario, a bad option) is an
``FgslamError``; the CLI prints its message and exits non-zero instead of a traceback.
"""


class FgslamError(Exception):
    """Base class of every error fgslam raises on purpose."""


def decode_utf8(path, raw: bytes, expected: str, error: type[FgslamError] = FgslamError) -> str:
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


def read_text(path, what: str, expected: str, error: type[FgslamError] = FgslamError) -> str:
    """The text of the user's file at ``path`` (a ``what``: "trials file", "camera file", ...):
    one ``error`` line when it cannot be read (and why) or is not UTF-8 (:func:`decode_utf8`
    with ``expected``)."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror})") from None
    return decode_utf8(path, raw, expected, error)
