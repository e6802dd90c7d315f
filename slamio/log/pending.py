"""A log being recorded: written beside its final name, put in place once it has begun.

``fgslam record --overwrite`` used to truncate the old log to its header before the robot
had answered: a robot that never answered cost the user their recording. A
:class:`PendingLogWriter` writes a hidden file beside the log,
``.NAME.recording-PID.tmp``; :meth:`PendingLogWriter.place` — called once the robot has
answered — makes its lines durable (``fsync``) and renames it over the final name in one
step (the old file, if any, is replaced only then; a new file never replaces one that
appeared meanwhile). Writing then goes on in the same open file, now under the final name,
each line handed to the operating system as it is written, so a recorder killed even by SIGKILL
keeps every complete record.

If the recording ends before :meth:`place` (no answer, a fault at start-up), :meth:`close`
removes the hidden file and the old log is untouched, byte for byte. A recorder killed
before it placed its log leaves its hidden file; the next recording of the same name
removes those of processes that no longer run, so nothing blocks a retry.

A write that fails (a full disk) raises :class:`LogWriteError` naming the file; the file is
cut back to its last complete line, so what was complete is kept and reads cleanly.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from slamio.errors import FgslamError
from slamio.log.records import Header, Record
from slamio.log.write import format_line

__all__ = ["LogWriteError", "PendingLogWriter"]


class LogWriteError(FgslamError):
    """A log line could not be written (disk full, file system gone)."""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_pending(final: Path) -> list[Path]:
    """Remove the hidden files of recordings of ``final`` whose process is gone."""
    removed = []
    prefix = f".{final.name}.recording-"
    try:
        entries = list(final.parent.iterdir())
    except OSError:
        return removed
    for entry in entries:
        name = entry.name
        if not (name.startswith(prefix) and name.endswith(".tmp")):
            continue
        pid = name[len(prefix):-len(".tmp")]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)) and entry.is_file():
            try:
                entry.unlink()
                removed.append(entry)
            except OSError:
                pass
    return removed


class PendingLogWriter:
    """Writes a run log through a hidden file, :meth:`place` puts it at ``path``.

    Has :class:`slamio.log.LogWriter`'s interface (``write``, ``flush``, ``close``, a
    context manager). ``overwrite`` allows :meth:`place` to replace an existing file (whose
    permission bits the new log keeps).
    """

    def __init__(self, path: str | os.PathLike[str], header: Header, *, overwrite: bool = False):
        self.final = Path(path)
        self.overwrite = overwrite
        self.final.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_pending(self.final)
        self.pending = self.final.parent / f".{self.final.name}.recording-{os.getpid()}.tmp"
        self.path = os.fspath(self.pending)
        self.placed = False
        self.complete_bytes = 0  # the file's length after the last complete line
        try:
            self._fd: int | None = os.open(self.pending, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666)
        except OSError as exc:
            raise LogWriteError(f"cannot write the log {self.final}: {exc.strerror or exc}") from None
        self._lines = 0  # complete lines written (the header included)
        self.last_stamp_s = header.stamp_s  # the latest stamp written (a line must not go back before it)
        self._write_line(format_line(header))

    def _where(self) -> Path:
        return self.final if self.placed else self.pending

    def _write_line(self, line: str) -> None:
        """One line, handed to the operating system at once (no buffer a dying process loses)."""
        encoded = line.encode("utf-8") + b"\n"
        data = memoryview(encoded)
        try:
            while data:
                data = data[os.write(self._fd, data):]
        except OSError as exc:
            try:  # drop a partial line: what was complete stays, and reads cleanly
                os.ftruncate(self._fd, self.complete_bytes)
            except OSError:
                pass
            raise LogWriteError(f"cannot write the log {self._where()}: {exc.strerror or exc} (it keeps the "
                                f"{max(0, self._lines - 1)} complete records before)") from None
        self.complete_bytes += len(encoded)
        self._lines += 1

    def write(self, record: Record) -> None:
        self._write_line(format_line(record))
        stamp = getattr(record, "stamp_s", None)
        if stamp is not None and stamp > self.last_stamp_s:
            self.last_stamp_s = stamp

    def flush(self) -> None:
        """Every line is with the operating system as soon as it is written: nothing to do."""

    def place(self) -> None:
        """Make the lines so far durable and move the file to its final name (see module)."""
        if self.placed:
            return
        try:
            os.fsync(self._fd)
            if self.overwrite and self.final.is_file():
                os.chmod(self.pending, stat.S_IMODE(self.final.stat().st_mode))
            if self.overwrite:
                os.replace(self.pending, self.final)
            else:
                os.link(self.pending, self.final)  # fails if a file appeared meanwhile: never replaced
                os.unlink(self.pending)
        except FileExistsError:
            raise LogWriteError(f"{self.final} appeared while the robot was starting; nothing was replaced: give "
                                "another name, or --overwrite") from None
        except OSError as exc:
            raise LogWriteError(f"cannot put the log in place at {self.final}: {exc.strerror or exc}") from None
        self.placed = True
        _fsync_folder(self.final.parent)

    def close(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)
        if not self.placed:
            try:
                os.unlink(self.pending)
            except FileNotFoundError:
                pass

    def __enter__(self) -> "PendingLogWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (where the file system allows it)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
