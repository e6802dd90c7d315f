"""Apply a :class:`~slamio.noise.model.NoiseModel` to readings and to a written log.

:func:`correct_observation` and :func:`correct_range` turn one raw reading into what the
estimators expect (importers that still have the raw data call them: ``fgslam import
mrclam|plaza1|plaza2 --noise FILE``); :func:`apply_noise_model` re-reads a whole log.
Nothing here depends on how the model was fitted.

Applying a model to a log that is already written (``fgslam run LOG --noise FILE``): an
importer that still has the raw data applies the model itself, exactly (``fgslam import
mrclam --noise FILE``: the commands are delayed and scaled before they are integrated).
Here only the log is left, so:

* **odometry**: the log's increments are composed into a chain readable at any time
  (:class:`~slamio.noise.dead_reckoning.DeadReckoning`, constant velocity within an
  increment); the increment of step k becomes the chain's motion from ``t_{k−1} − lag_s`` to
  ``t_k − lag_s``, scaled (``forward_scale`` on x and y, ``turn_scale`` on θ plus
  ``turn_per_m_rad`` times the distance), with the covariance of the model's variance rates
  over that distance, turn and duration (one stretch, diagonal in its start frame);
* **observations**: each reading is corrected by
  :func:`correct_observation` with the turn rate of the (delayed)
  odometry at its time; one that cannot be corrected is dropped and counted.
  ``camera_latency_s`` is not applied (the reading stays with its pose; at the fitted
  0.03 s the difference is a few millimetres); a range-only reading (a ranging radio) by
  :func:`correct_range`;
* the **sensor's mount**: a model fitted with one (``sensor_pose_on_robot``) states it in the
  header's ``sensor.pose_on_robot`` (the header's own, if any, kept as ``pose_on_robot_stated``);
* a **range-only log** (every reading a range, e.g. Plaza) gets the range model only and
  keeps its odometry, as ``fgslam import plaza1|plaza2 --noise`` does: the truth such logs
  are calibrated against has no measured heading (Plaza's GPS heading is its dead-reckoned
  one), so a model fitted on one has a heading variance of nothing (1e-30 rad² per rad), and
  applying it made the filters certain of a heading they do not know (Plaza2: ATE 0.76 →
  5.99 m for the EKF);
* the header's ``noise`` says the model was applied, so ``fgslam calibrate`` refuses the
  result, as it refuses a log imported with ``--noise``.

All pure: :func:`apply_noise_model` takes a :class:`~slamio.log.RunLog` and returns a new one.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict

import numpy as np

from slamio.log import Observation, Odometry, RunLog, as_matrix3
from slamio.noise.dead_reckoning import DeadReckoning, odometry_arrays, turn_rate_radps
from slamio.noise.errors import NoiseModelError
from slamio.noise.model import NoiseModel, ObservationModel, carries_fitted_model

__all__ = ["apply_noise_model", "correct_observation", "correct_range", "sensor_with_mount"]


def correct_observation(
    model: ObservationModel, range_m: float, bearing_rad: float, turn_rate_radps: float
) -> tuple[float, float, float, float]:
    """A raw reading as the Euclidean ``(range_m, bearing_rad, σ_range_m, σ_bearing_rad)``.

    The model's σ describe the raw reading, so they are divided by the scales. Inverts
    ``measured_bearing = bearing_scale·b + bearing_bias_rad`` and
    ``measured_range = range_scale·(r·cos b if range_is_depth else r) + range_bias_m``.
    A depth reading at |b| ≥ 80° cannot be turned into a range reliably and raises
    :class:`NoiseModelError` (no forward camera sees that far aside).
    """
    bearing = (bearing_rad - model.bearing_bias_rad) / model.bearing_scale
    along = (range_m - model.range_bias_m) / model.range_scale
    if model.range_is_depth:
        c = math.cos(bearing)
        if c < math.cos(math.radians(80.0)):
            raise NoiseModelError(f"a depth reading at bearing {bearing:.3f} rad cannot be turned into a range")
        range_corrected = along / c
    else:
        range_corrected = along
    if not range_corrected > 0.0:
        raise NoiseModelError(f"reading {range_m!r} m corrects to a non-positive range {range_corrected!r} m")
    # the model's σ are of the raw reading; the correction divides by the scales
    sigma_b = model.sigma_bearing_rad(turn_rate_radps) / model.bearing_scale
    sigma_r = model.sigma_range_m(range_corrected) / model.range_scale
    if model.range_is_depth:  # the depth's σ, stretched by 1/cos b, plus the bearing's share
        sigma_r = math.hypot(sigma_r / c, range_corrected * math.tan(bearing) * sigma_b)
    return range_corrected, bearing, sigma_r, sigma_b


def correct_range(model: ObservationModel, range_m: float) -> tuple[float, float]:
    """A raw range-only reading (no bearing: a ranging radio) as ``(range_m, σ_range_m)``:
    inverts ``measured = range_scale·r + range_bias_m``; the σ is the model's at that range,
    divided by the scale. Raises :class:`NoiseModelError` for a non-positive result."""
    corrected = (range_m - model.range_bias_m) / model.range_scale
    if not corrected > 0.0:
        raise NoiseModelError(f"reading {range_m!r} m corrects to a non-positive range {corrected!r} m")
    return corrected, model.sigma_range_m(corrected) / model.range_scale


def apply_noise_model(log: RunLog, model: NoiseModel) -> tuple[RunLog, int]:
    """``log`` with its odometry and observations re-interpreted under ``model``.

    Returns the new log and the number of readings dropped as uncorrectable. Raises
    :class:`~slamio.noise.errors.NoiseModelError` when the log already carries a fitted model.
    """
    if carries_fitted_model(log.header.noise):
        raise NoiseModelError(
            f"{log.path}: this log already carries a fitted noise model (imported with --noise); "
            "apply a model only to a log made without one"
        )
    steps = log.steps()
    observations = [r for r in log.records if isinstance(r, Observation)]
    range_only = bool(observations) and all(o.range_only for o in observations)
    if not range_only and not model.odometry_fitted:
        raise NoiseModelError(
            f"{log.path}: the noise model's odometry part was not fitted (it was calibrated on a truth without "
            "heading, such as GPS), so it can correct range-only readings only; fit a model on logs whose truth "
            "has a heading"
        )
    stamps, increments = odometry_arrays(steps)
    odo_model = model.odometry
    chain = DeadReckoning(stamps, increments) if len(stamps) > 1 else None
    dropped = 0
    out = []
    step_index = 0
    for record in log.records:
        if isinstance(record, Odometry):
            step_index += 1
            out.append(record if range_only else _odometry(record, chain, stamps, step_index, model))
        elif isinstance(record, Observation) and not record.range_only and chain is not None:
            rate = odo_model.turn_scale * float(turn_rate_radps(chain, np.array([record.stamp_s - odo_model.lag_s]))[0])
            try:
                r, b, sr, sb = correct_observation(model.observation, record.range_m, record.bearing_rad, rate)
            except NoiseModelError:
                dropped += 1
                continue
            out.append(dataclasses.replace(record, range_m=r, bearing_rad=b, sigma_range_m=sr, sigma_bearing_rad=sb))
        elif isinstance(record, Observation) and record.range_only:  # a ranging radio
            try:
                r, sr = correct_range(model.observation, record.range_m)
            except NoiseModelError:
                dropped += 1
                continue
            out.append(dataclasses.replace(record, range_m=r, sigma_range_m=sr))
        else:
            out.append(record)
    if range_only:
        noise = {**log.header.noise, "observation": {
            "model": "range-only readings corrected by slamio.noise.apply.correct_range (fitted model, applied by "
                     "fgslam run --noise)", **asdict(model.observation), "fitted_on": list(model.fitted_on),
            "odometry_part": "not applied (a range-only log: its model's truth had no measured heading)",
            "replaced": log.header.noise.get("observation")}}
        return RunLog(log.path, dataclasses.replace(log.header, noise=noise), tuple(out), log.truncated), dropped
    noise = {
        "odometry": {"model": "fitted noise model applied by fgslam run --noise (slamio.noise.apply)",
                     "lag_s": odo_model.lag_s, "forward_scale": odo_model.forward_scale,
                     "turn_scale": odo_model.turn_scale, "turn_per_m_rad": odo_model.turn_per_m_rad,
                     **asdict(odo_model.noise)},
        "observation": {"model": "readings corrected by slamio.noise.apply.correct_observation",
                        **asdict(model.observation)},
        "fitted_on": list(model.fitted_on),
        "replaced": log.header.noise,
    }
    header = dataclasses.replace(log.header, noise=noise, sensor=sensor_with_mount(log.header.sensor, model.observation))
    return RunLog(log.path, header, tuple(out), log.truncated), dropped


def sensor_with_mount(sensor: dict, model: ObservationModel) -> dict:
    """A header's ``sensor`` with the model's fitted ``sensor_pose_on_robot`` stated as its
    ``pose_on_robot`` (the readings stay the sensor's own; :func:`slamio.log.group_steps`
    moves them to the centre); unchanged when the model has none."""
    if model.sensor_pose_on_robot is None:
        return sensor
    sensor = dict(sensor) if isinstance(sensor, dict) else {}
    if "pose_on_robot" in sensor:
        sensor["pose_on_robot_stated"] = sensor["pose_on_robot"]
    sensor["pose_on_robot"] = [float(v) for v in model.sensor_pose_on_robot]
    return sensor


def _odometry(record: Odometry, chain: DeadReckoning | None, stamps: np.ndarray, k: int, model: NoiseModel) -> Odometry:
    """Step k's increment re-read from the delayed chain, scaled, with the model's covariance."""
    o = model.odometry
    t0, t1 = stamps[k - 1] - o.lag_s, stamps[k] - o.lag_s
    a = chain.pose_at(float(np.clip(t0, stamps[0], stamps[-1]))) if chain is not None else None
    b = chain.pose_at(float(np.clip(t1, stamps[0], stamps[-1]))) if chain is not None else None
    if a is None or b is None:
        dx, dy, dth = record.dx_m, record.dy_m, record.dtheta_rad
    else:
        c, s = np.cos(a[2]), np.sin(a[2])
        ddx, ddy = b[0] - a[0], b[1] - a[1]
        dx, dy, dth = c * ddx + s * ddy, -s * ddx + c * ddy, b[2] - a[2]
    distance = float(np.hypot(dx, dy)) * o.forward_scale
    dx, dy = dx * o.forward_scale, dy * o.forward_scale
    dth = dth * o.turn_scale + o.turn_per_m_rad * distance * (1.0 if dx >= 0 else -1.0)
    cov = o.noise.stretch_covariance(distance, dth, max(float(stamps[k] - stamps[k - 1]), 0.0))
    return dataclasses.replace(record, dx_m=float(dx), dy_m=float(dy), dtheta_rad=float(dth), covariance=as_matrix3(cov))
