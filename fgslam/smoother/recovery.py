"""When an iSAM2 update fails: rebuild a fresh iSAM2 without the observations to blame.

GTSAM raises ``IndeterminantLinearSystemException`` (a ``RuntimeError`` in Python) when a
linear system it has to factor is singular — for example a landmark observed at a range
of practically zero, whose bearing says nothing about where it is. iSAM2 adds the new
variables and factors to its internal state *before* it factors, so an ``ISAM2`` object
that has thrown is left inconsistent and must not be used again. The smoother therefore:

1. counts the failure (``update_failures``, message in ``last_failure``);
2. withholds the update's observations of the landmark GTSAM names in the exception (or
   all of the update's observations when it names a pose or nothing);
3. rebuilds a fresh ``ISAM2`` from every factor accepted so far plus the rest of the
   update, seeded from the failed object's linearisation point (a plain copy of its
   values); if that fails too — relinearisation may itself have moved a variable to a
   degenerate place — from the initial values every variable entered with, then from a
   Levenberg–Marquardt solve of the whole graph (its damping copes with a corrupted
   odometry record that leaves the poses after it metres from what they observe), and then
   without any of the update's observations. A rebuild costs one batch factorisation, so
   it is only for the rare failure; it is the only time a step runs more than one update
   (:func:`rebuild`);
4. keeps the withheld observations pending (:mod:`fgslam.smoother.pending`): they are
   retried once a gate against the map or a fresh observation passes, dropped when it
   fails or after ``1 + max_retries`` failed updates. Both count in
   ``dropped_observations``; observations still waiting at the end are in
   ``pending_observations``.

If the rebuild without any of the step's observations fails from every seed, the odometry
or the prior itself is degenerate and :class:`~slamio.errors.FgslamError` is raised.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import gtsam

from fgslam.smoother.factors import PendingObservation, update_batch

_NEAR_VARIABLE = re.compile(r"near variable\s+(\d+)")


@dataclass
class Rebuild:
    """What :func:`rebuild` made: the new iSAM2 (None when every attempt failed), the factors
    and new values of the update it accepted, the observations it withheld, and the message
    of the most recent failure."""

    isam: gtsam.ISAM2 | None
    factors: gtsam.NonlinearFactorGraph | None
    values: gtsam.Values | None
    withheld: list[PendingObservation]
    last_failure: str


def rebuild(
    exc: RuntimeError,
    failed: gtsam.ISAM2,
    params: gtsam.ISAM2Params,
    graph: gtsam.NonlinearFactorGraph,
    initial: gtsam.Values,
    core: gtsam.NonlinearFactorGraph,
    core_values: gtsam.Values,
    entries: list[PendingObservation],
    known_landmarks: set[int],
) -> Rebuild:
    """A fresh iSAM2 holding ``graph`` (every factor accepted so far, whose variables entered
    at ``initial``) plus the update that raised ``exc`` in ``failed`` — its ``core`` factors
    and values and its observation ``entries`` but those withheld (module docstring)."""
    last_failure = str(exc)
    seeds = []
    try:  # the failed object's values are a plain copy: usually a good linearisation point
        seeds.append(failed.getLinearizationPoint())
    except RuntimeError:
        pass
    seeds.append(initial)
    blamed = key_named_in(exc)
    blamed_ids = {e.landmark_id for e in entries if e.key == blamed}
    innocent = [e for e in entries if e.landmark_id not in blamed_ids]
    plans = [innocent, []] if blamed_ids and innocent else [[]]
    for kept in plans:
        kept_ids = {id(e) for e in kept}
        withheld = [e for e in entries if id(e) not in kept_ids]
        factors, values = update_batch(core, core_values, kept, known_landmarks)
        everything = gtsam.NonlinearFactorGraph(graph)
        everything.push_back(factors)
        for seed in seeds + [None]:
            isam = gtsam.ISAM2(params)
            try:
                start = reseeded(initial, values, seed) if seed is not None else damped(everything, initial, values)
                isam.update(everything, start)
            except RuntimeError as again:
                last_failure = str(again)
                continue
            return Rebuild(isam, factors, values, withheld, last_failure)
    return Rebuild(None, None, None, list(entries), last_failure)


def damped(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values, new_values: gtsam.Values) -> gtsam.Values:
    """The last seed: Levenberg–Marquardt on the whole graph from the initial values. Its
    damping solves systems that Gauss–Newton's cannot (a corrupted odometry record that
    leaves the poses after it far from their observations); raises RuntimeError if it fails too."""
    return gtsam.LevenbergMarquardtOptimizer(graph, reseeded(initial, new_values, initial)).optimize()


def key_named_in(exc: BaseException) -> int | None:
    """The variable GTSAM's IndeterminantLinearSystemException names, if any."""
    match = _NEAR_VARIABLE.search(str(exc))
    return int(match.group(1)) if match else None


def reseeded(initial: gtsam.Values, new_values: gtsam.Values, seed: gtsam.Values) -> gtsam.Values:
    """Initial values for a rebuild: old variables at ``seed`` where it has them, new ones as given."""
    out = gtsam.Values()
    for key in initial.keys():
        source = seed if seed.exists(key) else initial
        kind = chr(gtsam.Symbol(key).chr())
        if kind in "xt":
            out.insert(key, source.atPose2(key))
        elif kind == "h":
            out.insert(key, source.atDouble(key))
        else:
            out.insert(key, source.atPoint2(key))
    out.insert(new_values)
    return out
