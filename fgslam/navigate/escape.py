"""Leaving a spot forward: turn toward floor the grid shows free, look, then drive out.

A navigator that has stayed too long on one spot (goals given up one after another, two
ways that each close when looked at, or no way open at all) must leave it. Reversing does
that blind: the Create has neither camera nor bumper behind, and a reverse into a corner
or a thin cylinder, followed by a turn, carries the contact onto the bumper (the live bump
of docs/navigate.md, room 3). Reversing only over floor known free
(:func:`fgslam.navigate.vfh.known_free_behind_m`) is safe but often does not move the robot
at all (the floor behind was never looked at), and the robot stays.

So :class:`ForwardEscape` leaves forward, by ``vfh``'s own rules. From the histogram at the
robot (:meth:`fgslam.navigate.vfh.Vfh.histogram`: per sector how far the disc enlarged to
robot + half a cell's diagonal + margin goes before an occupied cell, and whether that
corridor was seen) it takes the sector needing the least turn whose free distance, and
that of its neighbour either side (the heading is never exact), reaches the way out plus
the stopping distance, all of them seen (:func:`escape_heading_rad`); failing that, the
roomiest such sector with at least ``least_m`` to drive. A disc turning on the spot sweeps
nothing new, so it turns there; then it waits for a scan taken facing the new heading (the
camera looks where the robot will go, also at what the grid had not shown), checks the
sector again, and drives out ``distance_m`` at ``speed_m_s`` under ``vfh``'s stop rules
(:meth:`~fgslam.navigate.vfh.Vfh.must_stop`: the corridor ahead and the arc, remembered
cells too), ending early where they stop it. With no such sector :meth:`ForwardEscape.start`
returns False and the owner falls back to reversing over known floor.
"""

from __future__ import annotations

import math

import numpy as np

from fgslam.navigate.common import Command, Situation, heading_error_rad, limited_command, turn_towards
from slamio.geometry import wrap_angle

__all__ = ["escape_heading_rad", "ForwardEscape"]


def _worst_of_neighbours(values, spread: int) -> np.ndarray:
    """Per (circular) sector, the least of its value and its ``spread`` neighbours' either side."""
    values = np.asarray(values, dtype=float)
    worst = values.copy()
    for k in range(1, spread + 1):
        worst = np.minimum(worst, np.minimum(np.roll(values, k), np.roll(values, -k)))
    return worst


def escape_heading_rad(free_m, known, headings_rad, heading_rad: float, need_m: float,
                       spread: int = 1) -> float | None:
    """Of the (equally spaced, circular) sectors ``headings_rad`` whose free distance
    ``free_m``, and that of their ``spread`` neighbours either side, reaches ``need_m``, all
    of them ``known``, the heading needing the least turn from ``heading_rad``; ``None``
    when there is none."""
    room = _worst_of_neighbours(np.where(np.asarray(known, bool), free_m, -np.inf), spread)
    ok = room >= need_m
    if not ok.any():
        return None
    headings = np.asarray(headings_rad, dtype=float)
    turn = np.abs(wrap_angle(headings - heading_rad))
    return float(headings[ok][int(np.argmin(turn[ok]))])


class ForwardEscape:
    """Turn toward floor the grid shows free, look, drive out (module docstring). ``vfh``:
    the :class:`~fgslam.navigate.vfh.Vfh` whose grid, histogram and stop rules it uses.
    :meth:`start` arms it; while :attr:`active` the owner returns :meth:`step`'s command."""

    def __init__(self, vfh, *, distance_m: float = 0.35, least_m: float = 0.15, speed_m_s: float = 0.15,
                 spread: int = 1, look_tolerance_rad: float = math.radians(10)):
        self.vfh = vfh
        self.distance_m, self.least_m, self.speed_m_s, self.spread = distance_m, least_m, speed_m_s, spread
        self.look_tolerance_rad = look_tolerance_rad
        self.stopping_m = 0.08 + speed_m_s**2 / (2 * 0.5) + speed_m_s * 0.2  # as vfh's stop rules
        self.active = False
        self.heading_rad: float | None = None
        self._phase = "turn"
        self._start_xy = (0.0, 0.0)
        self._drive_m = 0.0
        self._deadline_s = 0.0
        self._turned_scan = None  # the newest scan when the turn ended: the look waits for a newer one
        self._looks = 0  # headings given up after looking

    def choose(self, pose) -> tuple[float, float] | None:
        """(heading, how far to drive) out of the spot at ``pose``, or ``None`` (module docstring)."""
        free, _, known = self.vfh.histogram(pose)
        angles = self.vfh.sector_angles
        heading = escape_heading_rad(free, known, angles, pose[2], self.distance_m + self.stopping_m, self.spread)
        if heading is not None:
            return heading, self.distance_m
        room = _worst_of_neighbours(np.where(known, free, -np.inf), self.spread)
        best = int(np.argmax(room))
        if room[best] >= self.least_m + self.stopping_m:
            return float(angles[best]), float(room[best]) - self.stopping_m
        return None

    def start(self, situation: Situation) -> bool:
        """Choose the way out; True (and active) when there is one."""
        way = self.choose(situation.pose)
        self.active = way is not None
        if way is None:
            return False
        self.heading_rad, self._drive_m = way
        self._phase, self._turned_scan, self._looks = "turn", None, 0
        turn_s = abs(heading_error_rad(situation.pose, self.heading_rad)) / 0.8
        self._deadline_s = situation.now_s + turn_s + 2.0 + self._drive_m / self.speed_m_s + 2.0
        return True

    def cancel(self) -> None:
        self.active = False

    def _end(self, state: str = "escape") -> Command:
        self.active = False
        return limited_command(0.0, 0.0, state)

    def step(self, situation: Situation, reuse: bool = False) -> Command:
        """The escape's command (``reuse``: the histogram of the previous step, as ``vfh.steer``)."""
        pose = situation.pose
        if situation.now_s > self._deadline_s:
            return self._end()
        error = heading_error_rad(pose, self.heading_rad)
        if self._phase == "turn":
            if abs(error) > math.radians(6):
                return limited_command(0.0, turn_towards(error, 3.0), "escape-turn")
            self._phase, self._turned_scan = "look", situation.scan
        if self._phase == "look":
            newer = situation.scan is not None and situation.scan is not self._turned_scan
            if not (newer and abs(heading_error_rad(situation.scan_pose, self.heading_rad)) < self.look_tolerance_rad):
                return limited_command(0.0, turn_towards(error, 3.0), "escape-look")
            way = self.choose(pose)  # with what the camera saw facing the way out
            if way is None or self._looks >= 2:
                return self._end()
            if abs(wrap_angle(way[0] - self.heading_rad)) > self.look_tolerance_rad:  # not that way: the next
                self._looks += 1
                self.heading_rad, self._phase = way[0], "turn"
                self._deadline_s = situation.now_s + abs(wrap_angle(way[0] - pose[2])) / 0.8 + 2.0 + way[1] / self.speed_m_s + 2.0
                return limited_command(0.0, 0.0, "escape-look")
            self._phase, self._drive_m, self._start_xy = "drive", way[1], (pose[0], pose[1])
        gone = math.hypot(pose[0] - self._start_xy[0], pose[1] - self._start_xy[1])
        turn = turn_towards(error)
        self.vfh.histogram(pose, reuse)
        if gone >= self._drive_m or self.vfh.must_stop(pose, self.speed_m_s, turn):
            return self._end()
        return limited_command(self.speed_m_s, turn, "escape-drive")
