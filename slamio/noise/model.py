"""The noise model a log states: what ``fgslam calibrate LOG...`` writes and ``--noise`` reads.

A :class:`NoiseModel` says how a robot's odometry and its camera's range-bearing readings
relate to the truth, in terms with a physical meaning, so that the same file can be used
on another run of the same robot (``fgslam import mrclam --noise FILE``,
``fgslam run --noise FILE``):

Odometry (:class:`OdometryModel`)
    ``lag_s``: the robot moves ``lag_s`` after the odometry says it did (commanded
    velocities lead the motion: the command reaches the wheels and the motors accelerate).
    ``forward_scale`` / ``turn_scale``: true travel and turn per odometry metre and radian
    (wheel radius and wheel-base errors, or a robot that does not reach its commanded
    speed). ``turn_per_m_rad``: the turn per metre driven that the odometry does not see
    (wheels of slightly different diameter make a robot told to go straight curve), so the
    true turn rate is ``turn_scale·ω + turn_per_m_rad·forward_scale·v``. ``noise``: the per-stretch variance rates of :class:`OdometryNoiseRates`
    (variance per metre driven, per radian turned and per second).

Observations (:class:`ObservationModel`)
    ``range_is_depth``: the camera's "range" is the distance along its optical axis (what
    a stereo or size-based range from a forward camera measures), ``r·cos(bearing)``,
    not the Euclidean range. ``range_scale`` and ``range_bias_m``:
    ``measured = range_scale · (r or r·cos b) + range_bias_m``. ``bearing_scale`` and
    ``bearing_bias_rad``: ``measured = bearing_scale · b + bearing_bias_rad`` (a focal
    length or principal point that is slightly off). σ_range grows with range,
    ``√(range_sigma_m² + (range_sigma_per_m · r)²)`` (a pixel error of the landmark's image
    size costs range in proportion to range); σ_bearing grows with the turn rate,
    ``√(bearing_sigma_rad² + (bearing_sigma_s · ω)²)`` (motion blur and a jittery image
    time: a picture taken δ seconds away from its stamp sees the world turned by ω·δ).
    ``camera_latency_s``: a reading is stamped that long after its picture was taken.
    ``outlier_rate``: the share of readings beyond the fit's 5σ gate (misread barcodes,
    reflections); estimators should down-weight or gate them.
    ``sensor_pose_on_robot``: ``[x_m, y_m, yaw_rad]``, where the sensor sits on the robot
    (:mod:`slamio.noise.mount_fit`); applying the model states it in the log header's
    ``sensor.pose_on_robot`` (absent: the log's own header stands).
    ``correlated_share`` and ``correlation_time_s``: a reading's error is not independent of
    the last reading of the same landmark. Of each reading's variance, the share ρ =
    ``correlated_share`` is a Gauss–Markov error per landmark (normalised by the reading's
    σ, its correlation decays as ``exp(−Δt / correlation_time_s)``), the rest is white. (A
    camera seeing the same barcode from nearly the same place makes nearly the same error:
    on MRCLAM ρ ≈ 0.7 and τ ≈ 17 s.) 0 means white readings; :mod:`ekf.reading_error` says
    how the EKF uses it.

This module holds the model and its JSON file (:func:`load_noise_model`,
:func:`save_noise_model`); it is fitted from ground truth by :mod:`slamio.noise.fit_truth`
and applied by :mod:`slamio.noise.apply` (:func:`~slamio.noise.apply.correct_observation`
turns a reading into the Euclidean range and bearing the estimators expect, with its own
σ). All functions but the file's are pure.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from slamio.errors import read_text
from slamio.log.fields import SIGMA_ANGLE_RAD, SIGMA_LENGTH_M
from slamio.noise.errors import NoiseModelError, NoiseModelFileError
from slamio.safe_input import Document, parse_json

__all__ = [
    "NOISE_MODEL_FORMAT",
    "NoiseModel",
    "ObservationModel",
    "OdometryModel",
    "OdometryNoiseRates",
    "carries_fitted_model",
    "load_noise_model",
    "noise_expects_outliers",
    "save_noise_model",
]

NOISE_MODEL_FORMAT = "fgslam-noise-model"
NOISE_MODEL_VERSION = 1


#: The largest magnitude of any number in a noise model: a robot's model needs none larger,
#: and every square and product the estimators take of them stays far from overflow.
MAX_MODEL_VALUE = 1e6
#: Scales (``forward_scale``, ``range_scale``, ...): a model divides by them.
SCALE_BOUNDS = (1e-3, 1e3)


def _check_finite(owner: str, name: str, value: Any, *, positive: bool = False, non_negative: bool = False,
                  bounds: tuple[float, float] | None = None) -> None:
    keys = tuple(owner.split(".")) + (name,)

    def bad(rule: str) -> NoiseModelError:
        shown = f"an integer of {len(str(abs(value)))} digits" if isinstance(value, int) and abs(value) > 1e18 else repr(value)
        return NoiseModelError(f"{owner}.{name} must be {rule}, got {shown}", keys)

    if isinstance(value, bool) or not isinstance(value, (int, float)) or not abs(value) <= MAX_MODEL_VALUE:
        raise bad(f"a finite number within ±{MAX_MODEL_VALUE:g}")
    if positive and not value > 0.0:
        raise bad("> 0")
    if non_negative and not value >= 0.0:
        raise bad(">= 0")
    if bounds is not None and not bounds[0] <= value <= bounds[1]:
        raise bad(f"within {bounds[0]:g}..{bounds[1]:g}")


@dataclass(frozen=True)
class OdometryNoiseRates:
    """Variance rates of one stretch of odometry, in the frame at its start.

    forward ``forward_m2_per_m·|Δs| + forward_m2_per_s·dt``, sideways
    ``lateral_m2_per_m·|Δs| + lateral_m2_per_s·dt``, heading
    ``heading_rad2_per_rad·|Δθ| + heading_rad2_per_m·|Δs| + heading_rad2_per_s·dt``.
    The per-second terms must be > 0 (they keep a standing robot's covariance positive
    definite). The defaults are round numbers, not fitted to any robot: σ ≈ 0.1 m forward,
    0.05 m sideways and 0.05 rad of heading per metre driven, 0.1 rad per radian turned, and
    1 mm / 1 mrad per second standing still.
    """

    forward_m2_per_m: float = 0.01
    lateral_m2_per_m: float = 0.0025
    heading_rad2_per_rad: float = 0.01
    heading_rad2_per_m: float = 0.0025
    forward_m2_per_s: float = 1e-6
    lateral_m2_per_s: float = 1e-6
    heading_rad2_per_s: float = 1e-6

    def __post_init__(self) -> None:
        for f in fields(self):
            _check_finite("odometry.noise", f.name, getattr(self, f.name), non_negative=True)
        for name in ("forward_m2_per_s", "lateral_m2_per_s", "heading_rad2_per_s"):
            if not getattr(self, name) > 0.0:
                raise NoiseModelError(
                    f"odometry.noise.{name} must be > 0: it keeps the covariance positive definite "
                    "when the robot stands still", ("odometry", "noise", name)
                )

    def stretch_covariance(self, distance_m: float, angle_rad: float, dt_s: float) -> np.ndarray:
        """3×3 diagonal covariance over (dx, dy, dθ) of one stretch, in the frame at its start."""
        s, a = abs(distance_m), abs(angle_rad)
        return np.diag(
            [
                self.forward_m2_per_m * s + self.forward_m2_per_s * dt_s,
                self.lateral_m2_per_m * s + self.lateral_m2_per_s * dt_s,
                self.heading_rad2_per_rad * a + self.heading_rad2_per_m * s + self.heading_rad2_per_s * dt_s,
            ]
        )


@dataclass(frozen=True)
class OdometryModel:
    """How the odometry relates to the motion (see the module docstring)."""

    lag_s: float = 0.0
    forward_scale: float = 1.0
    turn_scale: float = 1.0
    turn_per_m_rad: float = 0.0
    noise: OdometryNoiseRates = field(default_factory=OdometryNoiseRates)

    def __post_init__(self) -> None:
        _check_finite("odometry", "lag_s", self.lag_s)
        if abs(self.lag_s) > 5.0:
            raise NoiseModelError(f"odometry.lag_s must be within ±5 s, got {self.lag_s!r}", ("odometry", "lag_s"))
        for name in ("forward_scale", "turn_scale"):
            _check_finite("odometry", name, getattr(self, name), positive=True, bounds=SCALE_BOUNDS)
        _check_finite("odometry", "turn_per_m_rad", self.turn_per_m_rad)


@dataclass(frozen=True)
class ObservationModel:
    """How the camera's range-bearing readings relate to the truth (module docstring)."""

    range_is_depth: bool = False
    range_scale: float = 1.0
    range_bias_m: float = 0.0
    range_sigma_m: float = 0.1
    range_sigma_per_m: float = 0.0
    bearing_scale: float = 1.0
    bearing_bias_rad: float = 0.0
    bearing_sigma_rad: float = 0.05
    bearing_sigma_s: float = 0.0
    camera_latency_s: float = 0.0
    outlier_rate: float = 0.0
    correlated_share: float = 0.0
    correlation_time_s: float = 0.0
    sensor_pose_on_robot: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.sensor_pose_on_robot is not None:
            from slamio.log.mount import checked_mount

            try:
                mount = checked_mount(self.sensor_pose_on_robot, "observation.sensor_pose_on_robot")
            except ValueError as exc:
                raise NoiseModelError(str(exc), ("observation", "sensor_pose_on_robot")) from None
            object.__setattr__(self, "sensor_pose_on_robot", mount)
        if not isinstance(self.range_is_depth, bool):
            raise NoiseModelError(f"observation.range_is_depth must be true or false, got {self.range_is_depth!r}",
                                  ("observation", "range_is_depth"))
        for name, bounds in (("range_scale", SCALE_BOUNDS), ("bearing_scale", SCALE_BOUNDS),
                             ("range_sigma_m", SIGMA_LENGTH_M), ("bearing_sigma_rad", SIGMA_ANGLE_RAD)):
            _check_finite("observation", name, getattr(self, name), positive=True, bounds=bounds)
        for name in ("range_sigma_per_m", "bearing_sigma_s", "outlier_rate"):
            _check_finite("observation", name, getattr(self, name), non_negative=True)
        for name in ("range_bias_m", "bearing_bias_rad", "camera_latency_s"):
            _check_finite("observation", name, getattr(self, name))
        if self.outlier_rate >= 1.0:
            raise NoiseModelError(f"observation.outlier_rate must be below 1, got {self.outlier_rate!r}",
                                  ("observation", "outlier_rate"))
        if abs(self.camera_latency_s) > 5.0:
            raise NoiseModelError(f"observation.camera_latency_s must be within ±5 s, got {self.camera_latency_s!r}",
                                  ("observation", "camera_latency_s"))
        for name in ("correlated_share", "correlation_time_s"):
            _check_finite("observation", name, getattr(self, name), non_negative=True)
        if self.correlated_share >= 1.0:
            raise NoiseModelError(
                f"observation.correlated_share must be below 1 (some of each reading's error is white), "
                f"got {self.correlated_share!r}", ("observation", "correlated_share")
            )
        if self.correlated_share > 0.0 and not self.correlation_time_s > 0.0:
            raise NoiseModelError(
                "observation.correlation_time_s must be > 0 when correlated_share is above 0, "
                f"got {self.correlation_time_s!r}", ("observation", "correlation_time_s")
            )

    def sigma_range_m(self, range_m: float) -> float:
        """σ of a range at ``range_m`` metres."""
        return math.hypot(self.range_sigma_m, self.range_sigma_per_m * range_m)

    def sigma_bearing_rad(self, turn_rate_radps: float) -> float:
        """σ of a bearing taken while the robot turns at ``turn_rate_radps``."""
        return math.hypot(self.bearing_sigma_rad, self.bearing_sigma_s * turn_rate_radps)


@dataclass(frozen=True)
class NoiseModel:
    """Odometry and observation models plus where they were fitted (``fitted_on``)."""

    odometry: OdometryModel = field(default_factory=OdometryModel)
    observation: ObservationModel = field(default_factory=ObservationModel)
    fitted_on: tuple[str, ...] = ()
    fit_report: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": NOISE_MODEL_FORMAT,
            "version": NOISE_MODEL_VERSION,
            "odometry": asdict(self.odometry),
            "observation": asdict(self.observation),
            "fitted_on": list(self.fitted_on),
            "fit_report": self.fit_report,
        }

    @property
    def odometry_fitted(self) -> bool:
        """False when the odometry part is the defaults, not a fit: ``fgslam calibrate`` on a
        truth without heading (GPS) fits only the range model (``fit_report["odometry"]``
        says ``not_fitted``). Such a model can correct range-only readings, nothing else."""
        odometry = self.fit_report.get("odometry") if isinstance(self.fit_report, dict) else None
        return not (isinstance(odometry, dict) and "not_fitted" in odometry)


def carries_fitted_model(noise: dict) -> bool:
    """True when a log header's ``noise`` says a fitted model was applied (by an importer's
    ``--noise`` or by :func:`slamio.noise.apply.apply_noise_model`)."""
    observation = noise.get("observation", {})
    return ("fitted_on" in noise or "lag_s" in noise.get("odometry", {})
            or (isinstance(observation, dict) and "fitted_on" in observation))  # a range model (Plaza's import)


def log_expects_outliers(header: Any) -> bool:
    """Whether a log says some readings are outliers: a fitted noise model's
    ``noise.observation.outlier_rate`` > 0 (``fgslam calibrate``), or a simulator's
    ``source.outliers`` > 0 (``fgslam sim --outliers``). The EKF then gates readings with
    an id and the default iSAM2 takes a robust kernel."""
    source = header.source.get("outliers") if isinstance(header.source, dict) else None
    simulated = isinstance(source, (int, float)) and not isinstance(source, bool) and source > 0
    return simulated or noise_expects_outliers(header.noise)


def noise_expects_outliers(noise: Any) -> bool:
    """Whether a log header's ``noise`` carries a fitted outlier rate above zero
    (``noise.observation.outlier_rate``, from ``fgslam calibrate``)."""
    observation = noise.get("observation") if isinstance(noise, dict) else None
    rate = observation.get("outlier_rate") if isinstance(observation, dict) else None
    return isinstance(rate, (int, float)) and not isinstance(rate, bool) and rate > 0


# --------------------------------------------------------------------------- the file


def _build(cls, data: Any, where: str, fail, nested: dict[str, Any] | None = None):
    keys = tuple(where.split("."))
    if not isinstance(data, dict):
        raise fail(f"{where} must be a JSON object, got {type(data).__name__}", keys)
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise fail(f"{where} has unknown field(s) {', '.join(unknown)}; known: {', '.join(sorted(names))}",
                   keys + (unknown[0],))
    kwargs = dict(data)
    for key, sub in (nested or {}).items():
        if key in kwargs:
            kwargs[key] = _build(sub, kwargs[key], f"{where}.{key}", fail)
    try:
        return cls(**kwargs)
    except NoiseModelError as exc:
        raise fail(str(exc), exc.field) from None


def noise_model_from_dict(data: Any, path: str = "<noise model>", doc: Document | None = None) -> NoiseModel:
    """Parse the JSON object written by :func:`save_noise_model`; errors name the field
    (``path: ...``, or with ``doc``, the file it was read from, ``file:line: ...`` as a
    :class:`NoiseModelFileError`)."""

    def fail(message: str, keys: tuple = ()) -> NoiseModelError:
        if doc is None:
            return NoiseModelError(f"{path}: {message}", keys)
        return NoiseModelFileError(f"{doc.where(*keys)}: {message}", keys)

    if not isinstance(data, dict) or data.get("format") != NOISE_MODEL_FORMAT:
        raise fail(
            f"not an fgslam noise model (expected a JSON object with \"format\": "
            f"\"{NOISE_MODEL_FORMAT}\"; make one with fgslam calibrate LOG... --out FILE)"
        )
    unknown = sorted(set(data) - {"format", "version", "odometry", "observation", "fitted_on", "fit_report"})
    if unknown:
        raise fail(
            f"unknown field(s) {', '.join(unknown)}; known: format, version, odometry, observation, "
            "fitted_on, fit_report", (unknown[0],)
        )
    version = data.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or version != NOISE_MODEL_VERSION:
        raise fail(f"noise-model version {version!r}; this fgslam reads version {NOISE_MODEL_VERSION}", ("version",))
    odometry = _build(OdometryModel, data.get("odometry", {}), "odometry", fail, {"noise": OdometryNoiseRates})
    observation = _build(ObservationModel, data.get("observation", {}), "observation", fail)
    fitted_on = data.get("fitted_on", [])
    if not isinstance(fitted_on, list) or not all(isinstance(s, str) for s in fitted_on):
        raise fail("fitted_on must be a list of strings", ("fitted_on",))
    report = data.get("fit_report", {})
    if not isinstance(report, dict):
        raise fail("fit_report must be a JSON object", ("fit_report",))
    return NoiseModel(odometry, observation, tuple(fitted_on), report)


_MAKE_ONE = "make a noise model with fgslam calibrate LOG... --out noise.json"


def load_noise_model(path: str | os.PathLike[str]) -> NoiseModel:
    """Read a noise-model file; every problem is one :class:`NoiseModelFileError` line
    (``file:line: ...`` naming the field; :mod:`slamio.safe_input` refuses a FIFO, a device,
    a huge file, deep nesting and numbers no model holds). A run log given instead is a
    plain :class:`NoiseModelError`: a mistake in the command, not a bad file."""
    path = os.fspath(path)
    if not os.path.lexists(path):
        raise NoiseModelFileError(f"{path}: no such noise-model file (make one with fgslam calibrate LOG... --out {path})")
    text = read_text(path, "noise-model file", f"a noise model is UTF-8 JSON ({_MAKE_ONE})", NoiseModelFileError)
    try:
        doc = parse_json(path, text, error=NoiseModelFileError, fix=_MAKE_ONE)
    except NoiseModelFileError:
        if _is_run_log(text):
            raise NoiseModelError(f"{path} is a run log, not a noise model; make a noise model from logs with ground "
                                  f"truth with fgslam calibrate LOG... --out noise.json") from None
        raise
    return noise_model_from_dict(doc.data, path, doc)


def _is_run_log(text: str) -> bool:
    """Whether ``text`` starts like a run log (a first line that is the JSON header record)."""
    try:
        first = json.loads(text.split("\n", 1)[0])
    except (ValueError, RecursionError):
        return False
    return isinstance(first, dict) and first.get("type") == "header"


def save_noise_model(path: str | os.PathLike[str], model: NoiseModel, *, overwrite: bool = False) -> None:
    """Write ``model`` as JSON; refuses to replace an existing file unless ``overwrite``."""
    path = os.fspath(path)
    mode = "w" if overwrite else "x"
    try:
        with open(path, mode, encoding="utf-8") as f:
            json.dump(model.to_dict(), f, indent=2)
            f.write("\n")
    except FileExistsError:
        raise NoiseModelError(f"{path} exists; choose another --out or delete it first") from None
    except OSError as exc:
        raise NoiseModelError(f"{path}: cannot write ({exc.strerror})") from None
