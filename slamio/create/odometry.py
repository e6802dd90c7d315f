"""Create odometry → run-log :class:`slamio.log.Odometry` records (arc model + covariance).

Two robots, two sources
=======================

**Create 2** (Roomba 600 OI): packets 43/44 are the left/right wheel encoder counts,
unsigned 16-bit numbers that wrap around 65535 → 0. The change since the previous frame is
``(new − old) mod 65536`` read as a signed 16-bit number (:func:`counts_delta`; a wheel
moves at most ~17 counts per 15 ms frame, far from the ±32768 ambiguity). One count is
``π · 72 mm / 508.8`` ≈ 0.445 mm of wheel travel (72 mm wheels, 508.8 counts per turn).
The counters are cumulative, so a lost or rejected frame loses no motion: the next good
frame carries it. The encoders are *not* quadrature: the firmware adds or subtracts counts
according to the **commanded** direction of each wheel, so the sign of a delta is the
commanded sign, and a wheel that still rolls forward after being commanded backwards counts
backwards. Come to a stop before reversing a wheel (the recorder does) and the error
disappears. As the Create 2 spec advises::

    distance = (dL + dR) / 2,     angle = (dR − dL) / wheel base (235 mm)

**Create 1**: only packets 19 (distance, mm) and 20 (angle, degrees), each "since it was
last read" and reset by every read, with a resolution of 1 mm and 1°. The robot discards
the fraction it does not report, so a Create polled every 15 ms that turns slower than
~67°/s reports no turn at all (libcreate issue #22, create_robot issue #28). Two things
are done about it (:class:`Create1Odometry`):

1. it is read less often (the recorder polls every 0.1 s instead of streaming every
   15 ms), so the lost fraction is at most 1 unit per 0.1 s instead of per 15 ms; and
2. a reading r only says the true value lies in its truncation interval — ``[r, r+1)`` for
   r > 0, ``(r−1, r]`` for r < 0, ``(−1, 1)`` for r = 0 — and the motion *predicted* from
   the commanded wheel speeds (integrated since the previous read) is clamped into that
   interval (:func:`within_reading`). The measurement bounds the error to one unit per
   read; the command picks the point inside it. Integrating the command alone drifts
   (the libcreate authors tried it); the reading alone loses up to 1° per read.

Records and covariance
======================

Readings are summed until the recorder takes a record (every ~0.1 s): ΔS, Δθ become the
increment with the arc model (:func:`slamio.geometry.arc_increment`), exactly as
``docs/log-format.md`` says. The covariance over (dx, dy, dθ) grows with the motion::

    Σ = |ΔS| · F  +  |Δθ| · R  +  k · Q

``F`` is the covariance per metre driven and ``R`` per radian turned (from
``fgslam calibrate``, seed 001's trials, or the nominal values of :func:`default_noise`),
``Q`` the quantisation of one reading (k = 1 for the Create 2, whose counts are cumulative;
k = number of reads for the Create 1, each of which truncates). Variances that add up with
distance and angle are what a random walk does, so the covariance of a long drive is the
same however it is cut into records.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slamio.errors import FgslamError
from slamio.geometry import arc_increment, compose_pose
from slamio.log import Matrix3, Odometry, as_matrix3

__all__ = [
    "WHEEL_BASE_M",
    "CREATE2_WHEEL_DIAMETER_MM",
    "CREATE2_COUNTS_PER_REV",
    "CREATE2_MM_PER_COUNT",
    "counts_delta",
    "counts_to_m",
    "wheel_reading",
    "truncation_interval",
    "within_reading",
    "OdometryNoise",
    "default_noise",
    "quantisation_floor",
    "odometry_record",
    "integrate_records",
    "Create1Odometry",
    "Create2Odometry",
]

WHEEL_BASE_M = 0.235
CREATE2_WHEEL_DIAMETER_MM = 72.0
CREATE2_COUNTS_PER_REV = 508.8
CREATE2_MM_PER_COUNT = math.pi * CREATE2_WHEEL_DIAMETER_MM / CREATE2_COUNTS_PER_REV
_COUNTS_MODULUS = 1 << 16


# --------------------------------------------------------------------------- pure maths


def counts_delta(new_counts: int, old_counts: int) -> int:
    """Signed change between two uint16 encoder readings, across the 65535 → 0 wrap.

    ``counts_delta(3, 65533) == 6`` and ``counts_delta(65533, 3) == -6``.
    """
    return ((int(new_counts) - int(old_counts) + 32768) % _COUNTS_MODULUS) - 32768


def counts_to_m(counts: float, mm_per_count: float = CREATE2_MM_PER_COUNT) -> float:
    """Wheel travel in metres for a number of Create 2 encoder counts."""
    return counts * mm_per_count / 1000.0


def wheel_reading(left_m: float, right_m: float, wheel_base_m: float = WHEEL_BASE_M) -> tuple[float, float]:
    """(distance_m, angle_rad) of the robot's centre from the two wheels' travel.

    ``distance = (dL + dR)/2`` and ``angle = (dR − dL)/wheel base`` (counter-clockwise).
    """
    return 0.5 * (left_m + right_m), (right_m - left_m) / wheel_base_m


def truncation_interval(reading: int) -> tuple[float, float]:
    """Where the true value lies when the Create 1 reports ``reading`` (truncated to 0).

    ``[r, r+1)`` for r > 0, ``(r−1, r]`` for r < 0, ``(−1, 1)`` for r = 0; returned as
    the closed bounds (lo, hi).
    """
    if reading > 0:
        return float(reading), float(reading) + 1.0
    if reading < 0:
        return float(reading) - 1.0, float(reading)
    return -1.0, 1.0


def within_reading(predicted: float, reading: int) -> float:
    """The predicted value clamped into the truncation interval of ``reading``."""
    lo, hi = truncation_interval(reading)
    return min(max(predicted, lo), hi)


# --------------------------------------------------------------------------- noise


def _matrix(m, what: str) -> Matrix3:
    a = np.asarray(m, dtype=float)
    if a.shape != (3, 3) or not np.all(np.isfinite(a)):
        raise FgslamError(f"{what} must be a finite 3×3 matrix over (x, y, theta)")
    if not np.allclose(a, a.T, rtol=1e-9, atol=1e-18):
        raise FgslamError(f"{what} must be symmetric")
    if np.linalg.eigvalsh(0.5 * (a + a.T)).min() < -1e-12 * max(1.0, float(np.abs(a).max())):
        raise FgslamError(f"{what} must be positive semi-definite (a covariance)")
    return as_matrix3(0.5 * (a + a.T))


def quantisation_floor(model: str) -> Matrix3:
    """Covariance of one reading's quantisation, diag over (x, y, θ).

    Create 2: one count q = 0.445 mm per wheel at each end of a record, uniform:
    var(ΔS) = q²/12, var(Δθ) = q²/(3 b²) (and var(ΔS) across, so the matrix is definite).
    Create 1: one unit (1 mm, 1°) per read, uniform: 1/12 unit².
    """
    if model == "create2":
        q = CREATE2_MM_PER_COUNT / 1000.0
        var_s = q * q / 12.0
        var_theta = q * q / (3.0 * WHEEL_BASE_M**2)
    elif model == "create1":
        var_s = 1e-6 / 12.0
        var_theta = math.radians(1.0) ** 2 / 12.0
    else:
        raise FgslamError(f"unknown Create model {model!r}; use create1 or create2")
    return as_matrix3(np.diag([var_s, var_s, var_theta]))


@dataclass(frozen=True)
class OdometryNoise:
    """How uncertain an odometry increment is: Σ = |ΔS|·F + |Δθ|·R + k·Q (module docstring).

    ``forward_per_m`` (F, m²/m, m·rad/m, rad²/m) is the covariance over (x, y, θ) of the
    error per metre driven; ``rotate_per_rad`` (R) per radian turned; ``floor`` (Q) the
    quantisation of one reading. ``source`` says where the numbers came from.
    """

    forward_per_m: Matrix3
    rotate_per_rad: Matrix3
    floor: Matrix3
    source: str = "nominal"

    def __post_init__(self):
        object.__setattr__(self, "forward_per_m", _matrix(self.forward_per_m, "forward_per_m"))
        object.__setattr__(self, "rotate_per_rad", _matrix(self.rotate_per_rad, "rotate_per_rad"))
        floor = _matrix(self.floor, "floor")
        if np.linalg.eigvalsh(np.array(floor)).min() <= 0.0:
            raise FgslamError("floor must be positive definite (every reading has some quantisation)")
        object.__setattr__(self, "floor", floor)

    def covariance(self, distance_m: float, angle_rad: float, readings: int = 1) -> Matrix3:
        """Σ of an increment that drove ``distance_m`` and turned ``angle_rad``."""
        cov = (
            abs(distance_m) * np.array(self.forward_per_m)
            + abs(angle_rad) * np.array(self.rotate_per_rad)
            + max(1, readings) * np.array(self.floor)
        )
        return as_matrix3(0.5 * (cov + cov.T))

    def header_dict(self) -> dict:
        """The ``noise.odometry`` object of a run-log header."""
        return {
            "model": "Sigma = |distance|*forward_per_m + |angle|*rotate_per_rad + readings*floor "
            "over (dx, dy, dtheta); arc model for the increment",
            "forward_per_m": [list(r) for r in self.forward_per_m],
            "rotate_per_rad": [list(r) for r in self.rotate_per_rad],
            "floor": [list(r) for r in self.floor],
            "source": self.source,
        }


#: Nominal, uncalibrated per-metre and per-radian standard deviations (replace them with
#: ``fgslam calibrate``): after 1 m straight, 1 cm along, 1 cm across, 0.03 rad of heading;
#: after 1 rad of turning in place, 2 mm of position and 0.04 rad of heading.
NOMINAL_FORWARD_SIGMA_PER_SQRT_M = (0.01, 0.01, 0.03)
NOMINAL_ROTATE_SIGMA_PER_SQRT_RAD = (0.002, 0.002, 0.04)


def default_noise(model: str) -> OdometryNoise:
    """The nominal :class:`OdometryNoise` for ``create1`` or ``create2``."""
    return OdometryNoise(
        forward_per_m=as_matrix3(np.diag(np.square(NOMINAL_FORWARD_SIGMA_PER_SQRT_M))),
        rotate_per_rad=as_matrix3(np.diag(np.square(NOMINAL_ROTATE_SIGMA_PER_SQRT_RAD))),
        floor=quantisation_floor(model),
        source="nominal (uncalibrated): run fgslam calibrate on measured trials",
    )


# --------------------------------------------------------------------------- records


def odometry_record(stamp_s: float, distance_m: float, angle_rad: float, covariance: Matrix3) -> Odometry:
    """A log record for the Create reading (ΔS, Δθ): arc-model increment + covariance."""
    dx, dy, dtheta = arc_increment(distance_m, angle_rad)
    return Odometry(stamp_s, dx, dy, dtheta, covariance, distance_m, angle_rad)


def integrate_records(records, start_pose=(0.0, 0.0, 0.0)) -> tuple[tuple[float, float, float], float]:
    """Dead reckoning: (final pose, path length in metres = Σ|distance_m|) of odometry records."""
    pose = tuple(start_pose)
    length_m = 0.0
    for r in records:
        if isinstance(r, Odometry):
            pose = compose_pose(pose, (r.dx_m, r.dy_m, r.dtheta_rad))
            length_m += abs(r.distance_m if r.distance_m is not None else math.hypot(r.dx_m, r.dy_m))
    return pose, length_m  # type: ignore[return-value]


class _Accumulator:
    """Sums readings between two records."""

    def __init__(self, noise: OdometryNoise):
        self.noise = noise
        self.distance_m = 0.0
        self.angle_rad = 0.0
        self.readings = 0
        self.extra_var = np.zeros((3, 3))

    def add(self, distance_m: float, angle_rad: float) -> None:
        self.distance_m += distance_m
        self.angle_rad += angle_rad
        self.readings += 1

    def take(self, stamp_s: float) -> Odometry:
        cov = np.array(self.noise.covariance(self.distance_m, self.angle_rad, self.readings)) + self.extra_var
        record = odometry_record(stamp_s, self.distance_m, self.angle_rad, as_matrix3(cov))
        self.distance_m = self.angle_rad = 0.0
        self.readings = 0
        self.extra_var = np.zeros((3, 3))
        return record


class Create2Odometry:
    """Create 2 odometry from encoder counts (packets 43/44), one record per :meth:`take`.

    Feed every accepted frame's counts to :meth:`update`; the first call only sets the
    reference. :meth:`take` returns the record for everything since the previous take.
    """

    model = "create2"

    def __init__(self, noise: OdometryNoise | None = None, wheel_base_m: float = WHEEL_BASE_M,
                 mm_per_count: float = CREATE2_MM_PER_COUNT):
        self.noise = noise or default_noise("create2")
        self.wheel_base_m = wheel_base_m
        self.mm_per_count = mm_per_count
        self._last: tuple[int, int] | None = None
        self._pending = _Accumulator(self.noise)

    def update(self, left_counts: int, right_counts: int) -> tuple[float, float]:
        """Add one reading; returns its (distance_m, angle_rad) (zero for the first)."""
        if self._last is None:
            self._last = (left_counts, right_counts)
            return 0.0, 0.0
        left_m = counts_to_m(counts_delta(left_counts, self._last[0]), self.mm_per_count)
        right_m = counts_to_m(counts_delta(right_counts, self._last[1]), self.mm_per_count)
        self._last = (left_counts, right_counts)
        distance_m, angle_rad = wheel_reading(left_m, right_m, self.wheel_base_m)
        self._pending.add(distance_m, angle_rad)
        return distance_m, angle_rad

    @property
    def started(self) -> bool:
        return self._last is not None

    def take(self, stamp_s: float) -> Odometry:
        """The record of everything read since the previous take (one reading = quantisation once)."""
        self._pending.readings = min(self._pending.readings, 1)  # cumulative counts: quantised once
        return self._pending.take(stamp_s)


class Create1Odometry:
    """Create 1 odometry from packets 19/20 with the 1° truncation workaround.

    Tell it every wheel command (:meth:`command`) and every reading (:meth:`update`, with
    the time it was read); it predicts the motion since the previous read from the
    commands and clamps the prediction into each reading's truncation interval
    (module docstring). :meth:`lost` accounts for a read whose answer never arrived
    (the robot reset its counters anyway): the prediction is used, with a variance of
    10 % of it plus one unit.
    """

    model = "create1"

    def __init__(self, noise: OdometryNoise | None = None, wheel_base_m: float = WHEEL_BASE_M):
        self.noise = noise or default_noise("create1")
        self.wheel_base_m = wheel_base_m
        self._command_mm_s = (0.0, 0.0)  # (left, right)
        self._since_s: float | None = None
        self._predicted_mm = 0.0
        self._predicted_deg = 0.0
        self._pending = _Accumulator(self.noise)
        self.lost_reads = 0

    def _advance(self, stamp_s: float) -> None:
        if self._since_s is not None and stamp_s > self._since_s:
            dt = stamp_s - self._since_s
            left, right = self._command_mm_s
            self._predicted_mm += 0.5 * (left + right) * dt
            self._predicted_deg += math.degrees((right - left) / (1000.0 * self.wheel_base_m) * dt)
        self._since_s = stamp_s if self._since_s is None else max(self._since_s, stamp_s)

    def command(self, left_mm_s: float, right_mm_s: float, stamp_s: float) -> None:
        """The wheel speeds just commanded (mm/s), at ``stamp_s``."""
        self._advance(stamp_s)
        self._command_mm_s = (float(left_mm_s), float(right_mm_s))

    def start(self, stamp_s: float) -> None:
        """The first read (its values are discarded: they hold motion from before the run)."""
        self._advance(stamp_s)
        self._predicted_mm = self._predicted_deg = 0.0

    def unread(self, stamp_s: float) -> tuple[float, float]:
        """(distance_m, angle_rad) predicted from the commands since the last read."""
        self._advance(stamp_s)
        return self._predicted_mm / 1000.0, math.radians(self._predicted_deg)

    def update(self, distance_mm: int, angle_deg: int, stamp_s: float) -> tuple[float, float]:
        """Add the reading taken at ``stamp_s``; returns its corrected (distance_m, angle_rad)."""
        self._advance(stamp_s)
        distance_m = within_reading(self._predicted_mm, distance_mm) / 1000.0
        angle_rad = math.radians(within_reading(self._predicted_deg, angle_deg))
        self._predicted_mm = self._predicted_deg = 0.0
        self._pending.add(distance_m, angle_rad)
        return distance_m, angle_rad

    def lost(self, stamp_s: float) -> tuple[float, float]:
        """A read that was answered wrongly or not at all: use the prediction, inflate Σ."""
        self._advance(stamp_s)
        distance_m = self._predicted_mm / 1000.0
        angle_rad = math.radians(self._predicted_deg)
        self._predicted_mm = self._predicted_deg = 0.0
        self._pending.add(distance_m, angle_rad)
        var_s = (0.1 * distance_m) ** 2 + 1e-6
        var_theta = (0.1 * angle_rad) ** 2 + math.radians(1.0) ** 2
        self._pending.extra_var += np.diag([var_s, var_s, var_theta])
        self.lost_reads += 1
        return distance_m, angle_rad

    def take(self, stamp_s: float) -> Odometry:
        return self._pending.take(stamp_s)
