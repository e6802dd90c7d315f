"""A bump that does not end the run: the bumper's state, debounced, and the one rule for
driving while it is pressed.

By default a bump ends a recording (:mod:`slamio.create.safety`). A robot that navigates by
itself meets things on purpose or by surprise, and must go on: the wheels stop at once, the
bump is counted and logged, the controller is told, and it may back off or turn away
(:class:`~slamio.create.record_settings.RecorderSettings` ``bump_ends_run=False``).

**What moves away from a bump.** The Create is a disc of radius r. A point of its edge at
angle φ from straight ahead moves with velocity (v − ω·r·sin φ, ω·r·cos φ) in the robot
frame, whose outward (radial) part is ``v·cos φ``: turning never pushes the edge outward,
and for the bumper's points (|φ| < 90°) only a forward centre speed ``v > 0`` does. So while
a bumper is pressed a command is obeyed when its centre speed ``(left + right) / 2`` is not
forward — reversing, turning in place, or both — and any other is replaced by a stop
(:func:`away_from_bumper`).
"""

from __future__ import annotations

from dataclasses import dataclass

from slamio.create.protocol import decode_bumps_and_drops

__all__ = ["BumperState", "BumperWatch", "RELEASED", "away_from_bumper", "bumper_state"]


@dataclass(frozen=True)
class BumperState:
    """Which bumpers are pressed."""

    left: bool = False
    right: bool = False

    @property
    def pressed(self) -> bool:
        return self.left or self.right

    @property
    def side(self) -> str | None:
        """``left``, ``right``, ``both``, or None when neither is pressed (an event's ``side``)."""
        if self.left and self.right:
            return "both"
        return "left" if self.left else ("right" if self.right else None)


RELEASED = BumperState()


def bumper_state(packet7: int) -> BumperState:
    """The bumpers of packet 7's byte (bit 1 left, bit 0 right)."""
    b = decode_bumps_and_drops(packet7)
    return BumperState(b.bump_left, b.bump_right)


def away_from_bumper(wheels_mm_s: tuple[float, float], bumper: BumperState) -> tuple[float, float]:
    """``wheels_mm_s`` (left, right) if they do not drive the robot into what ``bumper`` touches
    (module docstring: a centre speed that is not forward), else a stop (0, 0)."""
    if bumper.pressed and wheels_mm_s[0] + wheels_mm_s[1] > 0.0:
        return (0.0, 0.0)
    return wheels_mm_s


class BumperWatch:
    """The bumper's state, changed only when ``debounce`` readings in a row agree (one damaged
    frame neither presses nor releases it). :meth:`reading` returns the new state when it
    changed, else None; :attr:`presses` counts the changes from released to pressed."""

    def __init__(self, debounce: int = 2):
        self.debounce = max(1, int(debounce))
        self.state = RELEASED
        self.presses = 0
        self._candidate = RELEASED
        self._streak = 0

    def reading(self, packet7: int) -> BumperState | None:
        seen = bumper_state(packet7)
        if seen == self.state:
            self._candidate, self._streak = seen, 0
            return None
        self._streak = self._streak + 1 if seen == self._candidate else 1
        self._candidate = seen
        if self._streak < self.debounce:
            return None
        was_pressed = self.state.pressed
        self.state, self._streak = seen, 0
        if seen.pressed and not was_pressed:
            self.presses += 1
        return seen
