"""A results folder (``fgslam run --out DIR``, ``fgslam bench --out DIR``) that never keeps a
stale file, never deletes what fgslam did not write, and is never left half-written.

- ``check()`` (before the run) accepts a new or empty folder, or one holding an earlier fgslam
  output (a ``manifest.json`` it wrote, or — from before manifests — a ``metrics.json`` with
  the ``.tum`` files of ``fgslam run``). Anything else is refused unless ``overwrite``, and so
  is the output of another verb or of another input (``source``). So is a folder or a
  symbolic link under one of fgslam's own file names: fgslam never removes a folder and never
  replaces or follows a link, whatever a (hand-edited) manifest says.
- ``clear()`` (after the run, just before writing) removes the earlier output's files: the
  *regular* files its manifest lists, or for an older output or with ``overwrite`` the
  regular files with fgslam's own names. Folders, symbolic links and every other file are
  left alone. It then writes an interim manifest that marks the folder incomplete, so a run
  that dies while writing leaves a folder the next run replaces without ``--overwrite``.
- ``filling()`` wraps the writing: every file is written whole (:mod:`fgslam.atomic`), and a
  write that fails (full disk, file-size limit, quota) is one error line naming the file;
  the files already written whole are kept and listed in a manifest that says
  ``"complete": false``.
- ``finish()`` writes the manifest of the complete output: every regular file written since
  ``clear()``, ``"complete": true``.

Callers hold the folder's :class:`slamio.filelock.OutputLock` around all of it
(:func:`fgslam.cli.common.holds_outputs`), so no second writer changes it in between.
"""

from __future__ import annotations

import contextlib
import json
import os
import stat
from pathlib import Path
from typing import Callable, Iterable, Iterator

from fgslam.atomic import is_temp_name, write_text_whole
from fgslam.cli.common import counted, explain, probe_writable
from slamio.errors import FgslamError

__all__ = ["MANIFEST", "MANIFEST_FORMAT", "ResultsFolder", "ResultsIncomplete"]

MANIFEST = "manifest.json"
MANIFEST_FORMAT = "fgslam-results"


class ResultsIncomplete(FgslamError):
    """A file of the results could not be written; the complete ones are kept and listed."""


class ResultsFolder:
    """The results folder of one verb at ``path``; see the module docstring."""

    def __init__(self, path: str | os.PathLike, *, overwrite: bool = False, verb: str = "run",
                 own_names: Iterable[str] | Callable[[], Iterable[str]] = (), own_suffixes: Iterable[str] = (),
                 option: str = "--out", source: str | None = None):
        self.path = Path(path)
        self.source = source  # what the output is made from (an absolute log path), kept in the manifest
        self.overwrite = overwrite
        self.verb = verb
        self._own_names = own_names  # a callable is asked only when needed (it may import a lot)
        self.own_suffixes = tuple(own_suffixes)
        self.option = option
        self.earlier: list[str] | None = None  # files of the earlier output to remove
        self._before: dict[str, tuple] = {}
        self.finish_names: list[str] = []

    # -- before the run
    def check(self) -> "ResultsFolder":
        out = self.path
        if out.exists() and not out.is_dir():
            raise FgslamError(f"{self.option} {out} is a file, and the results are a folder of files; "
                              f"give a folder name (e.g. {out.with_suffix('')}_results)")
        entries = sorted(p.name for p in out.iterdir() if not is_temp_name(p.name)) if out.is_dir() else []
        if entries:
            manifest = self._read_manifest()
            if manifest is not None:
                if not self.overwrite:
                    self._refuse_other_output(manifest)
                self.earlier = manifest["files"]
            elif self._looks_like_older_output(entries):
                self.earlier = [n for n in entries if self._is_own(n)]
            elif self.overwrite:
                self.earlier = [n for n in entries if self._is_own(n)]
            else:
                shown = ", ".join(entries[:3]) + (f", ... ({len(entries)} in all)" if len(entries) > 3 else "")
                raise FgslamError(
                    f"{self.option} {out} is a folder with other files in it ({shown}) and no {MANIFEST} of an "
                    f"earlier fgslam {self.verb}; give a new or empty folder, or add --overwrite to write into "
                    "it (fgslam's own file names there are replaced, other files are left alone)"
                )
            self._refuse_what_it_cannot_replace(entries)
        probe_writable(out, option=self.option)  # makes nothing: the folder is made by clear()
        return self

    def _read_manifest(self) -> dict | None:
        try:
            data = json.loads((self.path / MANIFEST).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT or not isinstance(data.get("files"), list):
            return None
        planned = data.get("planned") if isinstance(data.get("planned"), list) else []
        listed = [n for n in [*data["files"], *planned] if isinstance(n, str) and _plain_name(n)]
        return {**data, "files": list(dict.fromkeys(listed))}

    def _refuse_other_output(self, manifest: dict) -> None:
        """Raise when the folder holds another verb's output, or this verb's output of another
        input: replacing those is what ``--overwrite`` is for."""
        by = manifest.get("written_by")
        fix = "give another folder, or add --overwrite to replace them"
        if isinstance(by, str) and by != f"fgslam {self.verb}":
            raise FgslamError(f"{self.option} {self.path} holds the results of an earlier `{by}` ({MANIFEST}), "
                              f"not of fgslam {self.verb}; {fix}")
        earlier = manifest.get("source")
        if self.source is not None and isinstance(earlier, str) and earlier != self.source:
            raise FgslamError(f"{self.option} {self.path} holds the results of fgslam {self.verb} on {earlier} "
                              f"({MANIFEST}), not on {self.source}; {fix}")

    def _refuse_what_it_cannot_replace(self, entries: list[str]) -> None:
        """A folder or a symbolic link where fgslam writes one of its own files: fgslam never
        removes the one nor replaces the other, so it says so before the run."""
        odd = [n for n in entries if not _is_regular(self.path / n)]
        clash = [n for n in odd if self._is_own(n)] if odd else []
        if clash:
            path = self.path / clash[0]
            what = "a symbolic link" if path.is_symlink() else "a folder" if path.is_dir() else "not a regular file"
            raise FgslamError(
                f"{self.option} {path} is {what}, where fgslam {self.verb} writes a file of its own; "
                "fgslam never removes a folder nor replaces or follows a link: move it out of the way, or give "
                "another folder")

    def _looks_like_older_output(self, entries: list[str]) -> bool:
        """An ``fgslam run`` folder from before manifests: its metrics.json and .tum files."""
        if "metrics.json" not in entries or not any(n.endswith(".tum") for n in entries):
            return False
        try:
            metrics = json.loads((self.path / "metrics.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        return isinstance(metrics, dict) and "reference" in metrics

    @property
    def own_names(self) -> set[str]:
        if callable(self._own_names):
            self._own_names = tuple(self._own_names())
        return set(self._own_names) | {MANIFEST}

    def _is_own(self, name: str) -> bool:
        return name in self.own_names or (bool(self.own_suffixes) and name.endswith(self.own_suffixes))

    # -- after the run
    def clear(self) -> list[str]:
        """Remove the earlier output's regular files (and temporary files a killed run left);
        mark the folder incomplete until :meth:`finish`; return the names removed."""
        removed = []
        for name in self.earlier or ():
            if name == MANIFEST:  # replaced below, not removed first: the folder never lacks one
                if _is_regular(self.path / name):
                    removed.append(name)
            elif _remove_regular(self.path / name):
                removed.append(name)
        self.path.mkdir(parents=True, exist_ok=True)
        for entry in os.scandir(self.path):
            if is_temp_name(entry.name):
                _remove_regular(Path(entry.path))
        self._write_manifest(complete=False, files=[], planned=sorted(self.own_names - {MANIFEST}))
        self._before = self._snapshot()
        return removed

    @contextlib.contextmanager
    def filling(self, **provenance) -> Iterator["ResultsFolder"]:
        """Write the results inside this block: a failed write (an :class:`OSError`) becomes
        :class:`ResultsIncomplete`, one line naming the file, with the complete files kept
        and listed in a manifest marked ``"complete": false``."""
        try:
            yield self
        except OSError as error:
            kept = self._written()
            with contextlib.suppress(OSError):  # on a full disk even the manifest may not fit
                self._write_manifest(complete=False, files=kept, error=explain(error), **provenance)
            raise ResultsIncomplete(
                f"{explain(error)}; the results in {self.path} are incomplete ({counted(len(kept), 'file')} written "
                f"whole, kept and listed in its {MANIFEST}; nothing half-written): run the same command again, it "
                "replaces them without --overwrite") from None

    def finish(self, **provenance) -> list[str]:
        """Write the manifest (every file written since :meth:`clear`); return the names."""
        written = self._written()
        self.finish_names = written
        self._write_manifest(complete=True, files=written, **provenance)
        return written

    def _written(self) -> list[str]:
        now = self._snapshot()
        return sorted(n for n, st in now.items() if self._before.get(n) != st and n != MANIFEST)

    def _snapshot(self) -> dict[str, tuple]:
        """The regular files of the folder (not temporary ones), by name."""
        result = {}
        for entry in os.scandir(self.path):
            try:
                st = entry.stat(follow_symlinks=False)
            except OSError:
                continue
            if stat.S_ISREG(st.st_mode) and not is_temp_name(entry.name):
                result[entry.name] = (st.st_ino, st.st_size, st.st_mtime_ns)
        return result

    def _write_manifest(self, *, complete: bool, files: list[str], **fields) -> None:
        manifest = {"format": MANIFEST_FORMAT, "written_by": f"fgslam {self.verb}", **fields,
                    **({"source": self.source} if self.source is not None else {}),
                    "complete": complete, "files": [*files, MANIFEST]}
        write_text_whole(self.path / MANIFEST, json.dumps(manifest, indent=1) + "\n")


def _plain_name(name: str) -> bool:
    """A manifest entry that names a file directly in the folder (nothing outside it)."""
    return bool(name) and name not in (".", "..") and "/" not in name and "\\" not in name and "\0" not in name


def _is_regular(path: Path) -> bool:
    """A regular file itself (not a folder, not a symbolic link, whatever it points to)."""
    try:
        return stat.S_ISREG(path.lstat().st_mode)
    except OSError:
        return False


def _remove_regular(path: Path) -> bool:
    """Remove ``path`` if it is a regular file; return whether it was removed."""
    if not _is_regular(path):
        return False
    try:
        path.unlink()
    except FileNotFoundError:
        return False
    return True
