"""Which steps ``fgslam run`` takes NEES and NIS at: every step, or a seeded sample.

The NIS before a step and the covariance after it (for NEES and the report's ellipses) are
free for an EKF (its covariance is its state) but not for iSAM2: each asks the Bayes tree for
a marginal, and the caches that builds are torn down again by the next update. Taken at
every step that work cost more than the estimator itself (docs/performance.md, issue 43
part 3). The consistency figures are shares and means over many steps, so a sample of the
steps estimates them, with a standard error that says how closely (:func:`in_band_se`).

The sample (:func:`choose_steps`) is drawn once per log, before any estimator runs, from a
generator seeded with :data:`SEED`: the same log gives the same steps on every run and every
machine (never chosen by time). It is a uniform draw without replacement, not a stride, so it
cannot fall in step with iSAM2's relinearisation every few updates or with a log's own
rhythm (e.g. a camera read every fifth odometry step). NEES steps are drawn among the steps
with ground truth (where a NEES can be scored), NIS steps among the steps with observations,
as many of each as :func:`sample_size` says (1 % of the log's steps, at least
:data:`MIN_SAMPLE_STEPS`); a log with no more candidates than that is taken at every one of
them. A log without ground truth has no NEES: its covariances serve only the report's
pose ellipses, and are taken at :data:`ELLIPSE_STEPS` steps spread evenly over the run.

Every estimator of a run shares the one sample, the EKF too although its covariance costs
nothing: the table then compares the estimators at the same moments of the run, so a hard
stretch of the log weighs the same for each, and the difference between two estimators'
shares is not the difference between two samples. ``fgslam run --consistency all`` takes
every step (the figures as before the sample existed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from fgslam.compare.errors import in_band_se

__all__ = ["ConsistencySample", "ELLIPSE_STEPS", "MIN_SAMPLE_STEPS", "MODES", "SAMPLE_SHARE", "SEED", "choose_steps",
           "every_step", "in_band_se", "sample_of_steps", "sample_size"]

#: Steps drawn for NEES and (separately) for NIS: this share of the log's steps …
SAMPLE_SHARE = 0.01
#: … and at least this many. The size is the trade between the work and the figures' precision:
#: an iSAM2 NEES or NIS at a sampled step costs a fresh marginal of its Bayes tree, about 0.5 ms
#: of CPU on MRCLAM, where a whole iSAM2 step costs 0.15 ms, and the goal is that the work costs
#: at most 10 % of the estimators' own time; the binomial standard error of an in-band share p
#: over n steps is √(p(1 − p)/n): 3.1 points at p = 95 %, 4.2 at 90 % for n = 50 (measured in
#: docs/performance.md). A long log gets a larger sample, and its estimators' steps cost more.
MIN_SAMPLE_STEPS = 50
#: Steps whose covariance a log without ground truth takes, for the report's ellipses.
ELLIPSE_STEPS = 12
#: The generator's seed: fixed, so the sample depends on the log alone.
SEED = 20261207
#: ``--consistency`` choices: ``sampled`` (the default), ``all`` (every step), ``none``.
MODES = ("sampled", "all", "none")


@dataclass(frozen=True)
class ConsistencySample:
    """The steps to take NEES (``nees``) and NIS (``nis``) at: ``(n,)`` boolean masks."""

    nees: np.ndarray
    nis: np.ndarray
    mode: str  # "sampled" or "all"
    seed: int | None = None

    def description(self) -> dict:
        """JSON-ready: the mode, the seed, how many steps of how many for each figure."""
        return {"mode": self.mode, "seed": self.seed, "steps": int(len(self.nees)),
                "nees_steps": int(np.count_nonzero(self.nees)), "nis_steps": int(np.count_nonzero(self.nis))}


def every_step(n: int) -> ConsistencySample:
    """NEES and NIS at all ``n`` steps."""
    return ConsistencySample(np.ones(n, dtype=bool), np.ones(n, dtype=bool), "all")


def sample_size(steps: int) -> int:
    """How many steps to draw for NEES (and for NIS) on a log of ``steps`` steps."""
    return max(MIN_SAMPLE_STEPS, int(round(SAMPLE_SHARE * steps)))


def choose_steps(has_truth: np.ndarray, has_observations: np.ndarray, *, size: int = MIN_SAMPLE_STEPS,
                 seed: int = SEED) -> ConsistencySample:
    """The seeded sample of the module docstring: ``size`` NEES steps among those with
    ``has_truth`` (without any: :data:`ELLIPSE_STEPS` evenly spread, for the ellipses),
    ``size`` NIS steps among those with ``has_observations``; all candidates when there are
    no more than ``size``."""
    has_truth = np.asarray(has_truth, dtype=bool)
    has_observations = np.asarray(has_observations, dtype=bool)
    rng = np.random.default_rng(seed)
    if has_truth.any():
        nees = _draw(rng, has_truth, size)
    else:
        nees = np.zeros(len(has_truth), dtype=bool)
        nees[np.linspace(0, len(has_truth) - 1, min(ELLIPSE_STEPS, len(has_truth))).round().astype(int)] = True
    nis = _draw(rng, has_observations, size)
    return ConsistencySample(nees, nis, "sampled", seed)


def _draw(rng: np.random.Generator, candidates: np.ndarray, size: int) -> np.ndarray:
    """A mask with ``size`` of the ``candidates`` (all of them when there are no more)."""
    where = np.flatnonzero(candidates)
    out = np.zeros(len(candidates), dtype=bool)
    if len(where) <= size:
        out[where] = True
    else:
        out[rng.choice(where, size=size, replace=False)] = True
    return out


def sample_of_steps(steps: Sequence, mode: str, *, size: int | None = None) -> ConsistencySample | None:
    """The sample for ``mode`` (:data:`MODES`) of ``steps`` (None for ``none``), of
    :func:`sample_size` steps unless ``size`` says."""
    if mode not in MODES:
        raise ValueError(f"consistency mode {mode!r}; expected one of {', '.join(MODES)}")
    if mode == "none":
        return None
    if mode == "all":
        return every_step(len(steps))
    from fgslam.runner import truth_trajectory

    _, has_truth = truth_trajectory(steps)
    if hasattr(steps, "observations_per_step"):  # StepColumns: without building every step
        has_observations = steps.observations_per_step() > 0
    else:
        has_observations = np.array([len(step.observations) > 0 for step in steps], dtype=bool)
    return choose_steps(has_truth, has_observations, size=sample_size(len(steps)) if size is None else size)
