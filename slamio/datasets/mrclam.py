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
physical limit as it is read (``_LIMITS`` of :mod:`slamio.datasets.mrclam_files`: |forward
velocity| ≤ 2 m/s, |angular velocity| ≤ 10 rad/s, range ≤ 20 m, |bearing| ≤ π, positions
within 20 m of the Vicon origin, |orientation| ≤ π): a value beyond one is a corrupted or
hand-edited line, not a reading, and stops the import with the file, line, value and
limit, as a malformed line does.
"""

from __future__ import annotations

import bisect
import math
import os
from pathlib import Path
from dataclasses import asdict, replace

import numpy as np

from slamio.datasets.mrclam_files import (
    LANDMARK_SUBJECTS,
    MRCLAM_URL,
    ROBOT_SUBJECTS,
    check_time_order,
    layout,
    read_barcodes,
    read_groundtruth,
    read_landmarks,
    read_table,
    sha256_of,
)
from slamio.datasets.mrclam_motion import (
    CommandOdometryNoise,
    fill_zero_blips,
    integrate_commands,
    interpolate_pose,
    is_stale_repeat,
    pose_times,
)
from slamio.datasets.victoria_park import DatasetFormatError
from slamio.errors import FgslamError, InputFileError
from slamio.noise.apply import correct_observation, sensor_with_mount
from slamio.noise.errors import NoiseModelError
from slamio.noise.model import NoiseModel, OdometryNoiseRates
from slamio.log import Header, Observation, Odometry, Record, TruthPose, as_matrix3

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

#: Prior sigmas (m, m, rad) on pose 0, which is read from the ground truth.
START_SIGMA = (1e-3, 1e-3, 1e-3)
DEFAULT_SIGMA_RANGE_M = 0.1
DEFAULT_SIGMA_BEARING_RAD = 0.05
DEFAULT_MAX_STEP_S = 0.5
DEFAULT_MAX_TRUTH_GAP_S = 0.5
#: Zero commands held shorter than this are logging artefacts (:func:`fill_zero_blips`).
MAX_ZERO_BLIP_S = 0.06


# --------------------------------------------------------------------------- import


#: The noise model ``fgslam import mrclam`` applies by default: fitted by ``fgslam calibrate``
#: on the five robots of UTIAS MRCLAM Dataset 6 against their Vicon truth (numbers only; no
#: data of the dataset is shipped).
SHIPPED_NOISE_MODEL = str(Path(__file__).with_name("mrclam_noise_dataset6.json"))
SHIPPED_NOISE_NOTE = ("the model shipped with fgslam, fitted on UTIAS MRCLAM Dataset 6's five robots against "
                      "Vicon (slamio/datasets/mrclam_noise_dataset6.json); scored on Dataset 6 itself it is "
                      "in-sample")

def _read_commands(path: str, model: NoiseModel | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``RobotN_Odometry.dat``: command times and commanded (v, ω) with the zero blips filled
    (and the blips' count); with a fitted ``model``, the motion they caused: later by its lag,
    scaled, curving by its turn per metre."""
    odo_rows = read_table(path, "odometry")
    check_time_order(path, "odometry", odo_rows)
    if len(odo_rows) < 2:
        raise DatasetFormatError(
            path, odo_rows[-1][0] if odo_rows else 1,
            f"fewer than two odometry lines; a run needs at least two (layout {layout('odometry')})",
        )
    odo = np.array([v for _, v in odo_rows])
    t_odo = odo[:, 0]
    v_cmd, w_cmd, zero_blips = fill_zero_blips(t_odo, odo[:, 1], odo[:, 2], MAX_ZERO_BLIP_S)
    if model is not None:  # the motion the commands caused: later, and scaled
        t_odo = t_odo + model.odometry.lag_s
        v_cmd = v_cmd * model.odometry.forward_scale
        w_cmd = w_cmd * model.odometry.turn_scale + model.odometry.turn_per_m_rad * v_cmd
    return t_odo, v_cmd, w_cmd, zero_blips


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
                "rates as in slamio.noise.model.OdometryNoiseRates; fitted by fgslam calibrate"
            ),
            "lag_s": model.odometry.lag_s,
            "forward_scale": model.odometry.forward_scale,
            "turn_scale": model.odometry.turn_scale,
            "turn_per_m_rad": model.odometry.turn_per_m_rad,
            **asdict(noise),
        },
        "observation": {
            "model": (
                "readings corrected by slamio.noise.apply.correct_observation (depth to range, "
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
        elif is_stale_repeat(last_reading.get(int(barcode)), t, range_m, bearing_rad, t_odo, travel):
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

    ``model`` (a :class:`~slamio.noise.model.NoiseModel`, from ``fgslam calibrate``)
    replaces the round default noise with a fitted one: its odometry lag and scales are
    applied to the commands (command ``k`` then acts from ``times_s[k] + lag_s`` at
    ``forward_scale·v``, ``turn_scale·ω``), its variance rates replace ``odometry_noise``,
    and every reading is corrected by
    :func:`~slamio.noise.apply.correct_observation` (depth to range, scale, bias; σ from
    the range and from the turn rate at the reading) and placed at its picture's time
    (``stamp − camera_latency_s``). ``sigma_range_m``/``sigma_bearing_rad`` are then
    unused.

    Raises :class:`DatasetFormatError` (``file:line: ...``) at the first bad line and
    :class:`~slamio.errors.FgslamError` for a missing file or a bad option.
    """
    noise = _checked_options(robot, sigma_range_m, sigma_bearing_rad, odometry_noise, max_step_s, max_truth_gap_s,
                             max_duration_s, model)
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

    subject_of_barcode = read_barcodes(paths["barcodes"])
    truth_landmarks, landmark_std = read_landmarks(paths["landmarks"])
    t_odo, v_cmd, w_cmd, zero_blips = _read_commands(paths["odometry"], model)
    t_gt, gt_poses = read_groundtruth(paths["groundtruth"])
    start, end = _run_span(paths, t_odo, t_gt, max_duration_s)
    start_pose = interpolate_pose(t_gt.tolist(), gt_poses, start, math.inf)
    assert start_pose is not None

    meas_rows = read_table(paths["measurement"], "measurement", integer_columns=(1,))
    latency = model.observation.camera_latency_s if model is not None else 0.0
    kept, dropped, unknown_barcodes = _kept_readings(meas_rows, subject_of_barcode, start, end, latency,
                                                     t_odo, v_cmd, w_cmd)
    readings = _Readings(kept, start, t_odo, w_cmd, model, (sigma_range_m, sigma_bearing_rad), dropped)
    times = pose_times(start, end, sorted(t for t in readings.by_time if t > start), max_step_s)
    records, n_truth, n_no_truth = _pose_records(truth_landmarks, start_pose, times, readings, t_odo, v_cmd,
                                                 w_cmd, noise, t_gt, gt_poses, max_truth_gap_s)

    counts = {
        "poses": len(times) + 1, "poses_with_truth": n_truth, "poses_without_truth": n_no_truth,
        "max_step_s": max_step_s, "max_truth_gap_s": max_truth_gap_s, "observations": len(kept),
        "measurement_lines": len(meas_rows), "dropped": dropped, "zero_command_blips_filled": zero_blips,
        "unknown_barcodes": unknown_barcodes, "landmark_truth_std_m": landmark_std,
    }
    header = _header(robot, folder, paths, start, readings.stamp(end), start_pose,
                     _noise_description(noise, model, sigma_range_m, sigma_bearing_rad), counts)
    if model is not None:  # a model fitted with the sensor's mount states it (slamio.noise.apply.sensor_with_mount)
        header = replace(header, sensor=sensor_with_mount(header.sensor, model.observation))
    return header, records


def _checked_options(robot, sigma_range_m, sigma_bearing_rad, odometry_noise, max_step_s, max_truth_gap_s,
                     max_duration_s, model: NoiseModel | None) -> CommandOdometryNoise:
    """The odometry noise model to use, once every option is checked."""
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
    return noise


def _run_span(paths: dict[str, str], t_odo: np.ndarray, t_gt: np.ndarray,
              max_duration_s: float | None) -> tuple[float, float]:
    """The run's (start, end) file times: where commands and ground truth both are."""
    start = max(float(t_odo[0]), float(t_gt[0]))
    end = float(t_odo[-1])
    if max_duration_s is not None:
        end = min(end, start + max_duration_s)
    if not (end > start and float(t_gt[-1]) >= start):
        raise FgslamError(
            f"{paths['odometry']} ({t_odo[0]!r}..{t_odo[-1]!r} s) and {paths['groundtruth']} "
            f"({t_gt[0]!r}..{t_gt[-1]!r} s) do not overlap in time: no start pose can be read"
        )
    return start, end


class _Readings:
    """The kept readings by time, made into observations (corrected by a fitted ``model``;
    one it cannot correct is counted in ``dropped["uncorrectable"]``)."""

    def __init__(self, kept, start: float, t_odo: np.ndarray, w_cmd: np.ndarray, model: NoiseModel | None,
                 sigmas: tuple[float, float], dropped: dict[str, int]):
        self.by_time: dict[float, list[tuple[int, float, float]]] = {}
        kept.sort(key=lambda m: m[0])  # stable: same-time sightings keep their file order
        for t, lid, range_m, bearing_rad in kept:
            self.by_time.setdefault(t, []).append((lid, range_m, bearing_rad))
        self.start, self.model, self.sigmas, self.dropped = start, model, sigmas, dropped
        self.t_odo_list, self.w_cmd = t_odo.tolist(), w_cmd

    def stamp(self, t: float) -> float:
        return round(t - self.start, 6)

    def at(self, t: float) -> list[Observation]:
        model, stamp = self.model, self.stamp
        if model is None:
            return [Observation(stamp(t), lid, range_m, bearing_rad, *self.sigmas)
                    for lid, range_m, bearing_rad in self.by_time.get(t, ())]
        turn_rate = abs(float(self.w_cmd[max(bisect.bisect_right(self.t_odo_list, t) - 1, 0)]))
        out = []
        for lid, range_m, bearing_rad in self.by_time.get(t, ()):
            try:
                r, b, sr, sb = correct_observation(model.observation, range_m, bearing_rad, turn_rate)
            except NoiseModelError:
                self.dropped["uncorrectable"] += 1
                continue
            out.append(Observation(stamp(t), lid, r, b, sr, sb))
        return out


def _pose_records(truth_landmarks, start_pose, times, readings: _Readings, t_odo, v_cmd, w_cmd, noise,
                  t_gt: np.ndarray, gt_poses: np.ndarray, max_truth_gap_s: float) -> tuple[list[Record], int, int]:
    """The records (module docstring) and how many poses have a ground truth and how many not."""
    t_gt_list = t_gt.tolist()
    records: list[Record] = list(truth_landmarks)
    records.append(TruthPose(0.0, *start_pose))
    records.extend(readings.at(readings.start))
    n_truth = 1
    n_no_truth = 0
    previous, k = readings.start, 0
    for t in times:
        (dx, dy, dth), P, distance, angle, k = integrate_commands(
            t_odo, v_cmd, w_cmd, previous, t, noise, first_index=k
        )
        records.append(Odometry(readings.stamp(t), dx, dy, dth, as_matrix3(P), distance, angle))
        truth = interpolate_pose(t_gt_list, gt_poses, t, max_truth_gap_s)
        if truth is None:
            n_no_truth += 1
        else:
            records.append(TruthPose(readings.stamp(t), *truth))
            n_truth += 1
        records.extend(readings.at(t))
        previous = t
    return records, n_truth, n_no_truth


def _header(robot: int, folder: str, paths: dict[str, str], start: float, duration_s: float, start_pose,
            noise: dict, counts: dict) -> Header:
    """The run log's header; ``counts`` end ``source`` (poses, observations, what was dropped)."""
    return Header(
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
            # the dataset gives range and bearing from the robot and no camera offset
            "pose_on_robot": [0.0, 0.0, 0.0],
            "landmark_ids": "MRCLAM subject numbers 6-20, mapped from barcodes through Barcodes.dat",
        },
        noise=noise,
        source={
            "dataset": "utias-mrclam",
            "url": MRCLAM_URL,
            "folder": folder,
            "robot": robot,
            "files_sha256": {os.path.basename(p): sha256_of(p) for p in paths.values()},
            "converted_by": f"fgslam import mrclam --robot {robot}",
            "time_origin_s": start,
            "stamps": "seconds since time_origin_s (file time), rounded to the microsecond",
            "duration_s": duration_s,
            "start": "pose 0 = ground truth at the start (interpolated), so the world frame is the Vicon frame",
            **counts,
        },
    )
