"""One writer per output: an advisory lock (``fcntl.flock``) held while a verb writes.

Two ``fgslam run LOG --out SAME`` started together used to both exit 0 and leave a folder
mixing both runs. Every verb that writes an output (a run log being recorded, a results
folder) now holds :class:`OutputLock` on it from its checks to its last byte; a second
writer gets :class:`OutputBusy`, one line naming the holder's process id.

The lock is a hidden file beside the output, ``.NAME.fgslam-lock`` (beside, not inside: a
log is replaced by a rename, and a folder may not exist yet). It holds the holder's pid.
The holder removes it when done; a holder that was killed leaves it behind, and the next
writer takes it over (``flock`` locks die with their process, so a stale file blocks
nothing). Taking it checks, after locking, that the file locked is still the one at the
path (another holder may have removed it in between), the usual pattern for lock files
that are removed on release.
"""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

from slamio.errors import FgslamError

__all__ = ["OutputBusy", "OutputLock", "lock_path"]


class OutputBusy(FgslamError):
    """Another process is writing the same output."""


def lock_path(output: str | os.PathLike[str]) -> Path:
    """The lock file of ``output``: ``.NAME.fgslam-lock`` in the same folder."""
    out = Path(output)
    return out.parent / f".{out.name}.fgslam-lock"


def _holder(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace").strip()
    except OSError:
        return "another process"
    return f"process {text}" if text.isdigit() else "another process"


class OutputLock:
    """Hold the advisory lock of ``output`` (a file or folder path) while the block runs.

    ``option`` names the command-line option in the refusal. Creates the output's parent
    folder if needed (the lock file lives there). Not reentrant; one per output per process.
    """

    def __init__(self, output: str | os.PathLike[str], *, option: str = "--out"):
        self.output = Path(output)
        self.path = lock_path(self.output)
        self.option = option
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> "OutputLock":
        if self._fd is not None:
            return self
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(100):  # a holder removing the file between our open and our lock: retry
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise OutputBusy(
                        f"{self.option} {self.output} is being written by {_holder(self.path)} (an fgslam "
                        f"still running; its lock is {self.path}); wait for it to end, or choose another "
                        f"{self.option}") from None
                raise
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
                self._fd = fd
                return self
            os.close(fd)
        raise OutputBusy(f"{self.option} {self.output}: could not take its lock {self.path}")  # pragma: no cover

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            os.unlink(self.path)  # while still locked: the next writer sees a fresh file
        except OSError:
            pass
        os.close(fd)

    def __enter__(self) -> "OutputLock":
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()
