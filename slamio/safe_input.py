"""Reading the user's files without trusting them: one place for what every reader refuses.

Every file fgslam reads (run logs, noise models, calibrations, trials, camera and landmark
files, tolerance files, waypoints, datasets) comes through here, so each refuses the same
hostile inputs with the same kind of message — :class:`~slamio.errors.InputFileError`
(``fgslam`` exits with status 2), naming the file, and the line and field where the format
has them:

- **not a regular file**: a FIFO (opening one for reading waits for a writer, forever), a
  device such as ``/dev/zero`` (never ends), a socket, a folder, or a loop of symbolic
  links. :func:`~slamio.errors.open_regular` looks before it reads (``stat``), opens without blocking and
  looks again (``fstat``: a file swapped in between is caught too);
- **too large**: a whole-file read stops at a cap (:data:`~slamio.errors.MAX_TEXT_BYTES` for text files,
  the run log's own cap for logs) instead of filling the memory;
- **JSON, YAML and TOML that no fgslam file holds**: nesting deeper than
  :data:`MAX_NESTING` levels (Python's parsers recurse, and a thousand levels crash them),
  integers of more than :data:`MAX_INTEGER_DIGITS` digits (a 5 000-digit integer is over
  Python's own limit; a 400-digit one overflows every float), numbers a float cannot hold
  (``1e400`` reads as infinity), ``NaN``/``Infinity`` literals (JSON), ``.inf``/``.nan``
  and aliases (YAML).

:func:`parse_json`, :func:`parse_yaml` and :func:`parse_toml` return a :class:`Document`:
the data plus the line of every field, so a reader's own checks (a value out of its range)
name ``file:line: field 'a.b[2]'`` as the parsers' errors do.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from typing import Any, Iterable

from slamio.errors import FgslamError, InputFileError

__all__ = [
    "MAX_INTEGER_DIGITS", "MAX_NESTING", "Document", "field_name", "parse_json", "parse_toml", "parse_yaml", "shown",
]

#: How deeply lists and objects may nest in a JSON, YAML or TOML file fgslam reads.
MAX_NESTING = 64
#: The most digits an integer in a JSON, YAML or TOML file may have (ids, counts and seeds
#: fit in 19; a longer one is a corrupted file, and beyond 308 it overflows every float).
MAX_INTEGER_DIGITS = 19



def shown(text: str, limit: int = 40) -> str:
    """``repr(text)`` for a message, shortened: a 300 000-character cell stays one short line."""
    return repr(text) if len(text) <= limit else f"{text[:limit - 10]!r}... ({len(text)} characters)"


# --------------------------------------------------------------------------- documents


def field_name(keys: Iterable[Any]) -> str:
    """``("landmarks", 0, "width_m")`` → ``landmarks[0].width_m``."""
    out = ""
    for key in keys:
        out += f"[{key}]" if isinstance(key, int) else (f".{key}" if out else str(key))
    return (out if len(out) <= 60 else out[:50] + "...") or "the top level"


@dataclass(frozen=True)
class Document:
    """A parsed file: ``data``, and the 1-based line where each field's value starts
    (``lines[("a", 0)]`` for ``a[0]``), so an error can say ``file:line: field 'a[0]'``."""

    path: str
    data: Any
    lines: dict[tuple, int] = field(default_factory=dict)

    def line(self, *keys: Any) -> int | None:
        """The line of the field ``keys``, or of the nearest enclosing field that has one."""
        for n in range(len(keys), -1, -1):
            if tuple(keys[:n]) in self.lines:
                return self.lines[tuple(keys[:n])]
        return None

    def where(self, *keys: Any) -> str:
        """``file:line`` of the field ``keys`` (``file`` alone when no line is known)."""
        line = self.line(*keys)
        return f"{self.path}:{line}" if line is not None else self.path

    def error(self, keys: Iterable[Any], message: str, error: type[FgslamError] = InputFileError) -> FgslamError:
        """``error("file:line: field 'a.b': message")``."""
        keys = tuple(keys)
        return error(f"{self.where(*keys)}: field '{field_name(keys)}' {message}")


def _number_problem(token: str) -> str | None:
    """What no fgslam file holds in a JSON/YAML/TOML number literal, or None."""
    digits = token.lstrip("+-")
    if re.fullmatch(r"[0-9_]+", digits) and len(digits.replace("_", "").lstrip("0")) > MAX_INTEGER_DIGITS:
        return (f"is an integer of {len(digits.replace('_', ''))} digits; no field of this file needs more than "
                f"{MAX_INTEGER_DIGITS} — is the file corrupted?")
    try:
        value = float(token.replace("_", ""))
    except ValueError:
        return None
    if not math.isfinite(value):
        return (f"is {token[:40]}, beyond the largest number a float holds (about 1.8e308); "
                "write a finite number in the field's units")
    return None


_CONSTANT_FIX = "is not a number (NaN and Infinity are not JSON); write a finite number"


class _Found(Exception):
    """Internal: the scan found what it refuses, at ``line`` in field ``keys``."""

    def __init__(self, line: int, keys: tuple, problem: str):
        super().__init__(problem)
        self.line, self.keys, self.problem = line, keys, problem


_JSON_TOKEN = re.compile(
    r'[ \t\r\n]*(?:(?P<string>"(?:[^"\\]|\\.)*")|(?P<number>-?[0-9]+(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?)'
    r"|(?P<punct>[\[\]{}:,])|(?P<word>-?[A-Za-z]+))", re.S)


def _scan_json(text: str) -> dict[tuple, int]:
    """The line of every field of the JSON ``text``; raises :class:`_Found` at nesting
    deeper than :data:`MAX_NESTING`, a number no fgslam file holds or a NaN/Infinity.
    Stops quietly where ``text`` is not JSON (``json.loads`` says where)."""
    lines: dict[tuple, int] = {}
    frames: list[list] = []  # [kind "{" or "[", key or index, expecting a key]
    line, last, pos = 1, 0, 0
    while pos < len(text):
        m = _JSON_TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            break
        start = m.start(m.lastgroup) if m.lastgroup else m.end()
        line += text.count("\n", last, start)
        last, pos = start, m.end()
        keys = tuple(f[1] for f in frames)
        kind, token = m.lastgroup, m.group(m.lastgroup or 0)
        if kind == "punct":
            if token in "[{":
                lines.setdefault(keys, line)
                if len(frames) >= MAX_NESTING:
                    raise _Found(line, keys, f"is nested more than {MAX_NESTING} levels deep (lists and objects "
                                             "inside each other); no fgslam file nests like that — is it corrupted?")
                frames.append([token, 0 if token == "[" else None, token == "{"])
            elif token in "]}" and frames:
                frames.pop()
            elif token == "," and frames:
                frame = frames[-1]
                frame[1] = frame[1] + 1 if frame[0] == "[" else None
                frame[2] = frame[0] == "{"
            continue
        if frames and frames[-1][2]:  # a key
            try:
                frames[-1][1] = json.loads(token)
            except ValueError:
                break
            frames[-1][2] = False
            continue
        lines.setdefault(keys, line)
        problem = (_CONSTANT_FIX if kind == "word" and token.lstrip("-") in ("NaN", "Infinity")
                   else _number_problem(token) if kind == "number" else None)
        if problem:
            raise _Found(line, keys, problem)
    return lines


def _found_error(path: str, found: _Found, error: type[FgslamError], fix: str) -> FgslamError:
    subject = f"field '{field_name(found.keys)}'" if found.keys else "the file"
    return error(f"{path}:{found.line}: {subject} {found.problem}" + (f"; {fix}" if fix else ""))


def parse_json(path: str | os.PathLike[str], text: str, *, error: type[FgslamError] = InputFileError,
               fix: str = "") -> Document:
    """``text`` (the file at ``path``) as JSON with the line of every field; one ``error``
    line ``file:line: ...`` (plus ``fix``) for bad syntax and for what this module refuses."""
    path = os.fspath(path)
    tail = f"; {fix}" if fix else ""

    def refuse(name: str) -> None:
        raise ValueError(name)

    failed = False
    try:
        data = json.loads(text, parse_constant=refuse)
    except json.JSONDecodeError as exc:
        raise error(f"{path}:{exc.lineno}: not valid JSON ({exc.msg} at column {exc.colno}){tail}") from None
    except (RecursionError, ValueError):  # deep nesting, > 4300 digits, NaN: the scan says where
        data, failed = None, True
    try:
        lines = _scan_json(text)
    except _Found as found:
        raise _found_error(path, found, error, fix) from None
    if failed:  # what json refused, the scan did not find: say so without a place
        raise error(f"{path}: not JSON fgslam can read{tail}")
    return Document(path, data, lines)


def parse_yaml(path: str | os.PathLike[str], text: str, *, error: type[FgslamError] = InputFileError,
               fix: str = "", what: str = "YAML") -> Document:
    """``text`` as YAML (safe types only) with the line of every field; one ``error`` line
    ``file:line: ...`` for bad syntax, aliases (``*name``: write the values out) and what
    this module refuses."""
    import yaml

    path = os.fspath(path)
    loader = None
    try:
        loader = _yaml_loader()(text)  # the reader refuses control characters here
        node = loader.get_single_node()
        lines = _yaml_lines(node, loader) if node is not None else {}
        data = loader.construct_document(node) if node is not None else None
    except _Found as found:
        raise _found_error(path, found, error, fix) from None
    except yaml.YAMLError as exc:  # one line: where and what (yaml's own text spans several)
        mark = getattr(exc, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"{path}{line}: not valid {what} ({problem})" + (f"; {fix}" if fix else "")) from None
    finally:
        if loader is not None:
            loader.dispose()
    return Document(path, data, lines)


_YAML_LOADER: type | None = None


def _yaml_loader() -> type:
    """yaml.SafeLoader that refuses aliases and nesting deeper than :data:`MAX_NESTING`."""
    global _YAML_LOADER
    if _YAML_LOADER is None:
        import yaml

        class Loader(yaml.SafeLoader):
            depth = 0

            def compose_node(self, parent, index):
                event = self.peek_event()
                if isinstance(event, yaml.AliasEvent):
                    raise _Found(event.start_mark.line + 1, (), "uses a YAML alias (*name); write the values out "
                                                                "(fgslam's files never need one)")
                self.depth += 1
                try:
                    if self.depth > MAX_NESTING:
                        raise _Found(event.start_mark.line + 1, (), f"is nested more than {MAX_NESTING} levels "
                                                                     "deep; no fgslam file nests like that")
                    return super().compose_node(parent, index)
                finally:
                    self.depth -= 1

        _YAML_LOADER = Loader
    return _YAML_LOADER


def _yaml_lines(root, loader) -> dict[tuple, int]:
    """The line of every field of a composed YAML tree; :class:`_Found` at a number no fgslam
    file holds (a huge integer, ``.inf``, ``.nan``)."""
    import yaml

    lines: dict[tuple, int] = {}
    stack = [((), root)]
    while stack:
        keys, node = stack.pop()
        line = node.start_mark.line + 1
        lines.setdefault(keys, line)
        if isinstance(node, yaml.MappingNode):
            stack.extend((keys + (k.value if isinstance(k, yaml.ScalarNode) else "?",), v) for k, v in node.value)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend((keys + (i,), v) for i, v in enumerate(node.value))
        elif node.tag.endswith((":int", ":float")):
            problem = _number_problem(node.value)
            if problem is None and node.tag.endswith(":float") and not math.isfinite(loader.construct_yaml_float(node)):
                problem = f"is {node.value}, not a finite number; write a finite number in the field's units"
            if problem is None and node.tag.endswith(":int") and len(node.value) > MAX_INTEGER_DIGITS + 3:
                problem = f"is an integer of {len(node.value)} characters; no field of this file needs one"
            if problem:
                raise _Found(line, keys, problem)
    return lines


def parse_toml(path: str | os.PathLike[str], text: str, *, error: type[FgslamError] = InputFileError,
               fix: str = "") -> Document:
    """``text`` as TOML; one ``error`` line ``file:line: ...`` for bad syntax, nesting and
    huge integers (TOML's ``inf`` and ``nan`` are left to the reader's range checks, which
    name the field). The lines of fields are found by their ``key =`` line under their
    ``[table]``."""
    import tomllib

    path = os.fspath(path)
    tail = f"; {fix}" if fix else ""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML ({exc}){tail}") from None
    except (RecursionError, ValueError):  # deep nesting or > 4300 digits: say where
        raise error(f"{path}:{_toml_trouble_line(text)}: nested more than {MAX_NESTING} levels deep or an integer "
                    f"of more than {MAX_INTEGER_DIGITS} digits; no fgslam file holds either{tail}") from None
    doc = Document(path, data, _toml_lines(text))
    stack = [((), data, 0)]
    while stack:
        keys, value, depth = stack.pop()
        problem = None
        if depth > MAX_NESTING:
            problem = f"is nested more than {MAX_NESTING} levels deep; no fgslam file nests like that"
        elif isinstance(value, dict):
            stack.extend((keys + (k,), v, depth + 1) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((keys + (i,), v, depth + 1) for i, v in enumerate(value))
        elif isinstance(value, int) and not isinstance(value, bool) and len(str(abs(value))) > MAX_INTEGER_DIGITS:
            problem = f"is an integer of {len(str(abs(value)))} digits; no field of this file needs one"
        if problem:
            raise doc.error(keys, problem + tail, error)
    return doc


def _toml_lines(text: str) -> dict[tuple, int]:
    """``(table..., key)`` → line for every ``key = value`` line (plain keys), and the line
    of each ``[table]`` header."""
    lines: dict[tuple, int] = {}
    table: tuple = ()
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        header = re.fullmatch(r"\[\[?\s*([A-Za-z0-9_.\-\" ]+?)\s*\]\]?(\s*#.*)?", line)
        if header:
            table = tuple(part.strip().strip('"') for part in header.group(1).split("."))
            lines.setdefault(table, number)
            continue
        key = re.match(r"([A-Za-z0-9_\-\"]+)\s*=", line)
        if key:
            lines.setdefault(table + (key.group(1).strip('"'),), number)
    return lines


def _toml_trouble_line(text: str) -> int:
    """The line of the first run of brackets deeper than :data:`MAX_NESTING` or of digits
    longer than :data:`MAX_INTEGER_DIGITS` (strings are not told apart: a rough pointer)."""
    depth = 0
    for number, line in enumerate(text.splitlines(), start=1):
        if re.search(r"[0-9_]{%d,}" % (MAX_INTEGER_DIGITS + 1), line):
            return number
        for ch in line:
            depth += (ch in "[{") - (ch in "]}")
            if depth > MAX_NESTING:
                return number
    return 1
