"""A file is written whole or not at all: through a hidden temporary file beside it and a rename.

Every file of a results folder (``fgslam run``, ``fgslam bench``: metrics, TUM trajectories,
the g2o graph, the report and its figures) is written with :func:`write_whole`. A write that
fails (a full disk, ``ENOSPC``; a file larger than the file system or the process's limit
allows, ``EFBIG``; a used-up quota, ``EDQUOT``) removes its temporary file and raises the
:class:`OSError` with the *final* file name in it, so the one error line of the CLI names the
file the user asked for, and nothing half-written is ever left under that name.

The temporary name is ``.NAME.PID.HEX.tmp`` (:func:`temp_path`); :func:`is_temp_name` tells
one (e.g. left by a process that was killed) from a user's file.
"""

from __future__ import annotations

import os
import re
import secrets
from pathlib import Path
from typing import Callable

__all__ = ["is_temp_name", "save_figure", "temp_path", "write_text_whole", "write_whole"]

_TEMP = re.compile(r"\..+\.\d+\.[0-9a-f]{8}\.tmp")


def temp_path(path: str | os.PathLike[str]) -> Path:
    """A fresh hidden temporary name beside ``path``: ``.NAME.PID.HEX.tmp``."""
    out = Path(path)
    return out.parent / f".{out.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"


def is_temp_name(name: str) -> bool:
    """Whether ``name`` (a file name, no folder) is one of :func:`temp_path`'s."""
    return _TEMP.fullmatch(name) is not None


def naming(error: OSError, path: str | os.PathLike[str], tmp: str | os.PathLike[str] | None = None) -> OSError:
    """``error`` with ``path`` as its file name when it had none or named the temporary file."""
    if error.filename is not None and (tmp is None or os.fspath(error.filename) != os.fspath(tmp)):
        return error
    return type(error)(error.errno, error.strerror or str(error), os.fspath(path))


def write_whole(path: str | os.PathLike[str], write: Callable[[Path], object]) -> Path:
    """``write(tmp)`` into a temporary file beside ``path``, then rename it to ``path``
    (replacing a file there). On any failure the temporary file is removed; an
    :class:`OSError` is raised again with ``path`` as its file name. Returns ``path``."""
    out = Path(path)
    tmp = temp_path(out)
    try:
        write(tmp)
        os.replace(tmp, out)
    except OSError as error:
        _remove(tmp)
        raise naming(error, out, tmp) from None
    except BaseException:
        _remove(tmp)
        raise
    return out


def write_text_whole(path: str | os.PathLike[str], text: str) -> Path:
    """:func:`write_whole` of UTF-8 ``text``."""
    return write_whole(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def save_figure(fig, path: str | os.PathLike[str], **savefig) -> Path:
    """A matplotlib figure saved whole (the format from the name's suffix, PNG without one)."""
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    return write_whole(path, lambda tmp: fig.savefig(tmp, format=fmt, **savefig))


def _remove(tmp: Path) -> None:
    try:
        tmp.unlink()
    except FileNotFoundError:
        pass
    except OSError:
        pass  # nothing more can be done; its name is hidden and the next run into the folder removes it
