"""The reader splits a log into lines a buffer at a time (slamio.log.read._raw_lines); it must give
the lines, the line that is too long and the bytes read past a limit exactly as reading one line
at a time does (the reference below: ``readline`` with the line limit), wherever the buffers end."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from slamio.errors import InputFileError
from slamio.log import LogFormatError, iter_log, read_log
from slamio.log import read as reader

ROOT = Path(__file__).resolve().parent.parent


def by_readline(path, limit: int | None, max_line: int) -> tuple[list[tuple[bytes, bool]], object]:
    """(lines without their newline, whether one ended them), then the error: the reference."""
    lines: list[tuple[bytes, bool]] = []
    total = 0
    with open(path, "rb") as f:
        while True:
            raw = f.readline(max_line + 1)
            if not raw:
                return lines, None
            total += len(raw)
            if limit is not None and total > limit:
                return lines, "too large"
            if len(raw) > max_line:
                return lines, ("too long", len(lines) + 1)
            lines.append((raw[:-1], True) if raw.endswith(b"\n") else (raw, False))


def by_buffers(path, limit: int | None, chunk_bytes: int) -> tuple[list[tuple[bytes, bool]], object]:
    lines: list[tuple[bytes, bool]] = []
    try:
        for chunk, ended in reader._raw_lines(str(path), limit, chunk_bytes):
            assert chunk
            lines.extend((line, ended) for line in chunk)
    except LogFormatError as error:
        assert "the line is longer than" in str(error)
        return lines, ("too long", error.line)
    except InputFileError as error:
        assert "more than" in str(error)
        return lines, "too large"
    return lines, None


def test_lines_are_split_as_one_line_at_a_time_wherever_the_buffers_end(tmp_path, monkeypatch):
    rng = random.Random(43)
    path = tmp_path / "lines"
    for _ in range(1500):
        max_line = rng.choice([5, 8, 20, 1000])
        monkeypatch.setattr(reader, "MAX_LINE_BYTES", max_line)
        parts = [bytes(rng.choice(b"ab\r{") for _ in range(rng.randrange(12))) for _ in range(rng.randrange(12))]
        data = b"\n".join(parts) + (b"\n" if rng.random() < 0.5 else b"")
        path.write_bytes(data)
        for chunk_bytes in (1, 2, 3, 7, 64):
            assert by_buffers(path, None, chunk_bytes) == by_readline(path, None, max_line), (data, chunk_bytes)


def test_a_log_that_grows_while_read_stops_at_the_limit_after_the_lines_within_it(tmp_path):
    path = tmp_path / "growing"
    for more, chunk_bytes in ((b"cc\n", 1), (b"c", 1), (b"cc\n", 4), (b"c\n", 64)):
        path.write_bytes(b"aa\nbb\n")
        lines = reader._raw_lines(str(path), 6, chunk_bytes)
        got = [next(lines)]
        with open(path, "ab") as f:
            f.write(more)
        with pytest.raises(InputFileError, match="more than 6 bytes"):
            got.extend(lines)
        assert [line for chunk, _ in got for line in chunk] == [b"aa", b"bb"]


def test_a_line_longer_than_the_limit_is_refused_at_its_number(tmp_path):
    with open(ROOT / "data" / "arena_octagon.jsonl", "rb") as f:
        header, record, other = f.readline(), f.readline(), f.readline()
    path = tmp_path / "long.jsonl"
    path.write_bytes(header + record + b" " * reader.MAX_LINE_BYTES + b"\n")  # with its newline: a byte too many
    with pytest.raises(LogFormatError, match="longer than 16 MiB") as error:
        list(iter_log(path))
    assert error.value.line == 3
    path.write_bytes(header + record + b" " * (reader.MAX_LINE_BYTES - len(other)) + other)  # just within
    assert len(read_log(path).records) == 2


def test_a_stream_closed_after_its_header_yields_nothing():
    stream = iter_log(ROOT / "data" / "arena_octagon.jsonl")  # its first buffer holds every line
    stream.close()
    assert list(stream) == []
