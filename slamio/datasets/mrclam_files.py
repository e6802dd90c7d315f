"""Reading the files of an MRCLAM dataset folder (the layouts are in
:mod:`slamio.datasets.mrclam`): every data line checked against its layout and the
physical limits of its values, the barcodes, the surveyed landmarks and a robot's Vicon
ground truth. A bad line raises :class:`DatasetFormatError` naming the file and line.
"""

from __future__ import annotations

import hashlib
import math
import os

import numpy as np

from slamio.datasets.victoria_park import DatasetFormatError, _BadLine, ascii_text
from slamio.errors import InputFileError, read_bytes
from slamio.log import TruthLandmark
from slamio.log.fields import MAX_ID, STAMP_S
from slamio.log.read import MAX_LOG_BYTES
from slamio.safe_input import shown

__all__ = [
    "LANDMARK_SUBJECTS", "MRCLAM_URL", "ROBOT_SUBJECTS", "check_time_order", "layout", "read_barcodes",
    "read_groundtruth", "read_landmarks", "read_table", "sha256_of",
]

#: The dataset's web page (where users download MRCLAM_Dataset1..9).
MRCLAM_URL = "http://asrl.utias.utoronto.ca/datasets/mrclam/"
#: Subjects that are robots; 6–20 are landmarks.
ROBOT_SUBJECTS = (1, 2, 3, 4, 5)
LANDMARK_SUBJECTS = tuple(range(6, 21))

# Column layouts, as the files' own fourth header line names them.
_LAYOUT = {
    "barcodes": ("Subject #", "Barcode #"),
    "landmarks": ("Subject #", "x [m]", "y [m]", "x std-dev [m]", "y std-dev [m]"),
    "odometry": ("Time [s]", "Forward Velocity [m/s]", "Angular Velocity [rad/s]"),
    "measurement": ("Time [s]", "Subject #", "Range [m]", "Bearing [rad]"),
    "groundtruth": ("Time [s]", "x [m]", "y [m]", "Orientation [rad]"),
}

# Physical limits of the values, checked on every data line as it is read (read_table):
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


# --------------------------------------------------------------------------- parsing


def layout(kind: str) -> str:
    return "'" + "  ".join(_LAYOUT[kind]) + "'"


def read_table(path: str, kind: str, *, integer_columns: tuple[int, ...] = ()) -> list[tuple[int, list[float]]]:
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
            stripped = ascii_text(raw, "is this an MRCLAM .dat file?").strip()
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
                path, number, f"{bad}; expected the layout {layout(kind)} (whitespace-separated, "
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


def check_time_order(path: str, kind: str, rows: list[tuple[int, list[float]]]) -> None:
    previous = -math.inf
    for number, values in rows:
        if values[0] < previous:
            raise DatasetFormatError(
                path, number,
                f"time {values[0]!r} s is earlier than the line before ({previous!r} s); the "
                f"file must be in time order (layout {layout(kind)})",
            )
        previous = values[0]


def sha256_of(path: str) -> str:
    return hashlib.sha256(read_bytes(path, "MRCLAM file", limit=MAX_LOG_BYTES)).hexdigest()


def read_barcodes(path: str) -> dict[int, int]:
    """``Barcodes.dat``: subject of each barcode (both directions unique)."""
    subject_of_barcode: dict[int, int] = {}
    seen_subjects: set[int] = set()
    for number, (subject, barcode) in read_table(path, "barcodes", integer_columns=(0, 1)):
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
        raise DatasetFormatError(path, 1, f"no data lines; expected the layout {layout('barcodes')}")
    return subject_of_barcode


def read_landmarks(path: str) -> tuple[list[TruthLandmark], dict[str, list[float]]]:
    """``Landmark_Groundtruth.dat``: the surveyed landmarks and their stated std-devs."""
    truth_landmarks: list[TruthLandmark] = []
    landmark_std: dict[str, list[float]] = {}
    for number, (subject, x, y, x_std, y_std) in read_table(path, "landmarks", integer_columns=(0,)):
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


def read_groundtruth(path: str) -> tuple[np.ndarray, np.ndarray]:
    """``RobotN_Groundtruth.dat``: Vicon's times and (x, y, θ)."""
    gt_rows = read_table(path, "groundtruth")
    check_time_order(path, "groundtruth", gt_rows)
    if not gt_rows:
        raise DatasetFormatError(path, 1, f"no data lines; expected the layout {layout('groundtruth')}")
    gt = np.array([v for _, v in gt_rows])
    t_gt, gt_poses = gt[:, 0], gt[:, 1:4]
    return t_gt, gt_poses
