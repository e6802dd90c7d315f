"""Plaza1 / Plaza2 (CMU, "navigating with ranging radios") → run-log records.

The data
--------
Djugash, Singh et al. drove a robot on a plaza and ranged to four radio beacons; RTK GPS
gave ground truth. The gtsam wheel ships both runs in its ``Data`` folder:

* ``PlazaN_DR.txt`` — dead reckoning, one line per interval:
  ``time_s  delta_distance_m  delta_heading_rad`` (0.2 s apart in Plaza1, 0.1 s in Plaza2);
* ``PlazaN_TD.txt`` — ranges: ``time_s  sender_id  receiver_id  range_m`` (the robot's radio
  is the sender; the receiver is the beacon);
* ``PlazaN_.mat`` — MATLAB file with ``GT`` (``time_s x_m y_m theta_rad``, GPS ground truth,
  one row at the start and one at each DR time) and ``TL`` (``beacon_id x_m y_m``, the
  surveyed beacon positions).

The conversion
--------------
* **Start**: pose 0 is at the first ``GT`` row's time and position, pinned with σ = 1e-3 m
  (heading: below): the world frame is the GPS frame and ATE is measured against GPS
  without alignment.
* **Odometry**: each DR interval ``(Δs, Δθ)`` becomes the arc increment of
  :func:`slamio.geometry.arc_increment` (within 1 % of other integrations' ATE against GPS:
  arc 1.93 m, heading-first 1.90 m, move-first 1.97 m over Plaza1). A range that arrives
  inside an interval splits it at the range's time (the motion shared in proportion to
  time), so every range belongs to a pose at its own time, as the log format asks.
* **Odometry noise** (chosen, not calibrated: GPS gives no independent heading in Plaza1,
  whose GT heading equals the DR heading): per piece of duration Δt,
  ``var(Δs) = (0.05·Δs)² + 0.02² m²/s·Δt``, ``var(Δθ) = (0.05·Δθ)² + 0.005² rad²/s·Δt``,
  mapped through the arc Jacobian, plus ``0.02² m²/s·Δt`` on x and y (sideways slip)
  (:class:`PlazaOdometryNoise`). The time-proportional parts keep a standing robot's covariance
  positive definite and make the total independent of how an interval is split.
* **Ranges** (sorted by time: the shipped TD files have blocks out of order): range-only observations (no bearing) of landmark ``receiver_id``, with
  ``range_m − range_bias_m`` and ``sigma_range_m`` (defaults 0 and 1.5 m), or, with
  ``range_model`` (``fgslam calibrate`` on the other run), corrected by that model
  (:func:`slamio.noise.apply.correct_range`). Measured against GPS truth (GT interpolated
  at each range time): ``measured = 1.069·distance + 0.03 m`` with white noise σ 0.54 m
  (Plaza1; Plaza2 1.070, 0.01 m, 0.56 m): a 7 % scale, which at the plaza's typical 40 m
  reads as a median offset of 2.84 m (2.80 m). The defaults do not use the truth.
  A range before the first DR time belongs to pose 0; ranges after the last are dropped.
* **Start heading**: GPS gives no heading (Plaza1's ``GT`` heading is its dead-reckoned one), and
  with unsurveyed beacons nothing else fixes the rotation of the whole solution about the
  start; the start heading is the one that turns the dead-reckoned path onto the first
  20 m of GPS track (:func:`gps_start_heading_rad`), σ 0.05 rad.
* **Truth**: a ``truth_pose`` at every pose with the GPS position only (GT interpolated
  linearly in time; no ``theta_rad``), and a ``truth_landmark`` per beacon (``TL``). The
  ``GT`` heading is no measurement: Plaza1's is the dead reckoning's, and Plaza2's points
  backwards — the direction of travel is 3.08 rad (median) from it, against −0.016 rad in
  Plaza1 (:func:`gt_heading_offset_rad`; GTSAM's Plaza2 example starts at ``π − 2.021``
  for that reason) — and, turned round and onto the start heading, is still 0.18 rad
  (median) off the direction of travel (Plaza1: 0.07 rad). Scored as a heading, it left the
  NEES of every estimator on Plaza2, dead reckoning's included, inside its band at only 5 %
  of the poses.
  Without it, the NEES is over the position (2 degrees of freedom), and no heading error or
  RPE is reported.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from slamio.datasets.mrclam_motion import interpolate_pose
from slamio.datasets.victoria_park import DatasetFormatError
from slamio.errors import FgslamError, InputFileError, check_regular
from slamio.geometry import arc_increment, arc_increment_jacobian, wrap_angle
from slamio.log import Header, Observation, Odometry, Record, TruthLandmark, TruthPose
from slamio.log.read import MAX_LOG_BYTES, check_records
from slamio.noise.apply import correct_range
from slamio.noise.errors import NoiseModelError
from slamio.noise.model import NoiseModel
from slamio.safe_input import shown

__all__ = ["import_plaza", "plaza_files", "PLAZA_RUNS", "odometry_covariance", "PlazaOdometryNoise", "gps_start_heading_rad"]

PLAZA_RUNS = ("plaza1", "plaza2")
START_SIGMA = (1e-3, 1e-3, 1e-3)
DEFAULT_RANGE_SIGMA_M = 1.5


@dataclass(frozen=True)
class PlazaOdometryNoise:
    """Per-interval odometry noise (see the module docstring): proportional parts ``k_*``
    and random-walk densities ``*_per_s`` (variance per second)."""

    k_distance: float = 0.05
    k_heading: float = 0.05
    distance_m2_per_s: float = 0.02**2
    heading_rad2_per_s: float = 0.005**2
    sideways_m2_per_s: float = 0.02**2


def plaza_files(run: str, folder: str | os.PathLike[str] | None = None) -> tuple[Path, Path, Path]:
    """``(DR, TD, mat)`` paths of ``run`` (``plaza1`` / ``plaza2``) in ``folder``, or in the
    installed gtsam wheel's Data folder."""
    name = run.lower()
    if name not in PLAZA_RUNS:
        raise FgslamError(f"unknown Plaza run {run!r}; choose plaza1 or plaza2")
    stem = "Plaza1" if name == "plaza1" else "Plaza2"
    if folder is None:
        try:
            import gtsam  # lazy: only to find the files it ships
        except ImportError as exc:  # pragma: no cover - gtsam is a dependency
            raise FgslamError(f"cannot find {stem}_DR.txt: gtsam is not importable ({exc}); give --source") from None
        try:
            folder = Path(gtsam.findExampleDataFile(f"{stem}_DR.txt")).parent
        except (RuntimeError, ValueError) as exc:
            raise FgslamError(f"gtsam does not ship {stem}_DR.txt here ({exc}); give --source FOLDER") from None
    folder = Path(folder)
    files = (folder / f"{stem}_DR.txt", folder / f"{stem}_TD.txt", folder / f"{stem}_.mat")
    for f in files:
        if not os.path.lexists(f):
            raise InputFileError(f"{f}: not found; a Plaza folder holds {stem}_DR.txt, {stem}_TD.txt and {stem}_.mat")
        check_regular(f, "Plaza file")  # never a FIFO, a device or a link loop
        if os.path.getsize(f) > MAX_LOG_BYTES:
            raise InputFileError(f"{f}: {os.path.getsize(f)} bytes, larger than any Plaza file; is it the right file?")
    return files


def _read_table(path: Path, columns: tuple[str, ...], *, ordered: bool = True) -> np.ndarray:
    """Whitespace-separated numbers, ``len(columns)`` per line; file:line errors. With
    ``ordered`` the first column (time) must not go back; otherwise rows are sorted by it
    (stable)."""
    rows = []
    with open(path, encoding="ascii", errors="replace") as f:
        for number, line in enumerate(f, start=1):
            tokens = line.split()
            if not tokens:
                continue
            if len(tokens) != len(columns):
                raise DatasetFormatError(
                    str(path), number,
                    f"{len(tokens)} numbers; expected {len(columns)}: {' '.join(columns)}",
                )
            try:
                values = [float(t) for t in tokens]
            except ValueError:
                raise DatasetFormatError(
                    str(path), number, f"not a number in {shown(line.strip(), 80)}; expected {' '.join(columns)}"
                ) from None
            if not all(math.isfinite(v) for v in values):
                raise DatasetFormatError(str(path), number, "a value is not finite")
            if ordered and rows and values[0] < rows[-1][0]:
                raise DatasetFormatError(str(path), number, f"time {values[0]} goes back (previous {rows[-1][0]})")
            rows.append(values)
    if not rows:
        raise DatasetFormatError(str(path), 1, f"no data; expected lines of {' '.join(columns)}")
    table = np.array(rows)
    return table if ordered else table[np.argsort(table[:, 0], kind="stable")]


def _read_mat(path: Path) -> tuple[np.ndarray, np.ndarray]:
    from scipy.io import loadmat

    try:
        mat = loadmat(str(path))
    except Exception as exc:  # scipy raises several kinds (and MemoryError) for a damaged or foreign file
        raise DatasetFormatError(str(path), 1, f"not a MATLAB file scipy can read ({type(exc).__name__}: "
                                               f"{str(exc)[:200]})") from None
    for name, cols in (("GT", 4), ("TL", 3)):
        if name not in mat or np.ndim(mat[name]) != 2 or np.shape(mat[name])[1] != cols:
            raise DatasetFormatError(
                str(path), 1, f"needs a variable {name} with {cols} columns (GT: t x y theta; TL: id x y)"
            )
    return np.asarray(mat["GT"], dtype=float), np.asarray(mat["TL"], dtype=float)


def odometry_covariance(
    distance_m: float, angle_rad: float, duration_s: float, noise: PlazaOdometryNoise = PlazaOdometryNoise()
) -> np.ndarray:
    """3×3 covariance of one arc increment over (dx, dy, dθ) (see the module docstring)."""
    dt = max(float(duration_s), 1e-3)
    var = np.diag([(noise.k_distance * distance_m) ** 2 + noise.distance_m2_per_s * dt,
                   (noise.k_heading * angle_rad) ** 2 + noise.heading_rad2_per_s * dt])
    J = arc_increment_jacobian(distance_m, angle_rad)
    cov = J @ var @ J.T + np.diag([noise.sideways_m2_per_s * dt, noise.sideways_m2_per_s * dt, 0.0])
    return 0.5 * (cov + cov.T)


def gt_heading_offset_rad(gt: np.ndarray, min_step_m: float = 0.05) -> float:
    """Median of wrap(direction of travel − GT heading) over GT steps longer than
    ``min_step_m``: ≈ 0 when the GT heading is the robot's heading (Plaza1: −0.016 rad),
    ≈ π when it points backwards (Plaza2: 3.08 rad)."""
    step = np.diff(gt[:, 1:3], axis=0)
    moving = np.hypot(step[:, 0], step[:, 1]) > min_step_m
    if not np.any(moving):
        return 0.0
    travel = np.arctan2(step[moving, 1], step[moving, 0])
    return float(np.median(wrap_angle(travel - gt[1:, 3][moving])))


def _check_range_bias(run: str, bias_m: float, largest_range_m: float) -> None:
    """The range bias against the run's ranges, before anything is converted.

    The bias is a constant offset in every reading of the ranging radios (reading = distance +
    bias), removed as reading − bias. Its size must be below the longest reading: a bias at
    least that long leaves no positive range (every observation would be dropped, a log without
    any), and a negative one that long would mean every reading is less than half its distance —
    not an offset but a broken radio. So |bias| < the largest range is the physical limit."""
    if not math.isfinite(bias_m):
        raise FgslamError(f"range bias (--range-bias) must be a finite number of metres, got {bias_m}")
    if bias_m != 0.0 and not abs(bias_m) < largest_range_m:
        raise FgslamError(f"--range-bias {bias_m:g} m: its size must be below the largest range in {run} "
                          f"({largest_range_m:.2f} m); a bias is a small constant offset of the radios' readings "
                          "(e.g. 0.5), for their 7 % scale fit a model with fgslam calibrate and use --noise")


def _observation_noise(range_sigma_m: float, range_bias_m: float, range_model: NoiseModel | None) -> dict:
    """The header's ``noise.observation``: the fitted range model when one was applied."""
    if range_model is None:
        return {"model": "range-only, constant sigma", "sigma_range_m": range_sigma_m,
                "range_bias_removed_m": range_bias_m,
                "measured_against_gps": "measured = 1.069 x distance + 0.03 m, white sigma 0.54 m (Plaza1; Plaza2 "
                                        "1.070, 0.01 m, 0.56 m): fgslam calibrate, then import --noise (docs/datasets.md)"}
    o = range_model.observation
    return {"model": "range-only readings corrected by slamio.noise.apply.correct_range (fitted model)",
            "range_scale": o.range_scale, "range_bias_m": o.range_bias_m, "range_sigma_m": o.range_sigma_m,
            "range_sigma_per_m": o.range_sigma_per_m, "outlier_rate": o.outlier_rate,
            "correlated_share": o.correlated_share, "correlation_time_s": o.correlation_time_s,
            "fitted_on": list(range_model.fitted_on),
            "odometry_part": "not applied (Plaza1's GPS heading is its dead-reckoned heading)"}


#: Length of the GPS track over which the start heading is measured (:func:`gps_start_heading_rad`).
START_HEADING_TRACK_M = 20.0
#: σ of that start heading: it moves by 2 degrees between the first 10 m and 20 m of track.
START_HEADING_SIGMA_RAD = 0.05


def gps_start_heading_rad(gt: np.ndarray, dr: np.ndarray, track_m: float = START_HEADING_TRACK_M) -> float:
    """The start heading that turns the dead-reckoned path onto the GPS track.

    The dead reckoning (``dr`` rows ``time_s, Δs, Δθ``, arc model) is integrated from the
    first GPS position with heading ``gt[0, 3]``; over the GPS poses within ``track_m`` of
    travel from the start (``gt`` row k + 1 is at ``dr`` row k's time), the rotation about the
    start that best fits the dead-reckoned positions to the GPS ones (least squares) is
    added to that heading. Plaza's ``GT`` heading is no measurement of the start heading
    (Plaza1's is its dead-reckoned heading), and with ranges to beacons whose positions are
    unknown nothing else fixes the rotation of the whole solution about the start."""
    x = y = 0.0
    theta = float(gt[0, 3])
    path = []
    for _, distance, angle in dr:
        dx, dy, dth = arc_increment(float(distance), float(angle))
        c, s = math.cos(theta), math.sin(theta)
        x, y, theta = x + c * dx - s * dy, y + s * dx + c * dy, theta + dth
        path.append((x, y))
    gps = gt[1 : len(path) + 1, 1:3] - gt[0, 1:3]
    a = np.asarray(path)[: len(gps)]
    travelled = np.r_[0.0, np.cumsum(np.hypot(*np.diff(gt[: len(gps) + 1, 1:3], axis=0).T))][1:]
    n = max(int(np.searchsorted(travelled, track_m)), 2)
    a, b = a[:n], gps[:n]
    rotation = math.atan2(float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])),
                          float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
    return float(wrap_angle(float(gt[0, 3]) + rotation))


def import_plaza(
    run: str = "plaza1",
    folder: str | os.PathLike[str] | None = None,
    *,
    range_sigma_m: float = DEFAULT_RANGE_SIGMA_M,
    range_bias_m: float = 0.0,
    odometry_noise: PlazaOdometryNoise = PlazaOdometryNoise(),
    range_model: NoiseModel | None = None,
) -> tuple[Header, list[Record]]:
    """Convert Plaza1 or Plaza2 into ``(header, records)`` (see the module docstring).

    With ``range_model`` (``fgslam calibrate`` on the *other* run) every range is corrected
    by its observation model (:func:`slamio.noise.apply.correct_range`: scale, bias and σ),
    instead of ``range_bias_m`` and ``range_sigma_m``; its odometry part is not used."""
    if not (range_sigma_m > 0 and math.isfinite(range_sigma_m)):
        raise FgslamError(f"range sigma must be > 0 m, got {range_sigma_m}")
    if range_model is not None and range_bias_m != 0.0:
        raise FgslamError("give a range model (--noise) or a range bias, not both")
    dr_path, td_path, mat_path = plaza_files(run, folder)
    dr = _read_table(dr_path, ("time_s", "delta_distance_m", "delta_heading_rad"))
    # the shipped TD files have blocks out of time order (Plaza1 line 1989 goes back 64 s): sort
    td = _read_table(td_path, ("time_s", "sender_id", "receiver_id", "range_m"), ordered=False)
    _check_range_bias(run, range_bias_m, float(td[:, 3].max()) if len(td) else 0.0)
    gt, tl = _read_mat(mat_path)
    t_start = float(gt[0, 0])
    start_heading = gps_start_heading_rad(gt, dr)
    start_pose = (float(gt[0, 1]), float(gt[0, 2]), start_heading)

    records: list[Record] = [
        TruthLandmark(landmark_id=int(b[0]), x_m=float(b[1]), y_m=float(b[2])) for b in tl
    ]
    records.append(TruthPose(t_start, start_pose[0], start_pose[1]))  # GPS: a position, no heading
    ranges = [(max(float(t), t_start), int(recv), float(r)) for t, _, recv, r in td]
    dropped_late = sum(1 for t, _, _ in ranges if t > dr[-1, 0])
    skipped_short = _motion_and_ranges(records, dr, gt, ranges, t_start, odometry_noise, range_sigma_m,
                                       range_bias_m, range_model)

    digest = hashlib.sha256(dr_path.read_bytes() + td_path.read_bytes()).hexdigest()
    header = Header(
        stamp_s=t_start,
        start_pose=start_pose,
        start_sigma=(START_SIGMA[0], START_SIGMA[1], START_HEADING_SIGMA_RAD),
        robot={"name": f"CMU {run.capitalize()} robot (Djugash & Singh, ranging radios)", "drive": "differential",
               "note": "dead reckoning given as (time, delta distance, delta heading) per interval"},
        sensor={"kind": "range-only", "landmark_kind": "radio beacon",
                "beacons": [int(b[0]) for b in tl], "range_bias_removed_m": range_bias_m},
        noise={
            "odometry": {"model": "arc increment; var(ds) = (k_distance ds)^2 + distance_m2_per_s dt, "
                                  "var(dtheta) = (k_heading dtheta)^2 + heading_rad2_per_s dt through the arc "
                                  "Jacobian, plus sideways_m2_per_s dt on x and y", **asdict(odometry_noise)},
            "observation": _observation_noise(range_sigma_m, range_bias_m, range_model),
        },
        source={"dataset": run, "files": [str(dr_path), str(td_path), str(mat_path)], "sha256": digest,
                "converted_by": "fgslam import " + run,
                "start_heading": f"from the GPS track's first {START_HEADING_TRACK_M:g} m (the dead reckoning "
                                 f"turned onto it): {start_heading:.4f} rad",
                "truth": "GPS positions; the GT heading is not a measurement and is left out",
                "ranges_after_last_odometry_dropped": dropped_late,
                "ranges_not_positive_after_bias_dropped": skipped_short},
    )
    return header, list(check_records(f"{dr_path} + {td_path}", header, records))  # no unreadable log


def _motion_and_ranges(records: list[Record], dr: np.ndarray, gt: np.ndarray, ranges: list[tuple[float, int, float]],
                       t_start: float, odometry_noise: PlazaOdometryNoise, range_sigma_m: float, range_bias_m: float,
                       range_model: NoiseModel | None) -> int:
    """Append to ``records`` the ranges of pose 0, then the odometry, GPS truth and range
    records of every dead-reckoning interval, split at the distinct range times inside it.
    Returns how many ranges were dropped as not positive after the bias."""
    skipped_short = 0
    j = 0  # next range

    def observe(t: float, receiver: int, range_m: float) -> None:
        nonlocal skipped_short
        value, sigma = range_m - range_bias_m, range_sigma_m
        if range_model is not None:
            try:
                value, sigma = correct_range(range_model.observation, range_m)
            except NoiseModelError:
                value = 0.0
        if value <= 0:
            skipped_short += 1
            return
        records.append(Observation(t, receiver, value, None, sigma, None))

    while j < len(ranges) and ranges[j][0] <= t_start:  # ranges before the first motion: pose 0
        observe(*ranges[j])
        j += 1
    previous_t = t_start
    for t_end, distance, angle in dr:
        interval = t_end - previous_t
        # split points: the distinct range times inside (previous_t, t_end]
        cuts = []
        while j < len(ranges) and ranges[j][0] <= t_end:
            if not cuts or ranges[j][0] > cuts[-1][0]:
                cuts.append((ranges[j][0], []))
            cuts[-1][1].append(ranges[j])
            j += 1
        if not cuts or cuts[-1][0] < t_end:
            cuts.append((t_end, []))
        done = 0.0
        for t_cut, batch in cuts:
            share = 1.0 if interval <= 0 else (t_cut - previous_t) / interval
            part = max(share - done, 0.0)
            d, a = distance * part, angle * part
            dx, dy, dth = arc_increment(d, a)
            cov = odometry_covariance(d, a, part * interval, odometry_noise)
            records.append(Odometry(t_cut, dx, dy, dth, tuple(map(tuple, cov)), d, a))
            x_m, y_m, _ = interpolate_pose(gt[:, 0], gt[:, 1:], t_cut, math.inf)
            records.append(TruthPose(t_cut, x_m, y_m))
            for t_obs, receiver, range_m in batch:
                observe(t_obs, receiver, range_m)
            done = share
        previous_t = t_end
    return skipped_short
