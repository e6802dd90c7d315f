"""Is one run's mean NEES what its stated noise predicts? A band made by redrawing the run.

The mean NEES of a run with N poses is often judged against ``nees_band(3, runs=N)``: the
band of the mean of N independent χ²(3) values (for 137 poses [2.60, 3.42]). The poses of
one SLAM run are not independent. The map is built from the odometry before the first
landmarks are seen, and that error stays with every later pose, so a run's mean NEES is
closer to one draw than to an average of N. Even when the estimator's models are exact
by construction (``fgslam sim arena-octagon``, seeds 1–30, the EKF), the run means spread
from 0.8 to 7.7 and only 2 of 30 fall inside their independent-pose band, while the mean
over the 30 runs, 2.89, is inside the band of 30 runs (docs/estimators.md).

:func:`run_nees_band` gives the band that does hold for one run: it redraws the run's noise
many times from the σ its own records state (:func:`slamio.redraw.redraw_noise`: the same
true poses and landmarks, the same sightings), runs the estimator on each copy and takes
the central ``probability`` interval of their mean NEES. A run whose own mean NEES lies
outside it states noise it does not have (or its estimator is inconsistent); inside it, it
is as consistent as one run can show. The log needs truth, with a heading, at every pose.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ekf.models import range_bearing
from fgslam.compare import nees_band, nees_over_truth
from fgslam.runner import run_estimator, truth_trajectory
from slamio.errors import FgslamError
from slamio.geometry import wrap_angle
from slamio.log import Observation, Odometry, RunLog
from slamio.redraw import redraw_noise

__all__ = ["RunNeesBand", "mean_nees", "reading_z_scores", "run_nees_band", "with_stated_noise_scaled"]


@dataclass(frozen=True)
class RunNeesBand:
    """A run's mean NEES against the band of runs redrawn from its stated noise."""

    mean_nees: float  # the run's own, over its poses with truth
    low: float  # the central interval of the redrawn runs' mean NEES
    high: float
    draws: np.ndarray  # every redrawn run's mean NEES
    independent_band: tuple[float, float]  # nees_band(3, runs=poses): if the poses were independent

    @property
    def inside(self) -> bool:
        return self.low <= self.mean_nees <= self.high


def mean_nees(log: RunLog, make_estimator: Callable) -> tuple[float, int]:
    """The mean NEES of ``make_estimator(header)``'s online poses against the log's truth, and
    how many poses it is over."""
    steps = log.steps()
    truth, has = truth_trajectory(steps)
    if np.any(has & ~np.isfinite(truth[:, 2])):
        raise FgslamError(f"{log.path}: its truth has no heading at some poses; the mean NEES here is over "
                          "(x, y, θ) against the 3-DoF band, and needs the true heading")
    run, _ = run_estimator(make_estimator(log.header), steps)
    values, _ = nees_over_truth(run.online, run.online_covariances, truth, has)
    values = values[np.isfinite(values)]
    return float(np.mean(values)), len(values)


def run_nees_band(log: RunLog, make_estimator: Callable, *, draws: int = 100, seed: int = 0,
                  probability: float = 0.95, on_draw: Callable[[int], None] | None = None) -> RunNeesBand:
    """The run's mean NEES and the band of ``draws`` copies redrawn from its stated noise
    (module docstring). ``on_draw(k)`` is called after each copy (progress)."""
    own, poses = mean_nees(log, make_estimator)
    rng = np.random.default_rng(seed)
    means = np.empty(draws)
    for k in range(draws):
        means[k], _ = mean_nees(redraw_noise(log, rng), make_estimator)
        if on_draw is not None:
            on_draw(k)
    tail = 0.5 * (1.0 - probability)
    low, high = np.quantile(means, [tail, 1.0 - tail])
    return RunNeesBand(own, float(low), float(high), means, nees_band(3, runs=poses))


def with_stated_noise_scaled(log: RunLog, factor: float) -> RunLog:
    """``log`` stating every σ ``factor`` times what it stated (odometry covariances by
    ``factor²``, the readings' range and bearing σ by ``factor``), the readings unchanged:
    what a log whose noise is mis-stated looks like, to see whether :func:`run_nees_band`
    can tell."""
    records = []
    for r in log.records:
        if isinstance(r, Odometry):
            r = dataclasses.replace(r, covariance=tuple(tuple(factor**2 * v for v in row) for row in r.covariance))
        elif isinstance(r, Observation):
            r = dataclasses.replace(r, sigma_range_m=factor * r.sigma_range_m,
                                    sigma_bearing_rad=None if r.sigma_bearing_rad is None
                                    else factor * r.sigma_bearing_rad)
        records.append(r)
    return dataclasses.replace(log, records=tuple(records))


def reading_z_scores(log: RunLog) -> tuple[np.ndarray, np.ndarray]:
    """Each range-and-bearing reading's error against the log's truth over the σ it states:
    ``(range z, bearing z)``. Standard normal when the log states the noise it has. Needs the
    true pose of every step with readings and every seen landmark's truth (by id)."""
    landmarks = {i: (t.x_m, t.y_m) for i, t in log.truth_landmarks().items()}
    z_range, z_bearing = [], []
    for step in log.steps():
        for o in step.observations:
            if o.range_only:
                continue
            if step.truth is None or step.truth.theta_rad is None:
                raise FgslamError(f"{log.path}: pose {step.index} has a reading but no true pose with a heading; "
                                  "the readings' errors need the true pose of every step with readings")
            pose = (step.truth.x_m, step.truth.y_m, step.truth.theta_rad)
            range_m, bearing_rad = range_bearing(pose, landmarks[o.landmark_id])
            z_range.append((o.range_m - range_m) / o.sigma_range_m)
            z_bearing.append(wrap_angle(o.bearing_rad - bearing_rad) / o.sigma_bearing_rad)
    return np.array(z_range), np.array(z_bearing)
