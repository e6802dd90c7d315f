"""slamio.laser: the LaserScan-like scan file and the ray-cast laser."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from slamio.errors import InputFileError
from slamio.laser import laser_scan, read_scan_file
from slamio.obstacles import Obstacles, box_segments


def test_a_scan_file_reads_free_unknown_and_hits(tmp_path):
    path = tmp_path / "scans.jsonl"
    lines = ["# two scans", json.dumps({"t": 0.5, "angle_min": -0.1, "angle_increment": 0.1, "range_min": 0.05,
                                        "range_max": 4.0, "ranges": [1.5, None, 5.0, 0.02]}),
             "", '{"t": 0.6, "angle_min": 0, "angle_increment": 0.1, "range_max": 4.0, "ranges": [Infinity, NaN, 0]}']
    path.write_text("\n".join(lines) + "\n")
    (t0, a), (t1, b) = read_scan_file(path)
    assert (t0, t1) == (0.5, 0.6)
    assert np.allclose(a.angles_rad, [-0.1, 0.0, 0.1, 0.2])
    assert a.ranges_m[0] == 1.5 and np.isnan(a.ranges_m[1]) and np.isposinf(a.ranges_m[2]) and np.isnan(a.ranges_m[3])
    assert a.max_range_m == 4.0 and a.min_range_m == 0.05
    assert np.isposinf(b.ranges_m[0]) and np.isnan(b.ranges_m[1:]).all()


@pytest.mark.parametrize("line, message", [
    ("{not json", "not JSON"),
    ('{"t": 1, "angle_min": 0, "angle_increment": 0.1, "range_max": 4}', "missing ranges"),
    ('{"t": 1, "angle_min": 0, "angle_increment": -0.1, "range_max": 4, "ranges": [1, 2]}', "angle_increment"),
    ('{"t": "x", "angle_min": 0, "angle_increment": 0.1, "range_max": 4, "ranges": [1]}', "'t' must be a finite number"),
    ('{"t": 1, "angle_min": 0, "angle_increment": 0.1, "range_max": 4, "ranges": ["a"]}', "numbers or null"),
    ('[1, 2]', "JSON object"),
])
def test_bad_lines_name_the_file_and_line(tmp_path, line, message):
    path = tmp_path / "bad.jsonl"
    good = '{"t": 0, "angle_min": 0, "angle_increment": 0.1, "range_max": 4, "ranges": [1]}'
    path.write_text(good + "\n" + line + "\n")
    with pytest.raises(InputFileError, match=f"bad.jsonl:2: .*{message}"):
        read_scan_file(path)


def test_the_simulated_laser_sees_a_box_by_hand():
    box = Obstacles(box_segments((2.0, 0.0), (1.0, 1.0)), segment_heights_m=np.full(4, 0.3))
    scan = laser_scan(box, (0.0, 0.0, 0.0))
    assert len(scan.angles_rad) == 683 and scan.field_of_view_rad == pytest.approx(math.radians(240))
    ahead = np.argmin(np.abs(scan.angles_rad))
    assert scan.ranges_m[ahead] == pytest.approx(1.5 / math.cos(scan.angles_rad[ahead]))
    assert np.isposinf(scan.ranges_m[np.abs(scan.angles_rad) > math.atan2(0.5, 1.5) + 0.01]).all()
    assert np.isposinf(laser_scan(box, (0.0, 0.0, 0.0), scan_height_m=0.4).ranges_m).all()  # it looks over the box
