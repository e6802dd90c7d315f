"""Finding the Create's stream frames in a byte stream that may hold garbage, flipped bits
and dropped bytes: :class:`StreamParser` (the frame layout is in :mod:`slamio.create.protocol`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from slamio.create.protocol import (
    STREAM_HEADER,
    ProtocolError,
    decode_frame_payload,
    frame_checksum_ok,
    stream_payload_size,
    valid_packet_id,
)

__all__ = ["MAX_STREAM_PAYLOAD", "StreamFrame", "StreamParser"]


@dataclass(frozen=True)
class StreamFrame:
    """One accepted stream frame: its packets by id, and the raw bytes it came from."""

    values: dict[int, int]
    raw: bytes


#: Largest payload accepted when the packet list is not known (57600 baud carries at most
#: ~86 bytes per 15 ms, so a longer frame could not be streamed anyway).
MAX_STREAM_PAYLOAD = 86


class StreamParser:
    """Finds stream frames in a byte stream that may be damaged; counts what it rejects.

    Feed it bytes as they arrive (any chunking); :meth:`feed` returns the frames completed
    by those bytes. A frame is accepted only when **all** of these hold:

    1. it starts with the header byte 19 and its length byte N is possible (equal to the
       expected payload size when ``expected_ids`` is given, else 2..``max_payload``);
    2. all N + 3 bytes sum to 0 mod 256 (the checksum);
    3. its payload is well formed: known packet ids, each with its full data, no id twice,
       and exactly ``expected_ids`` in order when given.

    When a candidate fails, only its header byte is discarded and the search goes on from
    the next byte, so a real frame that starts inside a damaged one (after garbage, a
    flipped bit or a dropped byte) is still found. Nothing but the header, N and the
    checksum marks a frame, so this is the only way to resynchronise.

    Counters: ``frames_ok``; ``bad_checksum`` and ``bad_layout`` (candidates of a possible
    length that failed 2 or 3; their sum is :attr:`bad_frames`); ``bad_length`` (header
    bytes followed by an impossible N — usually a 19 inside garbage or data after a loss of
    sync); ``bytes_discarded`` (bytes skipped while searching).

    Limits: an 8-bit sum detects every single damaged byte but not every pair (two faults
    in one frame cancel with probability ~1/256), so the caller should still check that
    values are plausible (:func:`slamio.create.safety.implausible_frame`).
    """

    def __init__(self, expected_ids: Sequence[int] | None = None, max_payload: int = MAX_STREAM_PAYLOAD):
        self.expected_ids = None if expected_ids is None else [valid_packet_id(i) for i in expected_ids]
        self.expected_payload = None if expected_ids is None else stream_payload_size(self.expected_ids)
        self.max_payload = max_payload
        self._buffer = bytearray()
        self.frames_ok = 0
        self.bad_checksum = 0
        self.bad_layout = 0
        self.bad_length = 0
        self.bytes_discarded = 0

    @property
    def bad_frames(self) -> int:
        """Candidates of a possible length rejected by the checksum or the layout."""
        return self.bad_checksum + self.bad_layout

    @property
    def pending(self) -> int:
        """Bytes kept for the next :meth:`feed` (a frame not yet complete)."""
        return len(self._buffer)

    def _length_ok(self, n: int) -> bool:
        if self.expected_payload is not None:
            return n == self.expected_payload
        return 2 <= n <= self.max_payload

    def feed(self, data: bytes) -> list[StreamFrame]:
        buf = self._buffer
        buf += data
        frames: list[StreamFrame] = []
        at = 0
        while True:
            start = buf.find(STREAM_HEADER, at)
            if start < 0:
                self.bytes_discarded += len(buf) - at
                at = len(buf)
                break
            self.bytes_discarded += start - at
            at = start
            if len(buf) - at < 2:
                break  # wait for N
            n = buf[at + 1]
            if not self._length_ok(n):
                self.bad_length += 1
                self.bytes_discarded += 1
                at += 1
                continue
            size = n + 3
            if len(buf) - at < size:
                break  # wait for the rest of the frame
            candidate = bytes(buf[at:at + size])
            if not frame_checksum_ok(candidate):
                self.bad_checksum += 1
                self.bytes_discarded += 1
                at += 1
                continue
            try:
                values = decode_frame_payload(candidate[2:-1], self.expected_ids)
            except ProtocolError:
                self.bad_layout += 1
                self.bytes_discarded += 1
                at += 1
                continue
            frames.append(StreamFrame(values, candidate))
            self.frames_ok += 1
            at += size
        del buf[:at]
        return frames

    def stats(self) -> dict[str, int]:
        return {
            "frames_ok": self.frames_ok,
            "bad_frames": self.bad_frames,
            "bad_checksum": self.bad_checksum,
            "bad_layout": self.bad_layout,
            "bad_length": self.bad_length,
            "bytes_discarded": self.bytes_discarded,
        }
