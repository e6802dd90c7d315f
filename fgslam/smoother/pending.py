"""Observations not yet in iSAM2, and the gate that decides when they go in.

Two kinds wait:

* **withheld** observations, taken out of an update that failed (see
  :mod:`fgslam.smoother.recovery`). One is retried only once it can be checked against
  something trustworthy: the current estimate of its landmark if the landmark is in the
  map, otherwise a fresh observation of that landmark (until then it waits — a landmark
  seen once tells nothing about the poses, so waiting costs the trajectory nothing). If it
  is more than about 7σ off (``½‖whitened residual‖² > PENDING_GATE``) it is dropped
  instead of retried: it was probably the cause, and accepting it would drag the whole
  map. One that has failed ``1 + max_retries`` updates is dropped too.
* with a robust kernel, **first sightings** of a landmark not yet in the map, waiting for
  a second observation that agrees (:meth:`PendingObservations.confirm_first_sightings`);
* **ranges** to a range-only landmark not yet placed (:class:`RangeOnlyLandmarks`).

The gate compares an observation's Gaussian factor (``gate_factor``) at its pose and a
landmark position: :func:`within_gate`.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import L, T, X

from ekf.range_only import DelayedInitRule, try_initialise
from fgslam.smoother.factors import FactorBuilder, PendingObservation
from fgslam.smoother.variables import LandmarkRegistry
from slamio.log import Observation

#: A pending observation whose ½‖whitened residual‖² at the current estimate exceeds
#: this (≈ 7σ in one component) is dropped instead of retried.
PENDING_GATE = 25.0

#: Robust mode: first sightings of a landmark kept waiting for one that agrees.
MAX_UNCONFIRMED = 10


def within_gate(entry: PendingObservation, pose: gtsam.Pose2, landmark, gate: float = PENDING_GATE) -> bool:
    """Whether ``entry``'s observation, made from ``pose``, fits ``landmark`` (a ``Point2``
    or a tag's ``Pose2``): ½‖whitened residual‖² of its Gaussian factor ≤ ``gate``."""
    values = gtsam.Values()
    values.insert(X(entry.pose_index), pose)
    values.insert(entry.key, landmark)
    error = entry.gate_factor.error(values)
    return math.isfinite(error) and error <= gate


class PendingObservations:
    """The observations waiting outside iSAM2, and what became of those that did not go in.

    ``dropped`` counts withheld observations abandoned (gated out, or failed
    ``1 + max_retries`` updates); ``rejected_first_sightings`` first sightings no later
    observation agreed with.
    """

    def __init__(self, max_retries: int, gate: float = PENDING_GATE, max_unconfirmed: int = MAX_UNCONFIRMED):
        self.max_retries = max_retries
        self.gate = gate
        self.max_unconfirmed = max_unconfirmed
        self.withheld: list[PendingObservation] = []
        self.unconfirmed: dict[int, list[PendingObservation]] = {}  # robust: first sightings waiting
        self.dropped = 0
        self.rejected_first_sightings = 0

    def withhold(self, entries: list[PendingObservation]) -> None:
        """Keep ``entries``, left out of a failed update, to retry later."""
        for e in entries:
            e.attempts += 1
        self.withheld.extend(entries)

    def screen(self, fresh: list[PendingObservation], isam: gtsam.ISAM2,
               landmarks: LandmarkRegistry) -> list[PendingObservation]:
        """The withheld observations to retry in this update (whose ``fresh`` observations
        are given); the others wait or are dropped."""
        retry, wait = [], []
        for e in self.withheld:
            if e.attempts > self.max_retries:
                self.dropped += 1
                continue
            if e.landmark_id in landmarks.known:
                if e.landmark_id in landmarks.tag_ids:
                    landmark = isam.calculateEstimatePose2(T(e.landmark_id))
                else:
                    landmark = isam.calculateEstimatePoint2(L(e.landmark_id))
            else:
                seen_now = [o for o in fresh if o.landmark_id == e.landmark_id]
                if not seen_now:  # nothing trustworthy to check it against yet
                    wait.append(e)
                    continue
                landmark = seen_now[-1].landmark_guess
            pose_key = X(e.pose_index)  # a pose held in this very batch is not in iSAM2 yet
            pose = isam.calculateEstimatePose2(pose_key) if isam.valueExists(pose_key) else e.seed_pose
            if within_gate(e, pose, landmark, self.gate):
                retry.append(e)
            else:
                self.dropped += 1
        self.withheld = wait
        return retry

    def confirm_first_sightings(self, fresh: list[PendingObservation], known: set[int]) -> list[PendingObservation]:
        """With a robust kernel, a new landmark enters the map only once two of its
        observations agree; returns the observations to use now.

        A robust kernel cannot repair a landmark *seeded* from a misdetection: its good
        observations then all look like outliers and are down-weighted (Cauchy leaves it
        stuck there). So the observations of a landmark not yet in the map (not in
        ``known``) wait. Each new one is checked against those waiting (its gate factor at
        its own seed pose and the waiting observation's landmark guess, ½‖whitened
        residual‖² ≤ ``PENDING_GATE``); at the first agreement both enter, seeded from the
        newer, and the rest that waited are gated against the landmark's estimate like
        withheld observations (kept when they fit, dropped when not). Nothing good is
        thrown away on the way: dropping a good first sighting made from the precisely
        known start pose doubled the ATE of an arena run. A landmark seen once tells
        nothing about the poses, so the wait costs the trajectory nothing. At most
        ``MAX_UNCONFIRMED`` observations wait per landmark; older ones are dropped
        (``rejected_first_sightings``).
        """
        accepted: list[PendingObservation] = []
        confirmed_now: set[int] = set()
        for e in fresh:
            if e.landmark_id in known:
                accepted.append(e)
                continue
            if e.landmark_id in confirmed_now:  # entering in this update: gate it, do not seed from it
                self.withheld.append(e)
                continue
            waiting = self.unconfirmed.setdefault(e.landmark_id, [])
            match = next((w for w in reversed(waiting) if within_gate(e, e.seed_pose, w.landmark_guess, self.gate)),
                         None)
            if match is None:
                waiting.append(e)
                if len(waiting) > self.max_unconfirmed:
                    waiting.pop(0)
                    self.rejected_first_sightings += 1
                continue
            accepted += [match, e]
            self.withheld += [w for w in waiting if w is not match]  # gated at the next screening
            del self.unconfirmed[e.landmark_id]
            confirmed_now.add(e.landmark_id)
        return accepted


class RangeOnlyLandmarks:
    """Range-only landmarks (see :mod:`ekf.range_only`): their ranges are buffered until they
    pin the landmark down, then every one becomes a ``RangeFactor2D`` seeded at the trilateration."""

    def __init__(self, rule: DelayedInitRule):
        self.rule = rule
        self._buffer: dict[int, list[tuple[int, gtsam.Pose2, Observation]]] = {}
        self._seed: dict[int, np.ndarray] = {}  # initialised range-only landmark → trilateration

    def add(self, k: int, seed: gtsam.Pose2, obs: Observation, factors: FactorBuilder) -> list[PendingObservation]:
        """The range factors to hold now for a range-only observation from pose ``k``.

        One ``RangeFactor2D`` once its landmark is placed; before that the observation is
        buffered until :func:`ekf.range_only.try_initialise` (the EKF's rule, on the robot
        positions estimated online at each range) places the landmark, and then all buffered
        ranges become factors, seeded at the trilateration."""
        lid = obs.landmark_id
        if lid in self._seed:
            return [factors.range(k, seed, obs, self._seed[lid])]
        buffer = self._buffer.setdefault(lid, [])
        buffer.append((k, seed, obs))
        del buffer[: -self.rule.max_buffer]
        positions = np.array([[pose.x(), pose.y()] for _, pose, _ in buffer])
        ranges = np.array([o.range_m for _, _, o in buffer])
        sigmas = np.array([o.sigma_range_m for _, _, o in buffer])
        fit = try_initialise(positions, ranges, sigmas, self.rule)
        if fit is None:
            return []
        entries = [factors.range(j, pose, o, fit.xy) for j, pose, o in buffer]
        del self._buffer[lid]
        self._seed[lid] = fit.xy
        return entries
