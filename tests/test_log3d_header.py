"""A 3-D log's header is checked without numpy (``fgslam validate`` starts without it): the
numpy-free checks must decide as the numpy ones do. ``top_view`` gives the same bits as the
rotation matrix it reads; ``check_stereo_sensor`` accepts and refuses (with the same message)
exactly what ``parse_stereo_sensor`` does, around every tolerance of its rigid-transform check."""

from __future__ import annotations

import copy
import math
import random

import numpy as np

from slamio.log import pose3_matrix, stereo_sensor, top_view
from slamio.log import records3d as log3d
from slamio.se3 import exp_so3


def test_top_view_is_the_matrix_yaw_to_the_bit():
    rng = random.Random(3)
    for _ in range(20000):
        q = [rng.gauss(0.0, 1.0) for _ in range(4)]
        n = math.sqrt(sum(v * v for v in q)) * (1.0 + rng.uniform(-1e-7, 1e-7))  # unit within the reader's tolerance
        pose = (rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-5, 5), *(v / n for v in q))
        R = pose3_matrix(pose)[:3, :3]
        expected = (float(pose[0]), float(pose[1]), math.atan2(R[1, 0], R[0, 0]))
        assert top_view(pose) == expected and math.copysign(1.0, top_view(pose)[2]) == math.copysign(1.0, expected[2])


def _outcome(check, sensor) -> str | None:
    try:
        check(sensor)
    except log3d._Bad as bad:
        return str(bad)
    return None


def _mutated(rng: random.Random, sensor: dict) -> dict:
    s = copy.deepcopy(sensor)
    T = s["cam_T_imu"]
    kind = rng.randrange(9)
    scale = rng.choice([1e-10, 4e-10, 6e-10, 1e-9, 2e-9, 2e-7, 4e-7, 6e-7, 1e-6, 5e-6, 1.05e-5, 1.2e-5, 1e-3])
    if kind == 0:  # the rotation stretched
        for i in range(3):
            for j in range(3):
                T[i][j] *= 1.0 + rng.choice([-1, 1]) * scale
    elif kind == 1:  # one entry of the rotation nudged
        T[rng.randrange(3)][rng.randrange(3)] += rng.choice([-1, 1]) * scale
    elif kind == 2:  # the last row nudged
        T[3][rng.randrange(4)] += rng.choice([-1, 1]) * scale
    elif kind == 3:  # a reflection
        T[0][:3] = [-v for v in T[0][:3]]
    elif kind == 4:  # a translation near or beyond the bound
        T[rng.randrange(3)][3] = rng.choice([-1, 1]) * log3d.MAX_MOUNT_M * rng.choice([0.5, 1.0, 1.0000001, 2.0])
    elif kind == 5:  # an intrinsic near or beyond its bound, or not positive
        key = rng.choice(["fx_px", "fy_px", "cx_px", "cy_px", "baseline_m"])
        limit = log3d.MAX_MOUNT_M if key == "baseline_m" else log3d.MAX_PIXEL_PX
        s[key] = rng.choice([-1.0, 0.0, 1.0, limit, limit * 1.0000001, -limit])
    elif kind == 6:  # a value that is no number, or a key missing
        key = rng.choice(list(log3d._STEREO_KEYS))
        if rng.random() < 0.5:
            del s[key]
        else:
            s[key] = rng.choice([None, "1", True, [1, 2], float("nan")])
    elif kind == 7:  # a wrong shape
        s["cam_T_imu"] = rng.choice([T[:3], [row[:3] for row in T], T + [[0, 0, 0, 1]], 1.0])
    else:
        s["kind"] = rng.choice(["mono", None, "stereo"])
    return s


def test_the_numpy_free_header_check_decides_as_the_numpy_one():
    rng = random.Random(43)
    accepted = refused = without_numpy = 0
    for _ in range(6000):
        R = exp_so3(np.array([rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1)]))
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, [rng.uniform(-1, 1) for _ in range(3)]
        K = np.array([[rng.uniform(100, 900), 0.0, rng.uniform(0, 700)], [0.0, rng.uniform(100, 900), rng.uniform(0, 400)],
                      [0.0, 0.0, 1.0]])
        sensor = stereo_sensor(K, rng.uniform(0.05, 1.0), T)
        if rng.random() < 0.8:
            sensor = _mutated(rng, sensor)
        expected = _outcome(log3d.parse_stereo_sensor, sensor)
        assert _outcome(log3d.check_stereo_sensor, sensor) == expected, sensor
        accepted += expected is None
        refused += expected is not None
        without_numpy += log3d._clearly_stereo(sensor)
    assert accepted > 1000 and refused > 1000 and without_numpy > 1000
