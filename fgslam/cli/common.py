"""What every verb shares: the one error path, reading and writing logs, and outputs that
never overwrite what the user has unless asked.

Verb modules import from here (and from :mod:`fgslam.cli.progress`), never from the
``fgslam.cli`` package itself, so there is no import cycle.

Outputs
-------
- A single output file (a run log, a calibration, a noise model): :func:`check_new_file`
  before any work — it refuses an existing file unless ``--overwrite``, a folder, and a
  place that cannot be written (it tries: a probe file is created and removed) — then
  :func:`write_new_file` writes it through a temporary file in the same folder and a rename,
  so an interrupted write never leaves half a file where the old one was.
- A results folder (``fgslam run --out DIR``, ``fgslam bench --out DIR``):
  :class:`fgslam.cli.results.ResultsFolder`. It is checked before the run and filled after
  it; the files a run wrote are listed in ``DIR/manifest.json``, and the next run into the
  same folder removes exactly those first (regular files only: never a folder, never a
  symbolic link), so nothing stale from an older run remains.
- One writer per output: a verb that writes holds :class:`slamio.filelock.OutputLock` on
  each output from before its checks to its last byte (:func:`holds_outputs`); a second
  ``fgslam`` writing the same output is refused, one line naming the holder's process id.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
import os
import stat
import sys
from pathlib import Path
from typing import Callable, Iterator

from slamio.errors import FgslamError

PROG = "fgslam"


# --------------------------------------------------------------------------- the one error path


def explain(error: BaseException) -> str:
    """The message of a user error: what is wrong, where, and how to fix it."""
    from slamio.log import LogFormatError

    if isinstance(error, OSError) and not isinstance(error, FgslamError):
        return _explain_os_error(error)
    message = str(error)
    if isinstance(error, LogFormatError) and error.partial is not None and error.line > 2:
        message += (
            f"\n  (the {error.line - 1} lines before it are valid; fix or delete line {error.line}, "
            f"or keep only the good part: head -n {error.line - 1} {error.path} > good.jsonl)"
        )
    return message


def _explain_os_error(error: OSError) -> str:
    what = error.strerror or str(error) or type(error).__name__
    if error.filename is None:
        return what
    where = f"{error.filename}" + (f" -> {error.filename2}" if error.filename2 is not None else "")
    hint = {
        "EACCES": "choose a place you can write to, or change its permissions",
        "EPERM": "choose a place you can write to, or change its permissions",
        "EROFS": "the file system is read-only: choose another place",
        "ENOSPC": "free some space or choose another disk",
        "EFBIG": "the file is larger than this file system or the file-size limit (ulimit -f) allows: "
                 "free some space, raise the limit or choose another disk",
        "EDQUOT": "your disk quota is used up: free some space or choose another disk",
        "EISDIR": "give a file name, not a folder",
        "ENOTDIR": "a part of the path is a file, not a folder",
        "ENOENT": "check the path",
    }.get(_errno_name(error.errno), "")
    return f"{where}: {what}" + (f" ({hint})" if hint else "")


def _errno_name(number: int | None) -> str:
    import errno

    return errno.errorcode.get(number, "") if number is not None else ""


def fail(error: BaseException, stream=None) -> int:
    """Print a user error as ``fgslam: error: ...`` on stderr and return exit status 1.

    The only place a verb's :class:`FgslamError` or :class:`OSError` (a file that does not
    open, a folder that cannot be written, a full disk) becomes a message.
    """
    stream = sys.stderr if stream is None else stream
    if isinstance(error, BrokenPipeError):  # `fgslam ... | head`: the reader left; say nothing
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 1
    print(f"{PROG}: error: {explain(error)}", file=stream)
    return 1


def run_verb(func: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run a verb's handler: user errors become one line and exit 1, Ctrl-C exit 130."""
    try:
        return func(args)
    except (FgslamError, OSError) as error:
        return fail(error)
    except KeyboardInterrupt as interrupt:  # a robot verb's Interrupted knows its signal (SIGHUP: 129)
        try:
            print(f"{PROG}: interrupted{f' by {interrupt}' if str(interrupt) else ''}", file=sys.stderr)
        except OSError:  # the terminal is gone
            pass
        return getattr(interrupt, "exit_code", 130)


def command_line(args: argparse.Namespace, default: str = "") -> str:
    """The command as typed (``fgslam sim ...``), for the provenance in headers and manifests.

    ``--overwrite`` is left out: it says what happens to an older file, not what is in this
    one, so ``make data`` (which needs it) gives the same bytes as the first ``fgslam sim``.
    """
    import shlex

    argv = getattr(args, "argv", None)
    if argv is None:
        return f"{PROG} {default}".strip()
    return f"{PROG} " + " ".join(shlex.quote(a) for a in argv if a != "--overwrite")


def add_verb(verbs, name: str, **options) -> argparse.ArgumentParser:
    """Add the sub-command ``name`` to ``fgslam``'s sub-parsers ``verbs`` and return its parser;
    its ``description`` and ``epilog`` are printed as written, line breaks kept. ``options``
    are ``add_parser``'s (``help``, ``description``, ``epilog``, ``usage``)."""
    return verbs.add_parser(name, formatter_class=argparse.RawDescriptionHelpFormatter, **options)


def add_overwrite_option(parser: argparse.ArgumentParser, what: str = "an existing --out file") -> None:
    parser.add_argument("--overwrite", action="store_true", help=f"replace {what} (default: refuse, keep it)")


# --------------------------------------------------------------------------- logs


def summary(log) -> str:
    """One line on what a run log holds."""
    return tally_of(log).text()


def tally_of(log) -> LogTally:
    """The :class:`LogTally` of a log read whole (its records)."""
    tally = LogTally(log.header)
    for record in log.records:
        tally.add(record)
    return tally


class LogTally:
    """What :func:`summary` says about a log, counted one record at a time in file order (so
    ``fgslam validate`` can stream a log of any size): poses as :func:`slamio.log.group_steps`
    makes them, observations and their landmarks, ground truth per pose, surveyed landmarks."""

    def __init__(self, header) -> None:
        import slamio.log as log

        self._log = log  # the record classes, imported when a log is read (not at start-up)
        self.start = self.stamp = header.stamp_s
        self.poses, self.odometry, self.observations, self.unknown = 1, 0, 0, 0
        self.ids: set[int] = set()
        self.with_truth = self.headless = 0  # over the poses before the current one
        self.truth = None  # the current pose's truth (the last truth record since its odometry)
        self.surveyed: set[int] = set()
        self.surveyed3 = 0
        self.events: dict[str, int] = {}  # event kind -> count

    def add(self, record) -> None:
        log = self._log
        if isinstance(record, log.Observation):
            self.observations += 1
            if record.landmark_id is None:
                self.unknown += 1
            else:
                self.ids.add(record.landmark_id)
        elif isinstance(record, log.StereoObservation):
            self.observations += 1
            self.ids.add(record.track_id)
        elif isinstance(record, (log.Odometry, log.VelocityOdometry)):
            self.with_truth, self.headless = self._truths()
            self.truth, self.stamp = None, record.stamp_s
            self.poses += 1
            self.odometry += 1
        elif isinstance(record, (log.TruthPose, log.TruthPose3)):
            self.truth = record
        elif isinstance(record, log.TruthLandmark):
            self.surveyed.add(record.landmark_id)
        elif isinstance(record, log.TruthLandmark3):
            self.surveyed3 += 1
        elif isinstance(record, log.Event):
            self.events[record.kind] = self.events.get(record.kind, 0) + 1

    def event_counts(self) -> dict[str, int]:
        """:func:`slamio.log.event_counts` of the records counted."""
        return self._log.records.in_event_kind_order(self.events)

    def _truths(self) -> tuple[int, int]:
        """(poses with a truth, of them with a position alone) up to and with the current pose."""
        if self.truth is None:
            return self.with_truth, self.headless
        return self.with_truth + 1, self.headless + (getattr(self.truth, "theta_rad", 0.0) is None)

    def text(self) -> str:
        with_truth, headless = self._truths()
        surveyed = len(self.surveyed) + self.surveyed3
        if with_truth == self.poses:
            truth = "ground truth for every pose"
        elif with_truth:
            truth = f"ground truth for {with_truth} of {self.poses} poses"
        elif surveyed:
            truth = f"no pose truth, {counted(surveyed, 'surveyed landmark')}"
        else:
            truth = "no ground truth"
        if headless and headless == with_truth:
            truth += " (positions only: no heading)"
        elif headless:
            truth += f" ({headless} of them a position without heading)"
        unknown = self.unknown
        return (
            f"{counted(self.poses, 'pose')} over {self.stamp - self.start:.1f} s, "
            f"{counted(self.observations, 'observation')} of {counted(len(self.ids), 'landmark')}"
            + (f" (+{unknown} with unknown id)" if unknown else "") + f", {truth}"
            + (f", {counted(sum(self.events.values()), 'event')} ("
               + ", ".join(f"{n} {kind}" for kind, n in sorted(self.events.items())) + ")" if self.events else "")
        )


def counted(n: int, noun: str) -> str:
    """``3 poses``, ``1 pose``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def read(path: str):
    """Read a run log, warning on stderr when its last line was cut off."""
    from slamio.log import read_log

    return _warned(read_log(path))


def read_counted(path: str, *, columns: bool = False) -> tuple[object, LogTally | None]:
    """``(log, tally)``: with ``columns`` the log read into columns — a planar log by
    :func:`slamio.log.columns.columns_of`, a 3-D one by :func:`slamio.log.columns3d.columns3d_of`:
    no record objects held, the run's memory grows with its numbers — and its
    :class:`LogTally` counted as it streams; without ``columns`` read whole (:func:`read`)
    with tally None (count it from its records). The same warnings and errors as :func:`read`."""
    from slamio.log import LogStream
    from slamio.log.columns import columns_of
    from slamio.log.columns3d import columns3d_of

    if columns:
        stream = LogStream(path)
        tally = LogTally(stream.header)
        read_into = columns3d_of if stream.header.is_3d else columns_of
        return _warned(read_into(stream, visit=tally.add)), tally
    return read(path), None


def _warned(log):
    """``log``, after a warning on stderr when its last line was cut off or observations were rejected."""
    if log.truncated:
        print(f"{PROG}: warning: {log.truncated}", file=sys.stderr)
    rejected = log.rejection_summary() if hasattr(log, "rejection_summary") else None
    if rejected:
        print(f"{PROG}: warning: {rejected}", file=sys.stderr)
    return log


def write_run_log(out_path: str | os.PathLike, header, records, *, overwrite: bool = False, option: str = "--out") -> int:
    """Write a made or imported log (never over an existing file unless ``overwrite``) and
    say what is in it (from memory, not re-read)."""
    from slamio.log import RunLog, write_log

    records = tuple(records)
    out = Path(out_path)
    write_new_file(out, lambda tmp: write_log(tmp, header, records), overwrite=overwrite, option=option)
    print(f"wrote {out}: {summary(RunLog(str(out), header, records))}")
    for stale in stale_status_files(out):  # how the replaced recording ended (fgslam record): not this log's
        stale.unlink()
        print(f"removed {stale}: it described the recording {out} replaced")
    return 0


def status_path(log: str | os.PathLike) -> Path:
    """``run.jsonl.status.json`` beside ``run.jsonl``: how ``fgslam record`` says a recording
    ended. The whole name plus ``.status.json``, so each log has its own (``run.jsonl`` and
    ``run.json`` once shared ``run.status.json``)."""
    out = Path(log)
    return out.with_name(out.name + ".status.json")


def stale_status_files(log: str | os.PathLike) -> list[Path]:
    """The status files of ``log`` that a new log there makes stale: its own
    (:func:`status_path`), and one under the older name (``run.status.json`` for
    ``run.jsonl``) only when it says it describes this log (its ``"log"``), as another
    log's status file may have that name."""
    out = Path(log)
    found = [path for path in [status_path(out)] if path.is_file() and not path.is_symlink()]
    older = out.with_name(out.stem + ".status.json")
    if out.suffix and older.is_file() and not older.is_symlink() and _status_names(older, out):
        found.append(older)
    return found


def _status_names(status: Path, log: Path) -> bool:
    try:
        described = json.loads(status.read_text(encoding="utf-8")).get("log")
    except (OSError, ValueError, AttributeError):
        return False
    return isinstance(described, str) and Path(described).name == log.name


# --------------------------------------------------------------------------- single output files


def check_new_file(path: str | os.PathLike, *, overwrite: bool = False, option: str = "--out",
                   example: str = "run.jsonl") -> Path:
    """Check, before any work, that ``path`` can be written as a new file.

    Refuses (:class:`FgslamError`, one line naming the file and the fix) an existing file
    unless ``overwrite``, an existing folder, and a place that cannot be written to. Creates
    nothing: the missing parent folders are made when the file is written. Returns ``path``.
    """
    out = Path(path)
    if out.is_dir():
        raise FgslamError(f"{option} {out} is a folder; give a file name such as {out / example}")
    if out.exists() or out.is_symlink():
        if not overwrite:
            raise FgslamError(
                f"{option} {out} exists ({_describe_file(out)}); give another name, or add --overwrite to replace it"
            )
    probe_writable(out.parent, option=option, target=out)
    return out


def check_number(option: str, value, *, above: float | None = None, at_least: float | None = None,
                 at_most: float | None = None, what: str = "", error: type[FgslamError] = FgslamError) -> None:
    """A number option's value (or each of an ``X,Y`` tuple's) is finite and inside the bounds,
    checked before a verb does any work; else one ``error`` line naming the option, the rule,
    what the number means (``what``) and the value."""
    values = value if isinstance(value, tuple) else (value,)
    ok = all(isinstance(v, (int, float)) and math.isfinite(v) for v in values) and all(
        (above is None or v > above) and (at_least is None or v >= at_least) and (at_most is None or v <= at_most)
        for v in values)
    if not ok:
        bounds = [f"{sign} {bound:g}" for sign, bound in ((">", above), (">=", at_least), ("<=", at_most))
                  if bound is not None]
        rule = ("a number " + " and ".join(bounds) if bounds else
                "finite numbers" if len(values) > 1 else "a finite number")
        shown = ",".join(f"{v:g}" for v in values)
        raise error(f"{option} must be {rule}{f' ({what})' if what else ''}; got {shown}")


def _describe_file(path: Path) -> str:
    try:
        size = path.stat().st_size
    except OSError:
        return "unreadable"
    if path.suffix == ".jsonl" and size < 1 << 30:
        try:
            with open(path, "rb") as f:
                lines = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 20), b""))
            return f"{lines} lines"
        except OSError:
            pass
    return f"{size} bytes"


def probe_writable(folder: Path, *, option: str = "--out", target: Path | None = None) -> None:
    """Check that files can be made in ``folder`` (or, while it does not exist, in its nearest
    existing parent, where it will be made): create a probe file there and remove it — the
    only test that also holds for root on a read-only disk. Creates nothing that stays.
    One clear line (:class:`FgslamError`) if it fails."""
    import tempfile

    target = folder if target is None else target
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise FgslamError(f"{option} {target}: {existing} is a file, not a folder; choose another place")
    try:
        fd, probe = tempfile.mkstemp(prefix=".fgslam-probe-", dir=existing)
        os.close(fd)
        os.unlink(probe)
    except OSError as error:
        raise FgslamError(f"{option} {target}: cannot write in {existing} ({error.strerror or error}); "
                          f"choose a place you can write to") from None


def write_new_file(path: Path, write: Callable[[str], None], *, overwrite: bool = False, option: str = "--out") -> None:
    """``write(tmp)`` into a temporary file beside ``path``, then move it into place.

    Never replaces an existing file unless ``overwrite`` (checked again here: a file may have
    appeared during the work), and never leaves a half-written file at ``path``. A new file
    gets the umask's mode; a replaced one keeps its permission bits.
    """
    from fgslam.atomic import naming, temp_path

    path = Path(path)
    check_new_file(path, overwrite=overwrite, option=option)
    path.parent.mkdir(parents=True, exist_ok=True)
    kept_mode = stat.S_IMODE(path.stat().st_mode) if overwrite and path.is_file() else None
    # Not mkstemp: its file is 0600, and the log would keep that; this one gets the umask's mode.
    tmp = str(temp_path(path))
    open(tmp, "x").close()
    try:
        try:
            write(tmp)
        except OSError as error:  # a full disk: the message names the file asked for, not the temporary one
            raise naming(error, path, tmp) from None
        if kept_mode is not None:
            os.chmod(tmp, kept_mode)
        if overwrite:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)  # fails if the file appeared meanwhile: never replaced
            except FileExistsError:
                raise FgslamError(f"{option} {path} appeared while it was being made; nothing was replaced, "
                                  "give another name or add --overwrite") from None
            except OSError:  # a file system without hard links
                if path.exists():
                    raise FgslamError(f"{option} {path} appeared while it was being made; nothing was "
                                      "replaced, give another name or add --overwrite") from None
                os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


# --------------------------------------------------------------------------- one writer per output


@contextlib.contextmanager
def hold_outputs(*outputs: tuple[str | os.PathLike | None, str]) -> Iterator[None]:
    """Hold the :class:`~slamio.filelock.OutputLock` of each ``(path, option)`` (``None``
    paths skipped) while the block runs; a second writer is refused with
    :class:`~slamio.filelock.OutputBusy`, one line naming the holder's process id.

    The lock file lives beside the output, so its folder must exist: a place that cannot be
    written is refused first as :func:`probe_writable` says, and folders made only for the
    lock are removed again at the end if nothing was put in them.
    """
    from slamio.filelock import OutputLock

    with contextlib.ExitStack() as stack:
        for path, option in outputs:
            if not path:  # not given
                continue
            out = Path(path)
            probe_writable(out.parent, option=option, target=out)
            stack.callback(_remove_if_empty, _missing_folders(out.parent))  # after the release
            stack.enter_context(OutputLock(out, option=option))
        yield


def holds_outputs(**options: str):
    """Decorate a verb's handler: hold the lock of ``args.NAME`` (refusals naming
    ``options[NAME]``, e.g. ``out="--out"``) for each NAME while the handler runs."""

    def decorate(handler: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
        @functools.wraps(handler)
        def verb(args: argparse.Namespace) -> int:
            with hold_outputs(*((getattr(args, name, None), option) for name, option in options.items())):
                return handler(args)

        return verb

    return decorate


def _missing_folders(folder: Path) -> list[Path]:
    """``folder`` and its parents that do not exist yet, deepest first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def _remove_if_empty(folders: list[Path]) -> None:
    for folder in folders:  # deepest first; stops at the first that holds something
        try:
            folder.rmdir()
        except OSError:
            return
