"""How the recorder reads the robot: a Create 2 streams checksummed frames
(:class:`StreamReader`), a Create 1 answers a Query List every period (:class:`PollReader`).
Both drop readings that cannot be true (:mod:`slamio.create.safety`) and count them.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Sequence

from slamio.create import protocol
from slamio.create.link import CreateLink
from slamio.create.odometry import CREATE2_MM_PER_COUNT, counts_delta
from slamio.create.safety import implausible_create1_reading, implausible_encoder_jump, implausible_frame
from slamio.create.stream_parser import StreamParser

__all__ = ["POLL_IDS", "STREAM_IDS", "PollReader", "StreamReader"]

STREAM_IDS = (7, 35, 43, 44)  # Create 2: bumps/drops, OI mode, left and right encoder counts
POLL_IDS = (7, 35, 19, 20)  # Create 1: bumps/drops, OI mode, distance, angle


# --------------------------------------------------------------------------- readers


class StreamReader:
    """Create 2: stream frames, checksum, plausibility (reserved bits, mode, encoder jumps)."""

    def __init__(self, link: CreateLink, model: str, ids: Sequence[int] = STREAM_IDS):
        self.link, self.model, self.ids = link, model, list(ids)
        self.parser = StreamParser(self.ids)
        self.implausible = 0
        self._last: tuple[float, int, int] | None = None  # (time, left, right) of the last accepted frame

    def _implausible(self, values: dict[int, int], now_s: float) -> str | None:
        why = implausible_frame(values, self.model)
        if why is None and self._last is not None and 43 in values:
            t, left, right = self._last
            for new, old in ((values[43], left), (values[44], right)):
                why = why or implausible_encoder_jump(counts_delta(new, old), now_s - t, CREATE2_MM_PER_COUNT)
        return why

    def setup(self) -> None:
        self.link.write(protocol.stream(self.ids))

    def poll(self, now_s: float, tap: Callable | None) -> list[dict[int, int]]:
        out = []
        for frame in self.parser.feed(self.link.read()):
            if self._implausible(frame.values, now_s):
                self.implausible += 1
                continue
            if 43 in frame.values:
                self._last = (now_s, frame.values[43], frame.values[44])
            if tap is not None:
                tap(frame)
            out.append(frame.values)
        return out

    def stamp(self, now_s: float) -> float:
        return now_s

    def stats(self) -> dict[str, Any]:
        return {"reader": "stream", "packets": self.ids, **self.parser.stats(), "implausible_frames": self.implausible}


class PollReader:
    """Create 1: a Query List every ``period_s`` (robot time); no checksum in the answer."""

    def __init__(self, link: CreateLink, model: str, period_s: float, ids: Sequence[int] = POLL_IDS):
        self.link, self.model, self.period_s, self.ids = link, model, period_s, list(ids)
        self.size = protocol.query_response_size(self.ids)
        self._next_s: float | None = None
        self._asked_s: float | None = None
        self.answers = 0
        self.lost = 0
        self.implausible = 0

    def setup(self) -> None:
        self.link.discard_input()

    def poll(self, now_s: float, tap: Callable | None) -> list[dict[int, int] | None]:
        """A list with the answer's values, [None] for a lost answer, [] when not due."""
        if self._next_s is not None and now_s < self._next_s:
            time.sleep(0.001)
            return []
        self._next_s = now_s + self.period_s
        elapsed = None if self._asked_s is None else now_s - self._asked_s
        self._asked_s = now_s
        self.link.write(protocol.query_list(self.ids))
        data = self.link.read_exactly(self.size, timeout_s=max(0.05, 2 * self.link.timeout_s))
        if len(data) != self.size:
            self.lost += 1
            self.link.discard_input()
            return [None]
        values = protocol.decode_query_response(self.ids, data)
        why = implausible_frame(values, self.model)
        if why is None and elapsed is not None:
            why = implausible_create1_reading(values[19], values[20], elapsed)
        if why:
            self.implausible += 1
            return [None]
        self.answers += 1
        if tap is not None:
            tap(values)
        return [values]

    def stamp(self, now_s: float) -> float:
        """When the robot took the reading: when it was asked for (it answers at once)."""
        return now_s if self._asked_s is None else self._asked_s

    def stats(self) -> dict[str, Any]:
        return {"reader": "poll", "packets": self.ids, "period_s": self.period_s, "answers": self.answers,
                "lost_answers": self.lost, "implausible_answers": self.implausible}
