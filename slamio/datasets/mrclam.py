"""UTIAS MRCLAM (Leung et al. 2011) → run-log records, one robot at a time.

The dataset
-----------
The UTIAS Multi-Robot Cooperative Localization and Mapping dataset (Autonomous Space
Robotics Lab, University of Toronto; web page "UTIAS Multi-Robot Cooperative Localization
and Mapping Dataset", http://asrl.utias.utoronto.ca/datasets/mrclam/) has nine folders
``MRCLAM_Dataset1`` … ``MRCLAM_Dataset9``. In each, five iRobot Creates (subjects 1–5) drive
to random waypoints in a 15 m × 8 m room with 15 cylindrical landmarks (subjects 6–20),
each wrapped in a barcode. A monocular camera on every robot, aligned with the robot's body
frame, reads the barcodes and reports range and bearing; a Vicon system gives the ground
truth of every robot and landmark.

The files (plain text, whitespace-separated columns, every file starting with four ``#``
comment lines, times in seconds of Unix time with millisecond resolution)::

    Barcodes.dat               Subject #   Barcode #
    Landmark_Groundtruth.dat   Subject #   x [m]   y [m]   x std-dev [m]   y std-dev [m]
    RobotN_Odometry.dat        Time [s]    Forward Velocity [m/s]   Angular Velocity [rad/s]
    RobotN_Measurement.dat     Time [s]    Subject #   Range [m]   Bearing [rad]
    RobotN_Groundtruth.dat     Time [s]    x [m]   y [m]   Orientation [rad]

The second column of ``RobotN_Measurement.dat`` is headed "Subject #" but holds the
*barcode* number that was read: ``Barcodes.dat`` turns it into a subject. The odometry is
the *commanded* forward and angular velocity (logged at ~67 Hz), not wheel-encoder
readings: what the robot was told to do, which it does only roughly.

The conversion
--------------
* **Landmark ids.** A barcode is looked up in ``Barcodes.dat``; the landmark id is the
  subject number (6–20), the same number ``Landmark_Groundtruth.dat`` uses. Sightings of
  other robots (subjects 1–5) are dropped, and so are barcodes ``Barcodes.dat`` does not
  list; both are counted in ``header.source["dropped"]``.
* **Time.** The run starts at the later of the first odometry time and the first ground
  truth time (so the start pose can be read from the ground truth), and ends at the last
  odometry time (``max_duration_s`` cuts it shorter). Stamps in the log are seconds since
  that start, rounded to the microsecond; ``header.source["time_origin_s"]`` keeps the
  file time of stamp 0. Measurements outside the run are dropped and counted.
* **Poses.** Pose 0 is the ground-truth pose at the start (prior σ = 1e-3), which puts the
  log's world frame in the Vicon frame, so ``fgslam run`` compares against the ground truth
  directly. A new pose (an ``odometry`` record) starts at every distinct measurement time,
  so each observation belongs to the pose at its own time (the log's rule: observations
  belong to the latest odometry record). When no measurement arrives for a while, poses are
  added at equal spacing so that no two consecutive poses are more than ``max_step_s``
  apart (``None``: only measurement times).
* **Odometry.** Zero commands held for less than 60 ms between moving commands are
  logging artefacts the robot never executed and are replaced by the command before them
  (:func:`fill_zero_blips`; counted in ``header.source["zero_command_blips_filled"]``).
  Each command ``(v, ω)`` holds from its time to the next command's time
  (zero-order hold), so over a stretch ``dt`` the robot drives a circular arc
  ``arc_increment(v·dt, ω·dt)``. The arcs between two pose times are composed into the
  SE(2) increment of the ``odometry`` record; ``distance_m = Σ v·dt`` and
  ``angle_rad = Σ ω·dt`` keep the commanded travel (the seed variants that read the
  Create's distance/angle use it). ``dtheta_rad`` is the unwrapped sum of the turns.
* **Odometry noise** (:class:`CommandOdometryNoise`). Every stretch between two commands
  adds independent errors along the robot's forward axis, sideways and in heading, in the
  frame at the start of the stretch, with variances

      σ²_forward = a_f·|Δs| + q_f·dt,   σ²_sideways = a_l·|Δs| + q_l·dt,
      σ²_heading = a_θ·|Δθ| + a_θs·|Δs| + q_θ·dt,

  (``Δs = v·dt``, ``Δθ = ω·dt``) and are propagated to first order through the composition
  (the Jacobians of ``compose_pose``). Variance proportional to distance and angle keeps
  the result independent of the command rate; the ``q·dt`` terms make the covariance
  positive definite even when the robot stands still (the command is zero but the robot
  might still creep). The default numbers are round values, **not fitted** to the data.
* **Observations.** Range and bearing as in the file (bearing counter-clockwise from the
  robot's x axis, the log's convention), with constant ``sigma_range_m`` and
  ``sigma_bearing_rad`` (options; defaults 0.1 m and 0.05 rad, round values, not fitted).
  A sighting with a non-positive range cannot be logged and is dropped and counted, and
  so is a reading equal to the digit to the previous one of the same barcode while the
  robot moved (the camera re-reporting a stale reading; ``stale_repeats``).
  Measurements need not be in time order (they are sorted; sightings at the same time keep
  their file order); odometry and ground truth must be, or the first line out of order is
  reported.
* **Ground truth.** A ``truth_pose`` at every pose, linearly interpolated between the two
  ground-truth samples around the pose time (heading along the shorter arc). Where those
  samples are more than ``max_truth_gap_s`` apart (Vicon lost the robot) or the pose lies
  outside the ground truth, no ``truth_pose`` is written (counted). One
  ``truth_landmark`` per line of ``Landmark_Groundtruth.dat``; its std-devs go to
  ``header.source["landmark_truth_std_m"]``.

Every line of every file is validated: a bad one raises :class:`DatasetFormatError` naming
``file:line``, what is wrong and the expected layout. Every value is also checked against a
physical limit as it is read (``_LIMITS``: |forward velocity| ≤ 2 m/s, |angular velocity|
≤ 10 rad/s, range ≤ 20 m, |bearing| ≤ π, positions within 20 m of the Vicon origin,
|orientation| ≤ π): a value beyond one is a corrupted or hand-edited line, not a reading, and
stops the import with the file, line, value and limit, as a malformed line does.
"""

from __future__ import annotations

import bisect
import hashlib
import math
import os
from dataclasses import asdict

import numpy as np

from slamio.datasets.victoria_park import DatasetFormatError
from slamio.errors import FgslamError, InputFileError
from slamio.geometry import wrap_angle
from slamio.noise_model import NoiseModel, NoiseModelError, OdometryNoiseRates, correct_observation
from slamio.log import Header, Observation, Odometry, Record, TruthLandmark, TruthPose, as_matrix3
from slamio.log.fields import MAX_ID, STAMP_S
from slamio.log.read import MAX_LOG_BYTES
from slamio.safe_input import read_bytes, shown

__all__ = [
    "CommandOdometryNoise",
    "DEFAULT_MAX_STEP_S",
    "DEFAULT_MAX_TRUTH_GAP_S",
    "DEFAULT_SIGMA_BEARING_RAD",
    "DEFAULT_SIGMA_RANGE_M",
    "LANDMARK_SUBJECTS",
    "MRCLAM_URL",
    "ROBOT_SUBJECTS",
    "START_SIGMA",
    "import_mrclam",
    "integrate_commands",
    "interpolate_pose",
    "pose_times",
]

#: The dataset's web page (where users download MRCLAM_Dataset1..9).
MRCLAM_URL = "http://asrl.utias.utoronto.ca/datasets/mrclam/"
#: Subjects that are robots; 6–20 are landmarks.
ROBOT_SUBJECTS = (1, 2, 3, 4, 5)
LANDMARK_SUBJECTS = tuple(range(6, 21))
#: Prior sigmas (m, m, rad) on pose 0, which is read from the ground truth.
START_SIGMA = (1e-3, 1e-3, 1e-3)
DEFAULT_SIGMA_RANGE_M = 0.1
DEFAULT_SIGMA_BEARING_RAD = 0.05
DEFAULT_MAX_STEP_S = 0.5
DEFAULT_MAX_TRUTH_GAP_S = 0.5
#: Zero commands held shorter than this are logging artefacts (:func:`fill_zero_blips`).
MAX_ZERO_BLIP_S = 0.06

# Column layouts, as the files' own fourth header line names them.
_LAYOUT = {
    "barcodes": ("Subject #", "Barcode #"),
    "landmarks": ("Subject #", "x [m]", "y [m]", "x std-dev [m]", "y std-dev [m]"),
    "odometry": ("Time [s]", "Forward Velocity [m/s]", "Angular Velocity [rad/s]"),
    "measurement": ("Time [s]", "Subject #", "Range [m]", "Bearing [rad]"),
    "groundtruth": ("Time [s]", "x [m]", "y [m]", "Orientation [rad]"),
}

# Physical limits of the values, checked on every data line as it is read (_read_table):
# kind -> {column index: (low, high, the limit in words, why it is the limit, a likely slip)}.
# The robots are iRobot Creates in a 15 m x 8 m room. The limits are generous, so that no
# real reading comes near them (Dataset 6, all five robots: |v| <= 0.086 m/s, |w| <= 0.57
# rad/s, ranges 0.94-8.6 m, |bearing| <= 0.6 rad, positions within 6 m of the origin); a
# value beyond one is a corrupted or hand-edited line (a unit slip, a swapped column), and
# importing it would only make `fgslam run` fail later on a line of the log, or, for the
# odometry and ground truth that the log reader cannot judge, pass silently.
# The range has no lower limit here: a non-positive range stays dropped and counted
# (dropped.non_positive_range, _kept_readings), as before.
_ROOM_M = 20.0  # the room's diagonal is 17 m: no point in it is farther from the Vicon origin
_ROOM_WHY = ("the robots and landmarks are in a 15 m x 8 m room (17 m corner to corner) around "
             "the Vicon origin")
_LIMITS: dict[str, dict[int, tuple[float, float, str, str, str]]] = {
    "odometry": {
        # the Create's top speed is 0.5 m/s; 2 m/s is four times that
        1: (-2.0, 2.0, "|v| <= 2 m/s", "an iRobot Create's top speed is 0.5 m/s", "mm/s written as m/s?"),
        # turning on the spot at top wheel speed: 2 x 0.5 m/s / 0.26 m wheel base = 3.8 rad/s
        2: (-10.0, 10.0, "|w| <= 10 rad/s",
            "an iRobot Create turning on the spot at top speed (0.5 m/s per wheel, 0.26 m apart) turns at 3.8 rad/s",
            "degrees/s written as rad/s?"),
    },
    "measurement": {
        # the camera reads barcodes out to ~9 m, and the room is 17 m corner to corner
        2: (-math.inf, _ROOM_M, "range <= 20 m", _ROOM_WHY + ", and the camera reads barcodes out to about 9 m",
            "mm or cm written as m?"),
        # an angle within half a turn either way: the log refuses any other bearing
        3: (-math.pi, math.pi, "|bearing| <= pi",
            "a bearing is an angle within half a turn either way (the run log refuses any other)",
            "degrees written as radians?"),
    },
    "groundtruth": {
        1: (-_ROOM_M, _ROOM_M, "|x| <= 20 m", _ROOM_WHY, "mm written as m?"),
        2: (-_ROOM_M, _ROOM_M, "|y| <= 20 m", _ROOM_WHY, "mm written as m?"),
        # Vicon wraps the orientation into [-pi, pi]; the files round it to 4 decimals and
        # write pi as 3.1416 (Dataset 6, Robot5), hence the 1e-3 margin
        3: (-math.pi - 1e-3, math.pi + 1e-3, "|orientation| <= pi (+ 0.001 for rounding)",
            "Vicon's orientation is an angle wrapped into [-pi, pi]", "degrees written as radians?"),
    },
    "landmarks": {
        1: (-_ROOM_M, _ROOM_M, "|x| <= 20 m", _ROOM_WHY, "mm written as m?"),
        2: (-_ROOM_M, _ROOM_M, "|y| <= 20 m", _ROOM_WHY, "mm written as m?"),
    },
}
# Every time column within the run log's stamps (±1e10 s), every subject and barcode a
# run log's landmark id (0 ... 2^31 - 1).
_TIME = (-STAMP_S, STAMP_S, "|time| <= 1e10 s", "times are Unix seconds (1.2e9 s in MRCLAM)", "ms or ns written as s?")
_NUMBER = (0, MAX_ID, "0 <= number <= 2^31 - 1", "subjects and barcodes are small whole numbers", "is the line corrupted?")
for _kind in ("odometry", "measurement", "groundtruth"):
    _LIMITS[_kind][0] = _TIME
_LIMITS["measurement"][1] = _LIMITS["landmarks"][0] = _NUMBER
_LIMITS["barcodes"] = {0: _NUMBER, 1: _NUMBER}


#: The odometry noise model of integrated commands (module docstring); one class with
#: :class:`slamio.noise_model.OdometryNoiseRates`, which ``fgslam calibrate`` fits.
CommandOdometryNoise = OdometryNoiseRates


# --------------------------------------------------------------------------- pure maths


def _arc(distance_m: float, angle_rad: float) -> tuple[float, float]:
    """(dx, dy) of a circular arc (the arc model of slamio.geometry.arc_increment)."""
    if abs(angle_rad) < 1e-4:
        a2 = angle_rad * angle_rad
        return distance_m * (1.0 - a2 / 6.0), distance_m * (angle_rad / 2.0 - angle_rad * a2 / 24.0)
    return (
        distance_m * math.sin(angle_rad) / angle_rad,
        distance_m * (1.0 - math.cos(angle_rad)) / angle_rad,
    )


def integrate_commands(
    times_s: np.ndarray,
    forward_mps: np.ndarray,
    angular_radps: np.ndarray,
    t_from_s: float,
    t_to_s: float,
    noise: CommandOdometryNoise,
    *,
    first_index: int = 0,
) -> tuple[tuple[float, float, float], np.ndarray, float, float, int]:
    """Integrate zero-order-hold velocity commands over ``[t_from_s, t_to_s]``.

    Command ``k`` holds from ``times_s[k]`` to ``times_s[k+1]``; ``times_s`` is
    non-decreasing and ``times_s[0] ≤ t_from_s ≤ t_to_s ≤ times_s[-1]``. Each stretch is an
    exact circular arc; the arcs are composed in the frame of the pose at ``t_from_s``.

    Returns ``((dx_m, dy_m, dtheta_rad), covariance, distance_m, angle_rad, index)``:
    the increment (``dtheta_rad`` unwrapped), its 3×3 covariance under ``noise``, the
    commanded travel ``Σ v·dt`` and turn ``Σ ω·dt``, and the index of the command active at
    ``t_to_s`` (pass it back as ``first_index`` to continue without searching).
    """
    x = y = th = 0.0
    P = np.zeros((3, 3))
    distance = angle = 0.0
    k = max(first_index, 0)
    n = len(times_s)
    # the command active at t_from_s: the last k with times_s[k] <= t_from_s
    while k + 1 < n and times_s[k + 1] <= t_from_s:
        k += 1
    t = t_from_s
    while t < t_to_s and k < n - 1:
        t_next = min(t_to_s, float(times_s[k + 1]))
        dt = t_next - t
        if dt > 0.0:
            ds = float(forward_mps[k]) * dt
            dth = float(angular_radps[k]) * dt
            dx, dy = _arc(ds, dth)
            c, s = math.cos(th), math.sin(th)
            # first-order propagation through T ⊕ δ: J1 wrt T, J2 wrt δ
            J1 = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
            J2 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            P = J1 @ P @ J1.T + J2 @ noise.stretch_covariance(ds, dth, dt) @ J2.T
            x, y, th = x + c * dx - s * dy, y + s * dx + c * dy, th + dth
            distance += ds
            angle += dth
        t = t_next
        if t_next >= float(times_s[k + 1]):
            k += 1
    while k + 1 < n and times_s[k + 1] <= t_to_s:
        k += 1
    P = 0.5 * (P + P.T)
    return (x, y, th), P, distance, angle, k


def fill_zero_blips(
    times_s: np.ndarray, forward_mps: np.ndarray, angular_radps: np.ndarray, max_blip_s: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """Replace zero commands held shorter than ``max_blip_s`` by the command before them.

    The MRCLAM odometry files have a burst of ``0 0`` lines about once a second, 10–50 ms
    long, between equal non-zero commands. The robots do not execute them: over all five
    robots of Dataset 6, Vicon shows them keeping 93–98 % of their speed through a zero
    run shorter than 60 ms (and slowing to 7–26 % through runs of 0.2 s or longer, which
    are real stops). Integrating the blips makes the odometry read ~1 % short in distance
    and turn. Returns the filled ``(forward, angular)`` and the number of blips filled.
    """
    v, w = forward_mps.copy(), angular_radps.copy()
    zero = (v == 0.0) & (w == 0.0)
    n, i, filled = len(v), 0, 0
    while i < n:
        if not zero[i]:
            i += 1
            continue
        j = i
        while j < n and zero[j]:
            j += 1
        if 0 < i and j < n and times_s[j] - times_s[i] < max_blip_s:
            v[i:j], w[i:j] = v[i - 1], w[i - 1]
            filled += 1
        i = j
    return v, w, filled


def _is_stale_repeat(previous, t_s, range_m, bearing_rad, times_s, travel) -> bool:
    """A reading equal to the digit to the previous one of the same barcode while the robot moved.

    The MRCLAM camera sometimes re-reports its last reading of a barcode (1–2 % of the
    lines; median 0.24 s later): a moving robot cannot see a landmark at exactly the same
    range and bearing twice, so the repeat is not a new measurement, and counting it twice
    would make the estimators over-confident. ``travel`` is the cumulative commanded
    motion at ``times_s``.
    """
    if previous is None or (previous[1], previous[2]) != (range_m, bearing_rad):
        return False
    moved = np.interp([previous[0], t_s], times_s, travel)
    return bool(moved[1] - moved[0] > 1e-6)


def interpolate_pose(
    times_s: np.ndarray, poses: np.ndarray, t_s: float, max_gap_s: float
) -> tuple[float, float, float] | None:
    """Ground-truth pose at ``t_s``: linear in x, y; heading along the shorter arc.

    ``poses`` is (N, 3) of (x_m, y_m, theta_rad) at the non-decreasing ``times_s``.
    Returns None when ``t_s`` is outside the samples or the two samples around it are more
    than ``max_gap_s`` apart.
    """
    n = len(times_s)
    if n == 0 or t_s < times_s[0] or t_s > times_s[-1]:
        return None
    i = bisect.bisect_right(times_s, t_s) - 1  # times_s[i] <= t_s
    if times_s[i] == t_s:
        x, y, th = poses[i]
        return float(x), float(y), float(wrap_angle(float(th)))
    t0, t1 = float(times_s[i]), float(times_s[i + 1])
    if t1 - t0 > max_gap_s:
        return None
    a = (t_s - t0) / (t1 - t0)
    x0, y0, th0 = (float(v) for v in poses[i])
    x1, y1, th1 = (float(v) for v in poses[i + 1])
    return (
        x0 + a * (x1 - x0),
        y0 + a * (y1 - y0),
        float(wrap_angle(th0 + a * wrap_angle(th1 - th0))),
    )


def pose_times(
    start_s: float, end_s: float, measurement_times_s: list[float], max_step_s: float | None
) -> list[float]:
    """Times of poses 1, 2, …: every measurement time, plus fillers so gaps ≤ ``max_step_s``.

    ``measurement_times_s`` are sorted, distinct and in ``(start_s, end_s]``; pose 0 is at
    ``start_s`` and is not in the result. Fillers split a long gap into equal parts; the
    run's end gets a pose too when fillers are on.
    """
    anchors = list(measurement_times_s)
    if max_step_s is not None and (not anchors or anchors[-1] < end_s):
        anchors.append(end_s)
    out: list[float] = []
    previous = start_s
    for t in anchors:
        if max_step_s is not None:
            gap = t - previous
            parts = math.ceil(gap / max_step_s - 1e-9) if gap > 0 else 1
            for j in range(1, parts):
                out.append(previous + gap * j / parts)
        out.append(t)
        previous = t
    return out


# --------------------------------------------------------------------------- parsing


class _BadLine(Exception):
    """Internal: what is wrong with one line."""


def _layout(kind: str) -> str:
    return "'" + "  ".join(_LAYOUT[kind]) + "'"


def _read_table(path: str, kind: str, *, integer_columns: tuple[int, ...] = ()) -> list[tuple[int, list[float]]]:
    """Data lines of one MRCLAM file as (line number, values); ``#`` lines are comments."""
    columns = _LAYOUT[kind]
    if not os.path.lexists(path):
        raise InputFileError(
            f"{path}: no such file; an MRCLAM dataset folder holds Barcodes.dat, "
            "Landmark_Groundtruth.dat and RobotN_Odometry.dat, RobotN_Measurement.dat, "
            f"RobotN_Groundtruth.dat for N = 1..5 (download: {MRCLAM_URL})"
        )
    # a regular file of at most a run log's size: never a FIFO, /dev/zero or a link loop
    raw_lines = read_bytes(path, "MRCLAM file", limit=MAX_LOG_BYTES).split(b"\n")
    rows: list[tuple[int, list[float]]] = []
    for number, raw in enumerate(raw_lines, start=1):
        try:
            try:
                text = raw.decode("ascii")
            except UnicodeDecodeError:
                raise _BadLine("not plain ASCII text; is this an MRCLAM .dat file?") from None
            stripped = text.strip()
            if not stripped or stripped.startswith("#"):
                continue
            tokens = stripped.split()
            if len(tokens) != len(columns):
                raise _BadLine(f"{len(tokens)} columns, expected {len(columns)}")
            values = []
            for index, (token, name) in enumerate(zip(tokens, columns)):
                try:
                    value = float(token)
                except ValueError:
                    raise _BadLine(f"column {index + 1} ({name}) is not a number: {shown(token)}") from None
                if not math.isfinite(value):
                    raise _BadLine(f"column {index + 1} ({name}) must be finite, got {shown(token)}")
                if index in integer_columns and value != int(value):
                    raise _BadLine(f"column {index + 1} ({name}) must be an integer, got {shown(token)}")
                values.append(value)
        except _BadLine as bad:
            raise DatasetFormatError(
                path, number, f"{bad}; expected the layout {_layout(kind)} (whitespace-separated, "
                "'#' lines are comments)"
            ) from None
        _check_limits(path, kind, number, tokens, values)
        rows.append((number, values))
    return rows


def _check_limits(path: str, kind: str, number: int, tokens: list[str], values: list[float]) -> None:
    """Raise :class:`DatasetFormatError` for a value of line ``number`` beyond its ``_LIMITS``."""
    for index, (low, high, limit, why, slip) in _LIMITS.get(kind, {}).items():
        if not low <= values[index] <= high:
            raise DatasetFormatError(
                path, number,
                f"column {index + 1} ({_LAYOUT[kind][index]}) is {tokens[index]}, beyond the physical limit "
                f"{limit}: {why}; correct the value ({slip}) or delete this line",
            )


def _check_time_order(path: str, kind: str, rows: list[tuple[int, list[float]]]) -> None:
    previous = -math.inf
    for number, values in rows:
        if values[0] < previous:
            raise DatasetFormatError(
                path, number,
                f"time {values[0]!r} s is earlier than the line before ({previous!r} s); the "
                f"file must be in time order (layout {_layout(kind)})",
            )
        previous = values[0]


def _sha256(path: str) -> str:
    return hashlib.sha256(read_bytes(path, "MRCLAM file", limit=MAX_LOG_BYTES)).hexdigest()


# --------------------------------------------------------------------------- import


def _read_barcodes(path: str) -> dict[int, int]:
    """``Barcodes.dat``: subject of each barcode (both directions unique)."""
    subject_of_barcode: dict[int, int] = {}
    seen_subjects: set[int] = set()
    for number, (subject, barcode) in _read_table(path, "barcodes", integer_columns=(0, 1)):
        subject, barcode = int(subject), int(barcode)
        if subject in seen_subjects:
            raise DatasetFormatError(path, number, f"subject {subject} is listed twice; each subject has one barcode")
        if barcode in subject_of_barcode:
            raise DatasetFormatError(
                path, number,
                f"barcode {barcode} is already subject {subject_of_barcode[barcode]}'s; a barcode names one subject",
            )
        seen_subjects.add(subject)
        subject_of_barcode[barcode] = subject
    if not subject_of_barcode:
        raise DatasetFormatError(path, 1, f"no data lines; expected the layout {_layout('barcodes')}")
    return subject_of_barcode


def _read_landmarks(path: str) -> tuple[list[TruthLandmark], dict[str, list[float]]]:
    """``Landmark_Groundtruth.dat``: the surveyed landmarks and their stated std-devs."""
    truth_landmarks: list[TruthLandmark] = []
    landmark_std: dict[str, list[float]] = {}
    for number, (subject, x, y, x_std, y_std) in _read_table(path, "landmarks", integer_columns=(0,)):
        lid = int(subject)
        if lid in ROBOT_SUBJECTS:
            raise DatasetFormatError(
                path, number, f"subject {lid} is a robot (1-5), not a landmark (6-20)"
            )
        if str(lid) in landmark_std:
            raise DatasetFormatError(path, number, f"landmark {lid} is listed twice")
        truth_landmarks.append(TruthLandmark(landmark_id=lid, x_m=x, y_m=y))
        landmark_std[str(lid)] = [x_std, y_std]
    return truth_landmarks, landmark_std


def _read_commands(path: str, model: NoiseModel | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``RobotN_Odometry.dat``: command times and commanded (v, ω) with the zero blips filled
    (and the blips' count); with a fitted ``model``, the motion they caused: later by its lag,
    scaled, curving by its turn per metre."""
    odo_rows = _read_table(path, "odometry")
    _check_time_order(path, "odometry", odo_rows)
    if len(odo_rows) < 2:
        raise DatasetFormatError(
            path, odo_rows[-1][0] if odo_rows else 1,
            f"fewer than two odometry lines; a run needs at least two (layout {_layout('odometry')})",
        )
    odo = np.array([v for _, v in odo_rows])
    t_odo = odo[:, 0]
    v_cmd, w_cmd, zero_blips = fill_zero_blips(t_odo, odo[:, 1], odo[:, 2], MAX_ZERO_BLIP_S)
    if model is not None:  # the motion the commands caused: later, and scaled
        t_odo = t_odo + model.odometry.lag_s
        v_cmd = v_cmd * model.odometry.forward_scale
        w_cmd = w_cmd * model.odometry.turn_scale + model.odometry.turn_per_m_rad * v_cmd
    return t_odo, v_cmd, w_cmd, zero_blips


def _read_groundtruth(path: str) -> tuple[np.ndarray, np.ndarray]:
    """``RobotN_Groundtruth.dat``: Vicon's times and (x, y, θ)."""
    gt_rows = _read_table(path, "groundtruth")
    _check_time_order(path, "groundtruth", gt_rows)
    if not gt_rows:
        raise DatasetFormatError(path, 1, f"no data lines; expected the layout {_layout('groundtruth')}")
    gt = np.array([v for _, v in gt_rows])
    t_gt, gt_poses = gt[:, 0], gt[:, 1:4]
    return t_gt, gt_poses


def _noise_description(noise: CommandOdometryNoise | OdometryNoiseRates, model: NoiseModel | None,
                       sigma_range_m: float, sigma_bearing_rad: float) -> dict:
    """The header's ``noise``: the round defaults, or the fitted model applied."""
    return {
        "odometry": {
            "model": (
                "commands (v, w) held until the next command, integrated as exact arcs; each "
                "stretch adds independent forward/sideways/heading errors in its start frame with "
                "variances forward_m2_per_m*|ds| + forward_m2_per_s*dt, lateral_m2_per_m*|ds| + "
                "lateral_m2_per_s*dt, heading_rad2_per_rad*|dtheta| + heading_rad2_per_m*|ds| + "
                "heading_rad2_per_s*dt, propagated to first order through the composition; "
                "round numbers, not fitted to the data"
            ),
            **asdict(noise),
        },
        "observation": {
            "model": "constant sigmas (options of the importer), not fitted to the data",
            "sigma_range_m": sigma_range_m,
            "sigma_bearing_rad": sigma_bearing_rad,
        },
    } if model is None else {
        "odometry": {
            "model": (
                "commands (v, w) held until the next command, delayed by lag_s and scaled "
                "by forward_scale/turn_scale, integrated as exact arcs; per-stretch variance "
                "rates as in slamio.noise_model.OdometryNoiseRates; fitted by fgslam calibrate"
            ),
            "lag_s": model.odometry.lag_s,
            "forward_scale": model.odometry.forward_scale,
            "turn_scale": model.odometry.turn_scale,
            "turn_per_m_rad": model.odometry.turn_per_m_rad,
            **asdict(noise),
        },
        "observation": {
            "model": (
                "readings corrected by slamio.noise_model.correct_observation (depth to range, "
                "scale, bias); per-reading sigmas from range and turn rate; fitted by fgslam calibrate"
            ),
            **asdict(model.observation),
        },
        "fitted_on": list(model.fitted_on),
    }


def _kept_readings(rows, subject_of_barcode: dict[int, int], start: float, end: float, latency_s: float,
                   t_odo: np.ndarray, v_cmd: np.ndarray, w_cmd: np.ndarray):
    """The readings of ``RobotN_Measurement.dat`` (``rows``) that become observations, at their
    picture's time (``latency_s`` earlier), as ``(time, landmark id, range, bearing)``; and
    the counts of those dropped, by reason, and of each unknown barcode."""
    dropped = {"robot_sightings": 0, "unknown_barcodes": 0, "outside_run": 0, "non_positive_range": 0,
               "uncorrectable": 0, "stale_repeats": 0}
    # commanded travel so far (|v|·dt + |ω|·dt) at each command time: did the robot move?
    travel = np.concatenate([[0.0], np.cumsum((np.abs(v_cmd[:-1]) + np.abs(w_cmd[:-1])) * np.diff(t_odo))])
    last_reading: dict[int, tuple[float, float, float]] = {}  # barcode -> (time, range, bearing)
    unknown_barcodes: dict[str, int] = {}
    kept: list[tuple[float, int, float, float]] = []  # (file time, landmark id, range, bearing)
    # in time order (stable: same-time sightings keep their file order), so "the previous
    # reading of this barcode" means the one before in time
    for number, (t, barcode, range_m, bearing_rad) in sorted(rows, key=lambda row: row[1][0]):
        t = t - latency_s  # the time the picture was taken
        subject = subject_of_barcode.get(int(barcode))
        if subject is None:
            dropped["unknown_barcodes"] += 1
            unknown_barcodes[str(int(barcode))] = unknown_barcodes.get(str(int(barcode)), 0) + 1
        elif subject in ROBOT_SUBJECTS:
            dropped["robot_sightings"] += 1
        elif not (start <= t <= end):
            dropped["outside_run"] += 1
        elif not range_m > 0.0:
            dropped["non_positive_range"] += 1
        elif _is_stale_repeat(last_reading.get(int(barcode)), t, range_m, bearing_rad, t_odo, travel):
            dropped["stale_repeats"] += 1
        else:
            kept.append((t, subject, range_m, bearing_rad))
        last_reading[int(barcode)] = (t, range_m, bearing_rad)
    return kept, dropped, unknown_barcodes


def import_mrclam(
    folder: str | os.PathLike[str],
    robot: int = 1,
    *,
    sigma_range_m: float = DEFAULT_SIGMA_RANGE_M,
    sigma_bearing_rad: float = DEFAULT_SIGMA_BEARING_RAD,
    odometry_noise: CommandOdometryNoise | None = None,
    max_step_s: float | None = DEFAULT_MAX_STEP_S,
    max_truth_gap_s: float = DEFAULT_MAX_TRUTH_GAP_S,
    max_duration_s: float | None = None,
    model: NoiseModel | None = None,
) -> tuple[Header, list[Record]]:
    """Convert one robot's run of an MRCLAM dataset folder into a run-log header and records.

    ``folder`` is an ``MRCLAM_DatasetK`` folder; ``robot`` (1–5) picks whose
    ``RobotN_*.dat`` files are converted. ``sigma_range_m``/``sigma_bearing_rad`` are the
    observation sigmas; ``odometry_noise`` the odometry noise model (default
    :class:`CommandOdometryNoise`); ``max_step_s`` the longest time between poses when no
    measurement arrives (None: poses only at measurement times); ``max_truth_gap_s`` the
    longest ground-truth gap interpolated over; ``max_duration_s`` cuts the run short.

    The records: the ``truth_landmark`` records, then the ``truth_pose`` of pose 0, then
    for each later pose its ``odometry``, ``truth_pose`` and ``observation`` records (see the
    module docstring). Write them with ``slamio.log.write_log``. Counts of everything
    dropped are in ``header.source["dropped"]``.

    ``model`` (a :class:`~slamio.noise_model.NoiseModel`, from ``fgslam calibrate``)
    replaces the round default noise with a fitted one: its odometry lag and scales are
    applied to the commands (command ``k`` then acts from ``times_s[k] + lag_s`` at
    ``forward_scale·v``, ``turn_scale·ω``), its variance rates replace ``odometry_noise``,
    and every reading is corrected by
    :func:`~slamio.noise_model.correct_observation` (depth to range, scale, bias; σ from
    the range and from the turn rate at the reading) and placed at its picture's time
    (``stamp − camera_latency_s``). ``sigma_range_m``/``sigma_bearing_rad`` are then
    unused.

    Raises :class:`DatasetFormatError` (``file:line: ...``) at the first bad line and
    :class:`~slamio.errors.FgslamError` for a missing file or a bad option.
    """
    if robot not in ROBOT_SUBJECTS:
        raise FgslamError(f"robot must be one of {', '.join(map(str, ROBOT_SUBJECTS))}, got {robot!r}")
    for name, value in (("sigma_range_m", sigma_range_m), ("sigma_bearing_rad", sigma_bearing_rad),
                        ("max_truth_gap_s", max_truth_gap_s)):
        if not (math.isfinite(value) and value > 0.0):
            raise FgslamError(f"{name} must be a positive number, got {value!r}")
    for name, value in (("max_step_s", max_step_s), ("max_duration_s", max_duration_s)):
        if value is not None and not (math.isfinite(value) and value > 0.0):
            raise FgslamError(f"{name} must be a positive number of seconds or None, got {value!r}")
    noise = odometry_noise if odometry_noise is not None else CommandOdometryNoise()
    if model is not None and not model.odometry_fitted:
        raise FgslamError("the noise model's odometry part was not fitted (it was calibrated on a truth without "
                          "heading, such as GPS); fit the model on MRCLAM runs, whose Vicon truth has headings")
    if model is not None:
        noise = model.odometry.noise
    folder = os.fspath(folder)
    if not os.path.isdir(folder):
        raise InputFileError(f"{folder}: not a folder; give an MRCLAM_DatasetK folder (download: {MRCLAM_URL})")
    paths = {
        "barcodes": os.path.join(folder, "Barcodes.dat"),
        "landmarks": os.path.join(folder, "Landmark_Groundtruth.dat"),
        "odometry": os.path.join(folder, f"Robot{robot}_Odometry.dat"),
        "measurement": os.path.join(folder, f"Robot{robot}_Measurement.dat"),
        "groundtruth": os.path.join(folder, f"Robot{robot}_Groundtruth.dat"),
    }

    subject_of_barcode = _read_barcodes(paths["barcodes"])

    truth_landmarks, landmark_std = _read_landmarks(paths["landmarks"])

    t_odo, v_cmd, w_cmd, zero_blips = _read_commands(paths["odometry"], model)

    t_gt, gt_poses = _read_groundtruth(paths["groundtruth"])
    t_gt_list = t_gt.tolist()

    # ---- the run's time span and its start pose
    start = max(float(t_odo[0]), float(t_gt[0]))
    end = float(t_odo[-1])
    if max_duration_s is not None:
        end = min(end, start + max_duration_s)
    if not (end > start and float(t_gt[-1]) >= start):
        raise FgslamError(
            f"{paths['odometry']} ({t_odo[0]!r}..{t_odo[-1]!r} s) and {paths['groundtruth']} "
            f"({t_gt[0]!r}..{t_gt[-1]!r} s) do not overlap in time: no start pose can be read"
        )
    start_pose = interpolate_pose(t_gt_list, gt_poses, start, math.inf)
    assert start_pose is not None

    meas_rows = _read_table(paths["measurement"], "measurement", integer_columns=(1,))
    latency = model.observation.camera_latency_s if model is not None else 0.0
    kept, dropped, unknown_barcodes = _kept_readings(meas_rows, subject_of_barcode, start, end, latency,
                                                     t_odo, v_cmd, w_cmd)

    # ---- poses and records
    obs_by_time: dict[float, list[tuple[int, float, float]]] = {}
    kept.sort(key=lambda m: m[0])  # stable: same-time sightings keep their file order
    for t, lid, range_m, bearing_rad in kept:
        obs_by_time.setdefault(t, []).append((lid, range_m, bearing_rad))
    times = pose_times(start, end, sorted(t for t in obs_by_time if t > start), max_step_s)

    def stamp(t: float) -> float:
        return round(t - start, 6)

    def observations_at(t: float) -> list[Observation]:
        if model is None:
            return [
                Observation(stamp(t), lid, range_m, bearing_rad, sigma_range_m, sigma_bearing_rad)
                for lid, range_m, bearing_rad in obs_by_time.get(t, ())
            ]
        turn_rate = abs(float(w_cmd[max(bisect.bisect_right(t_odo_list, t) - 1, 0)]))
        out = []
        for lid, range_m, bearing_rad in obs_by_time.get(t, ()):
            try:
                r, b, sr, sb = correct_observation(model.observation, range_m, bearing_rad, turn_rate)
            except NoiseModelError:
                dropped["uncorrectable"] += 1
                continue
            out.append(Observation(stamp(t), lid, r, b, sr, sb))
        return out

    t_odo_list = t_odo.tolist()

    records: list[Record] = list(truth_landmarks)
    records.append(TruthPose(0.0, *start_pose))
    records.extend(observations_at(start))
    n_truth = 1
    n_no_truth = 0
    previous, k = start, 0
    for t in times:
        (dx, dy, dth), P, distance, angle, k = integrate_commands(
            t_odo, v_cmd, w_cmd, previous, t, noise, first_index=k
        )
        records.append(Odometry(stamp(t), dx, dy, dth, as_matrix3(P), distance, angle))
        truth = interpolate_pose(t_gt_list, gt_poses, t, max_truth_gap_s)
        if truth is None:
            n_no_truth += 1
        else:
            records.append(TruthPose(stamp(t), *truth))
            n_truth += 1
        records.extend(observations_at(t))
        previous = t

    digests = {os.path.basename(p): _sha256(p) for p in paths.values()}
    header = Header(
        stamp_s=0.0,
        start_pose=start_pose,
        start_sigma=START_SIGMA,
        robot={
            "name": f"MRCLAM Robot{robot} (iRobot Create)",
            "drive": "differential",
            "dataset_robot": robot,
            "odometry_source": "commanded forward and angular velocity (~67 Hz), not wheel encoders",
        },
        sensor={
            "kind": "range-bearing",
            "landmark_kind": "barcoded cylinder",
            "camera": "monocular, 960x720, aligned with the robot body frame",
            "landmark_ids": "MRCLAM subject numbers 6-20, mapped from barcodes through Barcodes.dat",
        },
        noise=_noise_description(noise, model, sigma_range_m, sigma_bearing_rad),
        source={
            "dataset": "utias-mrclam",
            "url": MRCLAM_URL,
            "folder": folder,
            "robot": robot,
            "files_sha256": digests,
            "converted_by": f"fgslam import mrclam --robot {robot}",
            "time_origin_s": start,
            "stamps": "seconds since time_origin_s (file time), rounded to the microsecond",
            "duration_s": stamp(end),
            "start": "pose 0 = ground truth at the start (interpolated), so the world frame is the Vicon frame",
            "poses": len(times) + 1,
            "poses_with_truth": n_truth,
            "poses_without_truth": n_no_truth,
            "max_step_s": max_step_s,
            "max_truth_gap_s": max_truth_gap_s,
            "observations": len(kept),
            "measurement_lines": len(meas_rows),
            "dropped": dropped,
            "zero_command_blips_filled": zero_blips,
            "unknown_barcodes": unknown_barcodes,
            "landmark_truth_std_m": landmark_std,
        },
    )
    return header, records
