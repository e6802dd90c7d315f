"""explore's forward escape (fgslam/navigate/escape.py): leaving a spot by turning toward a
sector the grid shows free, looking, and driving out forward — not reversing blind (issue
44: the live bump of docs/navigate.md, a reverse toward a thin cylinder, then a turn)."""

import math

import numpy as np
import pytest

from fgslam.navigate.common import Situation
from fgslam.navigate.escape import ForwardEscape, escape_heading_rad
from fgslam.navigate.explore import Explore
from fgslam.navigate.vfh import Vfh, sector_angles_rad
from slamio.geometry import wrap_angle
from slamio.scan import Scan

WALL_X_M = 0.35  # the wall's cells: centres at x = 0.35 (cells 0.3…0.4), y from −1.45 to 1.45


def _walled_vfh() -> Vfh:
    """The robot at the origin facing +x, 0.13 m from a wall (its cells' near edge at 0.3 m);
    every other cell within 2 m seen free."""
    nav = Vfh(seed=0)
    xs, ys = np.meshgrid(np.arange(-1.95, 2.0, 0.1), np.arange(-1.95, 2.0, 0.1))
    nav.grid.mark_occupied(np.column_stack([xs.ravel(), ys.ravel()]), -1.0)
    wall = np.column_stack([np.full(30, WALL_X_M), np.arange(-1.45, 1.5, 0.1)])
    nav.grid.mark_occupied(wall, 2.0 + 1.0)  # −1 + 3: occupied
    nav.escape = ForwardEscape(nav)
    return nav


def _reference_free_m(cells, heading_rad, radius_m, most_m, step_m=0.001) -> float:
    """Brute force: the disc's centre every millimetre along the heading; the first point
    where it is within ``radius_m`` of a cell centre it is nearing (the last point before)."""
    d = np.arange(step_m, most_m + 1e-12, step_m)
    centre = np.column_stack([d * math.cos(heading_rad), d * math.sin(heading_rad)])
    gap = np.hypot(centre[:, None, 0] - cells[None, :, 0], centre[:, None, 1] - cells[None, :, 1])
    nearing = gap < np.hypot(cells[:, 0], cells[:, 1])[None, :]
    hit = ((gap < radius_m) & nearing).any(axis=1)
    return float(d[np.argmax(hit)] - step_m) if hit.any() else most_m


def test_escape_heading_is_the_least_turn_among_seen_sectors_roomy_with_their_neighbours():
    headings = sector_angles_rad(8)  # −157.5°, −112.5°, … 157.5°
    free = np.array([1.0, 1.0, 1.0, 1.0, 0.1, 1.0, 0.1, 1.0])
    known = np.ones(8, bool)
    # roomy with both neighbours: 0, 1, 2 (−157.5°, −112.5°, −67.5°); sector 5 (67.5°) is roomy,
    # the least turn from 0.3 rad, but its neighbours are not
    assert escape_heading_rad(free, known, headings, 0.3, 0.5) == pytest.approx(headings[2])
    assert escape_heading_rad(free, known, headings, 3.0, 0.5) == pytest.approx(headings[0])
    known[2] = False  # never seen: neither it nor its neighbours qualify; 0 is left
    assert escape_heading_rad(free, known, headings, 0.3, 0.5) == pytest.approx(headings[0])
    assert escape_heading_rad(free, known, headings, 0.0, 1.5) is None


def test_facing_a_wall_it_turns_to_the_first_sector_along_it_that_has_room():
    nav = _walled_vfh()
    pose = (0.0, 0.0, 0.1)
    heading, drive_m = nav.escape.choose(pose)
    # reference: per 5° sector the brute-force room of the enlarged disc; the sector needing
    # the least turn with it and its neighbours above the way out plus the stopping distance
    cells = np.column_stack([np.full(30, WALL_X_M), np.arange(-1.45, 1.5, 0.1)])
    angles = nav.sector_angles
    room = np.array([_reference_free_m(cells, a, nav.enlarge_m, nav.d_max_m) for a in angles])
    need = nav.escape.distance_m + nav.escape.stopping_m
    good = (room >= need) & (np.roll(room, 1) >= need) & (np.roll(room, -1) >= need)
    expected = angles[good][np.argmin(np.abs(wrap_angle(angles[good] - pose[2])))]
    assert heading == pytest.approx(expected, abs=1e-9)
    assert math.degrees(heading) == pytest.approx(87.5)  # along the wall, the side it was turned to
    assert drive_m == pytest.approx(nav.escape.distance_m)


def test_the_escape_turns_on_the_spot_looks_then_drives_out_forward():
    nav = _walled_vfh()
    scan = Scan(np.linspace(-0.36, 0.36, 5), np.full(5, np.inf), 4.0)
    assert nav.escape.start(Situation(10.0, (0.0, 0.0, 0.1), scan, (0.0, 0.0, 0.1)))
    target = nav.escape.heading_rad
    turning = nav.escape.step(Situation(10.05, (0.0, 0.0, 0.1), scan, (0.0, 0.0, 0.1)))
    assert turning.state == "escape-turn" and turning.speed_m_s == 0 and turning.turn_rate_rad_s > 0
    # facing the way out: no driving on the old scan (taken facing the wall), wait for a new one
    facing = (0.0, 0.0, target)
    assert nav.escape.step(Situation(12.0, facing, scan, (0.0, 0.0, 0.1))).speed_m_s == 0
    new_scan = Scan(np.linspace(-0.36, 0.36, 5), np.full(5, np.inf), 4.0)
    command = nav.escape.step(Situation(12.4, facing, new_scan, facing))
    assert command.state == "escape-drive" and command.speed_m_s > 0
    # out by the way's length: done
    out = (0.0, nav.escape.distance_m + 0.01, target)
    assert nav.escape.step(Situation(15.0, out, new_scan, facing)).speed_m_s == 0
    assert not nav.escape.active


def test_with_nothing_seen_around_it_only_turns_away_never_reversing_blind():
    nav = Explore(seed=0)
    situation = Situation(10.0, (1.0, 1.0, 0.0), None, None)
    assert not nav.vfh.escape.start(situation)
    nav.vfh.leave_spot(situation)  # the fallback: back off over floor known free (none), turn away
    command = nav.vfh.backoff.step(situation)
    assert command.speed_m_s == 0 and command.state == "turn-away"
