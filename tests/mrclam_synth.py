"""A synthetic MRCLAM dataset with a known sensor and motion model (tests/test_noise_fit_truth.py).

:func:`write_dataset` writes ``Barcodes.dat``, ``Landmark_Groundtruth.dat`` and
``RobotN_Odometry.dat``, ``RobotN_Measurement.dat``, ``RobotN_Groundtruth.dat`` in the
published layout (four ``#`` header lines, whitespace-separated columns, Unix times with
millisecond resolution) from a seeded :class:`numpy.random.Generator`, so that the
calibration (``slamio.noise.fit_truth.fit_noise_model``) can be checked against the numbers the
data were made with (:class:`Truth`). Nothing here imports fgslam: the model is written out
independently of ``slamio.noise.model``.

* **Commands** (the odometry file, ~67 Hz with 13-17 ms jitter, as MRCLAM logs them):
  piecewise constant, a new command every 1-3 s at an odometry line: a stop, a straight
  stretch, or a random ``v`` in 0..0.15 m/s with ``w`` in -0.5..0.5 rad/s; a robot that is
  far from the middle of the room turns back towards it.
* **True motion**: the command active at ``t - lag_s`` (zero-order hold over the file's own
  lines; zero before the first line), at ``forward_scale·v`` and
  ``turn_scale·w + turn_per_m_rad·forward_scale·v``, integrated at 1 ms with the midpoint
  rule (exact heading; position error O(dt²)).
* **Vicon truth**: the true pose at 100 Hz, from 0.5 s before the first command to 1 s
  after the last, heading wrapped to (-π, π].
* **Measurements**: a picture every 0.25 ± 0.03 s at time ``t``, stamped
  ``t + camera_latency_s``. Every landmark within ``max_range_m`` and ``±fov_half_rad``
  is read as depth ``range_scale·r·cos b + range_bias_m + N(0, (range_sigma_per_m·r)²)``
  and bearing ``bearing_scale·b + bearing_bias_rad + N(0, bearing_sigma_rad²)``; a share
  ``outlier_rate`` of the readings are gross errors (range off by 0.5-2 m, bearing off by
  0.1-0.3 rad, random signs).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

#: The published barcode of each subject (1-5 robots, 6-20 landmarks; as the fixture).
BARCODES = {1: 5, 2: 14, 3: 41, 4: 32, 5: 23, 6: 72, 7: 27, 8: 54, 9: 70, 10: 36, 11: 18, 12: 25,
            13: 9, 14: 81, 15: 16, 16: 90, 17: 61, 18: 45, 19: 7, 20: 63}
HEADER = [
    "# UTIAS Multi-Robot Cooperative Localization and Mapping Dataset",
    "# synthetic copy for fgslam tests (tests/mrclam_synth.py)",
]
T0 = 1248272272.841
DT_TRUTH = 0.001


@dataclass(frozen=True)
class Truth:
    """The model the data are made with (the numbers the fit should recover)."""

    lag_s: float = 0.2
    forward_scale: float = 0.93
    turn_scale: float = 0.95
    turn_per_m_rad: float = -0.04
    range_is_depth: bool = True
    range_scale: float = 1.03
    range_bias_m: float = 0.02
    range_sigma_per_m: float = 0.01
    bearing_scale: float = 0.99
    bearing_bias_rad: float = -0.002
    bearing_sigma_rad: float = 0.006
    camera_latency_s: float = 0.03
    outlier_rate: float = 0.01
    max_range_m: float = 6.0
    fov_half_rad: float = 0.5


@dataclass
class Run:
    """What :func:`write_dataset` made, for the tests to compare with (file times)."""

    truth_t: np.ndarray  # 1 ms grid, seconds since T0 (file time - T0)
    truth_pose: np.ndarray  # (n, 3), heading unwrapped
    landmarks: dict[int, tuple[float, float]]
    n_readings: int
    n_outliers: int

    def pose_at(self, t_s):
        """True pose (x, y, unwrapped θ) at file time(s) ``t_s`` (linear between 1 ms samples).

        A float gives shape (3,), an array of n times shape (n, 3).
        """
        t = np.asarray(t_s, float) - T0
        return np.stack([np.interp(t, self.truth_t, self.truth_pose[:, j]) for j in range(3)], axis=-1)


def _write(path: str, kind: str, columns: list[str], lines: list[str]) -> None:
    with open(path, "w") as f:
        f.write("\n".join(HEADER + [f"# {kind} Data Format:", "# " + "    ".join(columns)] + lines) + "\n")


def _wrap(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _landmarks(rng: np.random.Generator, n: int) -> dict[int, tuple[float, float]]:
    """``n`` landmarks (subjects 6..) around a 9 m × 7 m room, a few inside."""
    out = {}
    for i in range(n):
        if i < n - 3:  # on the walls, spread around the perimeter
            a = 2 * math.pi * i / (n - 3) + rng.uniform(-0.2, 0.2)
            x, y = 4.5 * math.cos(a), 3.5 * math.sin(a)
        else:  # inside, away from the centre where the robot spends most time
            a = rng.uniform(0, 2 * math.pi)
            x, y = 2.6 * math.cos(a), 2.0 * math.sin(a)
        out[6 + i] = (round(x, 4), round(y, 4))
    return out


def _commands(rng: np.random.Generator, t_odo: np.ndarray, truth: Truth, start: tuple[float, float, float]):
    """Commands at the odometry times and the 1 ms truth, generated together (closed loop)."""
    n = len(t_odo)
    v = np.zeros(n)
    w = np.zeros(n)
    # whole milliseconds from 0.5 s before the first command to 1 s after the last
    grid = (np.arange(int(round(t_odo[-1] / DT_TRUTH)) + 1501) - 500) * DT_TRUTH
    pose = np.zeros((len(grid), 3))
    pose[0] = start
    done = 0  # pose[:done+1] is integrated

    def integrate_to(t_end: float) -> None:
        """Integrate the truth up to grid time t_end with the commands decided so far."""
        nonlocal done
        j_end = min(int(np.searchsorted(grid, t_end + 1e-9)) - 1, len(grid) - 1)
        if j_end <= done:
            return
        tm = grid[done:j_end] + DT_TRUTH / 2 - truth.lag_s  # midpoints, shifted to the command time
        k = np.searchsorted(t_odo, tm, side="right") - 1  # the command active then
        vc = np.where(k >= 0, v[np.clip(k, 0, n - 1)], 0.0)
        wc = np.where(k >= 0, w[np.clip(k, 0, n - 1)], 0.0)
        vt = truth.forward_scale * vc
        wt = truth.turn_scale * wc + truth.turn_per_m_rad * vt
        th0 = pose[done, 2]
        dth = wt * DT_TRUTH
        th_end = th0 + np.cumsum(dth)
        th_mid = th_end - dth / 2
        x = pose[done, 0] + np.cumsum(vt * np.cos(th_mid) * DT_TRUTH)
        y = pose[done, 1] + np.cumsum(vt * np.sin(th_mid) * DT_TRUTH)
        pose[done + 1 : j_end + 1] = np.column_stack([x, y, th_end])
        done = j_end

    i = 0
    while i < n:
        t_seg = float(t_odo[i])
        duration = rng.uniform(1.0, 3.0)
        j = min(int(np.searchsorted(t_odo, t_seg + duration)), n)
        integrate_to(t_seg)  # the commands before i set the truth up to t_seg + lag
        x, y, th = pose[done]
        kind = rng.uniform()
        to_centre = _wrap(math.atan2(-y, -x) - th)
        if math.hypot(x, y) > 2.2 and abs(to_centre) > 0.6:  # turn back into the room
            vc, wc = rng.uniform(0.0, 0.05), math.copysign(rng.uniform(0.3, 0.5), to_centre)
        elif kind < 0.12:
            vc, wc = 0.0, 0.0  # a stop
        elif kind < 0.35:
            vc, wc = rng.uniform(0.05, 0.15), 0.0  # straight
        else:
            vc, wc = rng.uniform(0.0, 0.15), rng.uniform(-0.5, 0.5)
        v[i:j], w[i:j] = round(vc, 6), round(wc, 6)  # the file's precision
        i = j
    integrate_to(float(grid[-1]))
    return v, w, grid, pose


def write_dataset(
    folder: str | os.PathLike[str],
    *,
    seed: int = 0,
    robot: int = 1,
    duration_s: float = 300.0,
    n_landmarks: int = 10,
    truth: Truth = Truth(),
    landmarks: dict[int, tuple[float, float]] | None = None,
) -> Run:
    """Write the five files of robot ``robot`` (and the shared ones) into ``folder``."""
    folder = os.fspath(folder)
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    if landmarks is None:
        landmarks = _landmarks(np.random.default_rng(1000 + seed), n_landmarks)
    _write(os.path.join(folder, "Barcodes.dat"), "Barcode", ["Subject #", "Barcode #"],
           [f"{s}\t{b}" for s, b in BARCODES.items()])
    _write(os.path.join(folder, "Landmark_Groundtruth.dat"), "Landmark Groundtruth",
           ["Subject #", "x [m]", "y [m]", "x std-dev [m]", "y std-dev [m]"],
           [f"{s}\t{x:.6f}\t{y:.6f}\t0.000400\t0.000500" for s, (x, y) in landmarks.items()])

    # odometry times: ~67 Hz with jitter, whole milliseconds. All times here are seconds
    # since T0 (small numbers, exact to ~1e-13 s); T0 is added only when a line is written.
    periods_ms = rng.integers(13, 18, size=int(duration_s / 0.015) + 10)
    t_odo = np.concatenate([[0], np.cumsum(periods_ms)]) / 1000.0
    t_odo = t_odo[t_odo <= duration_s]
    start = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-math.pi, math.pi))
    v, w, grid, pose = _commands(rng, t_odo, truth, start)
    _write(os.path.join(folder, f"Robot{robot}_Odometry.dat"), "Odometry",
           ["Time [s]", "Forward Velocity [m/s]", "Angular Velocity [rad/s]"],
           [f"{T0 + t:.3f}\t{a:.6f}\t{b:.6f}" for t, a, b in zip(t_odo, v, w)])

    # Vicon at 100 Hz (every 10th 1 ms sample; the grid is on whole milliseconds)
    vic = slice(0, len(grid), 10)
    _write(os.path.join(folder, f"Robot{robot}_Groundtruth.dat"), "Groundtruth",
           ["Time [s]", "x [m]", "y [m]", "Orientation [rad]"],
           [f"{T0 + t:.3f}\t{x:.9f}\t{y:.9f}\t{th:.9f}" for t, (x, y, th) in
            zip(grid[vic], np.column_stack([pose[vic, :2], _wrap(pose[vic, 2])]))])

    # measurements: pictures on whole milliseconds, stamped camera_latency_s later
    lm_ids = np.array(list(landmarks))
    lm_xy = np.array([landmarks[i] for i in lm_ids])
    lines = []
    n_readings = n_outliers = 0
    t = float(t_odo[0]) + 0.3
    while t < float(t_odo[-1]) - 0.1:
        j = int(round((t - grid[0]) / DT_TRUTH))
        x, y, th = pose[j]
        dx, dy = lm_xy[:, 0] - x, lm_xy[:, 1] - y
        r = np.hypot(dx, dy)
        b = _wrap(np.arctan2(dy, dx) - th)
        for k in np.flatnonzero((r < truth.max_range_m) & (r > 0.3) & (np.abs(b) < truth.fov_half_rad)):
            depth = truth.range_scale * r[k] * math.cos(b[k]) + truth.range_bias_m
            rm = depth + rng.normal(0.0, truth.range_sigma_per_m * r[k])
            bm = truth.bearing_scale * b[k] + truth.bearing_bias_rad + rng.normal(0.0, truth.bearing_sigma_rad)
            if rng.uniform() < truth.outlier_rate:
                rm = max(0.2, rm + rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 2.0))
                bm = bm + rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 0.3)
                n_outliers += 1
            n_readings += 1
            lines.append((round(t + truth.camera_latency_s, 3), BARCODES[int(lm_ids[k])], rm, bm))
        t = round(t + rng.uniform(0.22, 0.28), 3)
    _write(os.path.join(folder, f"Robot{robot}_Measurement.dat"), "Measurement",
           ["Time [s]", "Subject #", "Range [m]", "Bearing [rad]"],
           [f"{T0 + t:.3f}\t{code}\t{rm:.6f}\t{bm:.6f}" for t, code, rm, bm in lines])
    return Run(grid, pose, dict(landmarks), n_readings, n_outliers)
