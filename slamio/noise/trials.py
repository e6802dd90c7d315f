"""Seed 001's trial calibration: noise covariances from measured trials
(``fgslam calibrate TRIALS.csv``).

Not the fit of a noise model against a log's ground truth (:mod:`slamio.noise.fit_truth`,
``fgslam calibrate LOG.jsonl...``), nor the camera's intrinsics (``fgslam calibrate-camera``).

Seed 001 drove its robot forward 30 times and turned it in place 30 times, measured where it
really ended with a tape measure, and took the covariance of the errors in x, y and θ
(``numpy.ma.cov``) as the motion noise R; 15 range/bearing readings against tape-measured
truth gave the measurement noise Q. The paper lists no numbers, so the bundled
``data/calibration_trials_s001.csv`` is **simulated** (:func:`simulated_trials`); measure
your own robot the same way.

Trials file (CSV)
=================

One header line, then one trial per line; blank cells where a column does not apply; lines
starting with ``#`` are comments::

    kind,command_distance_m,command_angle_rad,x_m,y_m,theta_rad,true_range_m,true_bearing_rad,range_m,bearing_rad
    forward,0.5,0,0.497,0.004,0.012,,,,
    rotate,0,1.5708,0.002,-0.001,1.553,,,,
    sensor,,,,,,1.20,0.10,1.23,0.09

``forward`` / ``rotate``: what the robot was told to do (``command_distance_m``,
``command_angle_rad``; for a Create: drive until its odometry says so, as ``fgslam record``
does), and where it really ended (``x_m``, ``y_m``, ``theta_rad``) measured in the frame of
its start pose (x forward, y left, θ counter-clockwise). The error is the measured pose
minus the commanded motion's arc increment (``(d, 0, 0)`` forward, ``(0, 0, a)`` in place).
``sensor``: the landmark's true range and bearing (tape, protractor) and what the sensor
reported.

What comes out
==============

Per kind: the mean error (bias) and the covariance of the errors (N − 1 normalised, like
``numpy.ma.cov``), and the covariance per metre (forward) or per radian (rotate) that
:class:`slamio.create.odometry.OdometryNoise` scales with each increment; the pooled
covariance of all motion errors (seed 001's single R, as written); the sensor's bias,
covariance and standard deviations. :meth:`TrialCalibration.to_dict` is what ``fgslam calibrate
TRIALS.csv --out`` writes and ``fgslam record --calibration`` and ``fgslam run --calibration`` read.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from dataclasses import dataclass

import numpy as np

from slamio.create.odometry import OdometryNoise, quantisation_floor
from slamio.errors import read_text
from slamio.geometry import arc_increment, wrap_angle
from slamio.log import as_matrix3
from slamio.noise.errors import NoiseModelError, NoiseModelFileError
from slamio.safe_input import Document, parse_json, shown

__all__ = [
    "COLUMNS",
    "MotionTrial",
    "SensorTrial",
    "read_trials",
    "motion_errors",
    "TrialCalibration",
    "calibrate_from_trials",
    "load_calibration",
    "calibration_from_dict",
    "simulated_trials",
]

COLUMNS = ("kind", "command_distance_m", "command_angle_rad", "x_m", "y_m", "theta_rad",
           "true_range_m", "true_bearing_rad", "range_m", "bearing_rad")
_NEEDS = {
    "forward": ("command_distance_m", "command_angle_rad", "x_m", "y_m", "theta_rad"),
    "rotate": ("command_distance_m", "command_angle_rad", "x_m", "y_m", "theta_rad"),
    "sensor": ("true_range_m", "true_bearing_rad", "range_m", "bearing_rad"),
}
CALIBRATION_FORMAT = "fgslam-calibration"


@dataclass(frozen=True)
class MotionTrial:
    kind: str  # forward or rotate
    command_distance_m: float
    command_angle_rad: float
    x_m: float
    y_m: float
    theta_rad: float
    line: int


@dataclass(frozen=True)
class SensorTrial:
    true_range_m: float
    true_bearing_rad: float
    range_m: float
    bearing_rad: float
    line: int


#: The largest magnitude of a trial's value (m or rad): a tape-measured trial is a few
#: metres and radians; 1e308 is a corrupted cell (and overflows the covariance).
MAX_TRIAL_VALUE = 1e3


def _number(text: str, where: str, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise NoiseModelFileError(f"{where}: column {column} must be a number, got {shown(text)}") from None
    if not math.isfinite(value):
        raise NoiseModelFileError(f"{where}: column {column} must be finite, got {shown(text)}")
    if abs(value) > MAX_TRIAL_VALUE:
        raise NoiseModelFileError(f"{where}: column {column} is {value!r}, beyond ±{MAX_TRIAL_VALUE:g} (metres or "
                             "radians): write the trial in metres and radians")
    return value


def _cells(text: str, where: str) -> list[str]:
    """The cells of one CSV line; a quoting error or a cell larger than csv's limit is one line."""
    try:
        return [c.strip() for c in next(csv.reader([text]))]
    except csv.Error as exc:
        raise NoiseModelFileError(f"{where}: not a CSV line ({exc}); a trials line is short numbers separated by commas") from None


def read_trials(path: str | os.PathLike[str]) -> tuple[list[MotionTrial], list[SensorTrial]]:
    """Read a trials CSV (module docstring); errors name ``file:line`` and the fix."""
    path = os.fspath(path)
    text = read_text(path, "trials file", "a trials file is UTF-8 CSV text (header "
                     "kind,command_distance_m,...; see fgslam calibrate --help)", NoiseModelFileError)
    numbered = [(i, line) for i, line in enumerate(text.splitlines(), start=1)
                if line.strip() and not line.lstrip().startswith("#")]
    if not numbered:
        raise NoiseModelFileError(f"{path}: no trials; the first line must be the header {','.join(COLUMNS)}")
    header_line, header_text = numbered[0]
    header = _cells(header_text, f"{path}:{header_line}")
    missing = [c for c in ("kind",) if c not in header]
    unknown = [h if len(h) <= 40 else h[:30] + "..." for h in header if h not in COLUMNS]
    if missing or unknown:
        raise NoiseModelFileError(
            f"{path}:{header_line}: the header must name columns from {','.join(COLUMNS)} "
            f"(missing: {', '.join(missing) or 'none'}; unknown: {', '.join(unknown) or 'none'})"
        )
    motion: list[MotionTrial] = []
    sensor: list[SensorTrial] = []
    for number, line in numbered[1:]:
        where = f"{path}:{number}"
        cells = _cells(line, where)
        if len(cells) > len(header):
            raise NoiseModelFileError(f"{where}: {len(cells)} cells but the header has {len(header)} columns")
        row = dict(zip(header, cells + [""] * (len(header) - len(cells))))
        kind = row["kind"]
        if kind not in _NEEDS:
            raise NoiseModelFileError(f"{where}: kind {shown(kind)} is not one of forward, rotate, sensor")
        values = {}
        for column in _NEEDS[kind]:
            if not row.get(column):
                raise NoiseModelFileError(f"{where}: a {kind} trial needs column {column}; fill it in")
            values[column] = _number(row[column], where, column)
        if kind == "sensor":
            if values["true_range_m"] <= 0 or values["range_m"] <= 0:
                raise NoiseModelFileError(f"{where}: ranges must be > 0 m")
            sensor.append(SensorTrial(line=number, **values))
        else:
            if kind == "forward" and values["command_distance_m"] == 0:
                raise NoiseModelFileError(f"{where}: a forward trial needs command_distance_m ≠ 0")
            if kind == "rotate" and values["command_angle_rad"] == 0:
                raise NoiseModelFileError(f"{where}: a rotate trial needs command_angle_rad ≠ 0")
            motion.append(MotionTrial(kind=kind, line=number, **values))
    return motion, sensor


def motion_errors(trials: list[MotionTrial]) -> np.ndarray:
    """(n, 3) errors: measured end pose minus the commanded arc increment (θ wrapped)."""
    out = np.zeros((len(trials), 3))
    for i, t in enumerate(trials):
        dx, dy, dtheta = arc_increment(t.command_distance_m, t.command_angle_rad)
        out[i] = (t.x_m - dx, t.y_m - dy, wrap_angle(t.theta_rad - dtheta))
    return out


def _covariance(errors: np.ndarray) -> np.ndarray:
    """N − 1 normalised covariance of the rows (as numpy.ma.cov with its defaults)."""
    return np.atleast_2d(np.cov(errors, rowvar=False, ddof=1))


def _listed(m: np.ndarray) -> list:
    return np.asarray(m, dtype=float).tolist()


@dataclass(frozen=True)
class TrialCalibration:
    """The result of :func:`calibrate_from_trials` (see the module docstring)."""

    source: str
    forward: dict | None
    rotate: dict | None
    pooled_motion_covariance: list | None
    observation: dict | None

    def odometry_noise(self, model: str) -> OdometryNoise:
        """The recorder's noise model: per-metre and per-radian covariances from the trials."""
        if self.forward is None or self.rotate is None:
            raise NoiseModelError(
                f"{self.source}: needs both forward and rotate trials to make an odometry noise model"
            )
        return OdometryNoise(
            forward_per_m=as_matrix3(self.forward["covariance_per_m"]),
            rotate_per_rad=as_matrix3(self.rotate["covariance_per_rad"]),
            floor=quantisation_floor(model),
            source=f"fgslam calibrate {self.source}",
        )

    def odometry_scales(self) -> dict[str, float]:
        """The odometry's scales the trials measured (``forward_scale`` and ``turn_per_m_rad``
        from forward trials, ``turn_scale`` from turns in place), as
        :class:`slamio.noise.model.OdometryModel` names them: what ``--noise self`` cannot
        learn without truth and holds at these values when a calibration is given."""
        out = {}
        for name, part, fields in (("forward", self.forward, (("scale", "forward_scale"), ("turn_per_m_rad", "turn_per_m_rad"))),
                                   ("rotate", self.rotate, (("scale", "turn_scale"),))):
            if part is None:
                continue
            if "scale" not in part:
                raise NoiseModelError(f"{self.source}: its {name} trials were calibrated before scales were kept; "
                                      "run fgslam calibrate TRIALS.csv --out FILE again")
            out.update({model_name: float(part[key]) for key, model_name in fields})
        return out

    def to_dict(self) -> dict:
        return {
            "format": CALIBRATION_FORMAT,
            "version": 1,
            "source": self.source,
            "forward": self.forward,
            "rotate": self.rotate,
            "pooled_motion_covariance": self.pooled_motion_covariance,
            "observation": self.observation,
        }

    def summary(self) -> str:
        lines = [f"calibration from {self.source}"]
        for name, part, unit in (("forward", self.forward, "m"), ("rotate", self.rotate, "rad")):
            if part is None:
                lines.append(f"  {name}: no trials")
                continue
            sd = np.sqrt(np.diag(part["covariance"]))
            bias = part["bias"]
            lines.append(
                f"  {name}: {part['trials']} trials of {part['mean_command']:.4g} {unit}; "
                f"bias x {bias[0]:+.4f} m, y {bias[1]:+.4f} m, θ {bias[2]:+.4f} rad; "
                f"σ x {sd[0]:.4f} m, y {sd[1]:.4f} m, θ {sd[2]:.4f} rad"
            )
            if "scale" in part:
                lines.append(f"    scale {part['scale']:.4f} ± {part['scale_std']:.4f} (true {unit} per commanded {unit})"
                             + (f", turn per metre {part['turn_per_m_rad']:+.4f} rad/m" if "turn_per_m_rad" in part else ""))
        if self.observation is None:
            lines.append("  sensor: no trials")
        else:
            o = self.observation
            lines.append(
                f"  sensor: {o['trials']} readings; bias range {o['bias'][0]:+.4f} m, bearing {o['bias'][1]:+.4f} rad; "
                f"σ range {o['sigma_range_m']:.4f} m, bearing {o['sigma_bearing_rad']:.4f} rad"
            )
        return "\n".join(lines)


def _motion_part(trials: list[MotionTrial], kind: str, where: str) -> dict | None:
    chosen = [t for t in trials if t.kind == kind]
    if not chosen:
        return None
    if len(chosen) < 2:
        raise NoiseModelError(f"{where}: one {kind} trial cannot give a covariance; measure at least 2 (seed 001: 30)")
    errors = motion_errors(chosen)
    cov = _covariance(errors)
    amount = [abs(t.command_distance_m) if kind == "forward" else abs(t.command_angle_rad) for t in chosen]
    mean_command = float(np.mean(amount))
    per = "covariance_per_m" if kind == "forward" else "covariance_per_rad"
    return {
        "trials": len(chosen),
        "mean_command": mean_command,
        "bias": _listed(errors.mean(axis=0)),
        "covariance": _listed(cov),
        per: _listed(cov / mean_command),
        **_scales(chosen, errors, kind),
    }


def _scales(trials: list[MotionTrial], errors: np.ndarray, kind: str) -> dict:
    """The odometry's scale of one kind of trial (true travel or turn per commanded metre or
    radian, ``1 + Σ sign·error / Σ |command|``, with the standard error of the trials' own
    ratios) and, from forward trials, the turn per metre driven (least squares of the θ
    errors on the distances): what :class:`slamio.noise.model.OdometryModel` calls
    ``forward_scale`` / ``turn_scale`` and ``turn_per_m_rad``."""
    command = np.array([t.command_distance_m if kind == "forward" else t.command_angle_rad for t in trials])
    along = errors[:, 0] if kind == "forward" else errors[:, 2]
    ratios = 1.0 + np.sign(command) * along / np.maximum(np.abs(command), 1e-12)
    out = {"scale": float(1.0 + np.sum(np.sign(command) * along) / np.sum(np.abs(command))),
           "scale_std": float(np.std(ratios, ddof=1) / math.sqrt(len(trials)))}
    if kind == "forward":
        out["turn_per_m_rad"] = float(np.sum(errors[:, 2] * command) / np.sum(command**2))
    return out


def calibrate_from_trials(motion: list[MotionTrial], sensor: list[SensorTrial],
                          source: str = "trials") -> TrialCalibration:
    """Biases and covariances of the trials (module docstring)."""
    if not motion and not sensor:
        raise NoiseModelError(f"{source}: no trials to calibrate from")
    pooled = _listed(_covariance(motion_errors(motion))) if len(motion) >= 2 else None
    observation = None
    if sensor:
        if len(sensor) < 2:
            raise NoiseModelError(f"{source}: one sensor reading cannot give a covariance; take at least 2 (seed 001: 15)")
        e = np.array([(s.range_m - s.true_range_m, wrap_angle(s.bearing_rad - s.true_bearing_rad)) for s in sensor])
        cov = _covariance(e)
        observation = {
            "trials": len(sensor),
            "bias": _listed(e.mean(axis=0)),
            "covariance": _listed(cov),
            "sigma_range_m": float(math.sqrt(cov[0, 0])),
            "sigma_bearing_rad": float(math.sqrt(cov[1, 1])),
        }
    return TrialCalibration(
        source=source,
        forward=_motion_part(motion, "forward", source),
        rotate=_motion_part(motion, "rotate", source),
        pooled_motion_covariance=pooled,
        observation=observation,
    )


_FIX = "write it with fgslam calibrate TRIALS.csv --out FILE"
_MOTION_KEYS = {"forward": "covariance_per_m", "rotate": "covariance_per_rad"}


class _Bad(Exception):
    """What is wrong with one part of a calibration (:func:`calibration_from_dict` adds where
    and how to fix it); ``key`` names the field, ``forward.covariance[0][1]``."""

    def __init__(self, message: str, key: str = ""):
        super().__init__(message)
        self.key = key


#: The largest magnitude of a number in a calibration (covariances in m², rad², biases):
#: far beyond any robot's, and far from overflow when squared.
MAX_CALIBRATION_VALUE = 1e6


def _finite(key: str, value, minimum: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not abs(value) <= MAX_CALIBRATION_VALUE:
        shown = f"an integer of {len(str(abs(value)))} digits" if isinstance(value, int) and abs(value) > 1e18 else repr(value)
        raise _Bad(f"{key} must be a finite number within ±{MAX_CALIBRATION_VALUE:g}, got {shown}", key)
    if minimum is not None and value < minimum:
        raise _Bad(f"{key} must be >= {minimum:g}, got {value!r}", key)
    return float(value)


def _keys(key: str) -> tuple:
    """``"forward.covariance[0][1]"`` → ``("forward", "covariance", 0, 1)``."""
    import re

    return tuple(int(k[1:-1]) if k.startswith("[") else k for k in re.findall(r"\[\d+\]|[^.\[\]]+", key))


def _vector(key: str, value, n: int) -> None:
    if not isinstance(value, list) or len(value) != n:
        raise _Bad(f"{key} must be a list of {n} numbers, got {_short(value)}", key)
    for i, v in enumerate(value):
        _finite(f"{key}[{i}]", v)


def _covariance_matrix(key: str, value, n: int) -> None:
    """A finite, symmetric n×n list of lists with no negative eigenvalue (a covariance)."""
    if (not isinstance(value, list) or len(value) != n
            or not all(isinstance(row, list) and len(row) == n for row in value)):
        raise _Bad(f"{key} must be a {n}×{n} matrix (a list of {n} lists of {n} numbers), got {_short(value)}", key)
    for i, row in enumerate(value):
        for j, v in enumerate(row):
            _finite(f"{key}[{i}][{j}]", v)
    m = np.array(value, dtype=float)
    scale = max(1.0, float(np.max(np.abs(m))))
    if not np.allclose(m, m.T, rtol=1e-9, atol=1e-12 * scale):
        raise _Bad(f"{key} is not symmetric, so it is not a covariance", key)
    if float(np.min(np.linalg.eigvalsh(m))) < -1e-9 * scale:
        raise _Bad(f"{key} has a negative eigenvalue, so it is not a covariance", key)


def _part(d: dict, name: str, keys: tuple[str, ...]) -> dict | None:
    part = d.get(name)
    if part is None:
        return None
    if not isinstance(part, dict):
        raise _Bad(f"{name} must be null or an object with {', '.join(keys)}, got {_short(part)}", name)
    missing = [k for k in keys if k not in part]
    if missing:
        raise _Bad(f"{name} lacks {', '.join(missing)}", name)
    trials = part["trials"]
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 2:
        raise _Bad(f"{name}.trials must be a whole number >= 2, got {_short(trials)}", f"{name}.trials")
    return part


def _check_calibration(d) -> None:
    if not isinstance(d, dict):
        raise _Bad(f"a calibration must be a JSON object, got {type(d).__name__}")
    for name, per in _MOTION_KEYS.items():
        part = _part(d, name, ("trials", "mean_command", "bias", "covariance", per))
        if part is not None:
            if not _finite(f"{name}.mean_command", part["mean_command"]) > 0:
                raise _Bad(f"{name}.mean_command must be > 0, got {part['mean_command']!r}", f"{name}.mean_command")
            _vector(f"{name}.bias", part["bias"], 3)
            _covariance_matrix(f"{name}.covariance", part["covariance"], 3)
            _covariance_matrix(f"{name}.{per}", part[per], 3)
            for key in ("scale", "scale_std", "turn_per_m_rad"):
                if key in part:
                    value = _finite(f"{name}.{key}", part[key])
                    if key == "scale" and not value > 0:
                        raise _Bad(f"{name}.scale must be > 0, got {part[key]!r}", f"{name}.scale")
    if d.get("pooled_motion_covariance") is not None:
        _covariance_matrix("pooled_motion_covariance", d["pooled_motion_covariance"], 3)
    sensor = _part(d, "observation", ("trials", "bias", "covariance", "sigma_range_m", "sigma_bearing_rad"))
    if sensor is not None:
        _vector("observation.bias", sensor["bias"], 2)
        _covariance_matrix("observation.covariance", sensor["covariance"], 2)
        _finite("observation.sigma_range_m", sensor["sigma_range_m"], 0.0)
        _finite("observation.sigma_bearing_rad", sensor["sigma_bearing_rad"], 0.0)
    parts = ("forward", "rotate", "pooled_motion_covariance", "observation")
    if all(d.get(name) is None for name in parts):
        raise _Bad(f"holds no calibration ({', '.join(parts)} are all missing or null)")


def _short(value) -> str:
    """A JSON value for a message, at most 60 characters."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError, RecursionError):
        text = repr(type(value).__name__)
    return text if len(text) <= 60 else text[:57] + "..."


def calibration_from_dict(d, where: str, fix: str = _FIX, doc: Document | None = None) -> TrialCalibration:
    """A :class:`TrialCalibration` from what :meth:`TrialCalibration.to_dict` wrote, every part
    checked (types, shapes, finite numbers within ±:data:`MAX_CALIBRATION_VALUE`, covariances, at
    least one part): a bad one is one :class:`NoiseModelError` line ``"{where}: what is wrong;
    {fix}"`` (``where``: the file, or where in a log it came from); with ``doc`` (the file
    it was read from), a :class:`NoiseModelFileError` ``"file:line: field 'k' ..."``."""
    try:
        _check_calibration(d)
    except _Bad as exc:
        if doc is not None:
            raise NoiseModelFileError(f"{doc.where(*_keys(exc.key))}: {exc}; {fix}") from None
        raise NoiseModelError(f"{where}: {exc}; {fix}") from None
    source = d.get("source")
    return TrialCalibration(source if isinstance(source, str) and source else where, d.get("forward"), d.get("rotate"),
                       d.get("pooled_motion_covariance"), d.get("observation"))


def load_calibration(path: str | os.PathLike[str]) -> TrialCalibration:
    """Read what ``fgslam calibrate TRIALS.csv --out`` wrote; a file that is not one, or one whose
    parts are not what it writes, is one :class:`NoiseModelError` line naming the file."""
    path = os.fspath(path)
    text = read_text(path, "calibration", f"a calibration file is UTF-8 JSON ({_FIX})", NoiseModelFileError)
    doc = parse_json(path, text, error=NoiseModelFileError, fix=_FIX)  # file:line errors; no FIFO, deep nesting, NaN or 1e400
    d = doc.data
    if not isinstance(d, dict) or d.get("format") != CALIBRATION_FORMAT:
        raise NoiseModelFileError(f"{path}: not a calibration file (no \"format\": \"{CALIBRATION_FORMAT}\"); {_FIX}")
    return calibration_from_dict(d, path, doc=doc)


# --------------------------------------------------------------------------- example data


def simulated_trials(seed: int = 1) -> str:
    """A stand-in for seed 001's trials (the paper gives none): 30 forward, 30 rotate, 15 sensor.

    Forward 0.5 m: x error N(−4 mm, 5 mm), heading error N(+0.005, 0.02) rad and a sideways
    error 0.25 m × heading error + N(0, 4 mm) (a heading error made along the way); rotate
    90°: x, y N(0, 3 mm), θ N(−0.02, 0.03) rad; sensor at 0.5–2.5 m, ±0.5 rad: range
    N(+1 cm, 2 cm), bearing N(0, 0.02) rad. Rounded to mm and mrad, as read off a tape.
    """
    rng = np.random.default_rng(seed)
    out = io.StringIO()
    out.write(
        "# SIMULATED stand-in for seed 001's 30 forward + 30 rotate calibration trials and 15 sensor\n"
        "# readings: the paper lists no numbers. Made by slamio.noise.trials.simulated_trials"
        f"(seed={seed}).\n"
        "# Replace with your own robot's tape-measured trials (layout: docs/create.md).\n"
    )
    out.write(",".join(COLUMNS) + "\n")
    for _ in range(30):
        theta = 0.005 + 0.02 * rng.standard_normal()
        x = 0.5 - 0.004 + 0.005 * rng.standard_normal()
        y = 0.25 * theta + 0.004 * rng.standard_normal()
        out.write(f"forward,0.5,0,{x:.3f},{y:.3f},{theta:.3f},,,,\n")
    quarter = math.pi / 2
    for _ in range(30):
        x, y = 0.003 * rng.standard_normal(2)
        theta = quarter - 0.02 + 0.03 * rng.standard_normal()
        out.write(f"rotate,0,{quarter:.4f},{x:.3f},{y:.3f},{theta:.3f},,,,\n")
    for _ in range(15):
        true_range = rng.uniform(0.5, 2.5)
        true_bearing = rng.uniform(-0.5, 0.5)
        range_m = true_range + 0.01 + 0.02 * rng.standard_normal()
        bearing = true_bearing + 0.02 * rng.standard_normal()
        out.write(f"sensor,,,,,,{true_range:.3f},{true_bearing:.3f},{range_m:.3f},{bearing:.3f}\n")
    return out.getvalue()
