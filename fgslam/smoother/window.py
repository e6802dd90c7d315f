"""A sliding window of poses: iSAM2 holds only the newest; older poses are marginalised.

Why: with every pose in iSAM2, the cost of an update and of reading the newest pose grows
with the run. A landmark seen from the whole run sits in the separator of nearly every
clique, so each update marks most of the tree for back-substitution; measured, an update
and the read of the newest pose grew from 0.9 to 4.0 ms (median, first and last quarter of
Plaza1) and from 0.27 to 1.47 ms on MRCLAM Dataset 6 robot 3 (docs/performance.md). A live
robot that runs for an hour would pass its 15 ms stream period. With ``window_poses`` set,
the smoother keeps at most twice that many poses in iSAM2: once it holds more, it
marginalises all but the newest ``window_poses`` (:func:`marginalise_poses`) and starts a
fresh iSAM2 on what is left. Every update then works on a bounded problem (the window and
the landmarks), however long the run.

What is marginalised is exact to first order: the factors that touch the dropped poses are
linearised at the current estimate and the dropped poses eliminated from them (GTSAM's
``eliminatePartialMultifrontal``); what remains is a Gaussian on the poses and landmarks
they shared with the window, kept as ``LinearContainerFactor`` s (their linearisation point
is fixed, the rest of the window still relinearises). The dropped poses keep the estimate
they had when they left (:attr:`SlidingWindow.frozen`).

The price is in the online estimate: the marginal keeps its landmarks' linearisation point,
so the window drifts from what the whole graph would say (on real data by −25 … +49 %, in
either direction), and a map of many landmarks becomes one dense block in the marginal that
every update refactors (the settings' docstring and docs/performance.md have the figures).
Hence it is off by default and on in ``fgslam live``.

The run's *final* estimate does not depend on the window: the smoother keeps every factor,
and :meth:`~fgslam.smoother.isam2.Isam2Smoother.finish` solves the whole graph
(:func:`~fgslam.smoother.batch.gauss_newton_steps`) from the window's estimate and the
frozen poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
from gtsam.symbol_shorthand import X


@dataclass
class Marginalised:
    """What :func:`marginalise_poses` leaves: the factors a fresh iSAM2 holds (those that did
    not touch a dropped pose, plus the marginal as ``LinearContainerFactor`` s) and their
    variables' values (the linearisation point, dropped poses removed)."""

    factors: gtsam.NonlinearFactorGraph
    values: gtsam.Values


def marginalise_poses(factors: gtsam.NonlinearFactorGraph, values: gtsam.Values, drop: list[int]) -> Marginalised:
    """Marginalise the variables ``drop`` (keys) out of ``factors`` linearised at ``values``.

    The factors touching a dropped key are linearised at ``values`` and the dropped keys
    eliminated from them; each factor left on the remaining keys becomes a
    ``LinearContainerFactor`` with its keys' values as linearisation point. ``values`` must
    hold every key of ``factors``; ``None`` slots (removed factors) are skipped.
    """
    dropped = set(drop)
    touching, kept = gtsam.NonlinearFactorGraph(), gtsam.NonlinearFactorGraph()
    for i in range(factors.size()):
        factor = factors.at(i)
        if factor is None:
            continue
        (touching if any(k in dropped for k in factor.keys()) else kept).add(factor)
    ordering = gtsam.Ordering()
    for key in drop:
        ordering.push_back(key)
    _, remaining = touching.linearize(values).eliminatePartialMultifrontal(ordering)
    for i in range(remaining.size()):
        marginal = remaining.at(i)
        if marginal is None or marginal.empty():
            continue
        kept.add(gtsam.LinearContainerFactor(marginal, values.extract(list(marginal.keys()))))
    return Marginalised(kept, values.extract([k for k in values.keys() if k not in dropped]))


class SlidingWindow:
    """Which poses iSAM2 holds, what it holds, and the estimates of the poses that left.

    ``factors`` and ``values`` are what the current iSAM2 was given (its factors, and each
    variable's value when it entered): what :mod:`fgslam.smoother.recovery` rebuilds from.
    """

    def __init__(self, size: int):
        self.size = int(size)
        self.poses: list[int] = []  # indices of the poses iSAM2 holds, oldest first
        self.dropped_below = 0  # every pose index below this has left iSAM2
        self.frozen = gtsam.Values()  # the poses that left, at their estimate then
        self.factors = gtsam.NonlinearFactorGraph()
        self.values = gtsam.Values()
        self.slides = 0
        self.stopped = False  # a fresh iSAM2 failed to take a slide: every pose is kept from then on

    def holds(self, pose_index: int) -> bool:
        """Whether pose ``pose_index`` is still in iSAM2 (or yet to enter it)."""
        return pose_index >= self.dropped_below

    def entered(self, factors: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> None:
        """Note an update's factors and new variables."""
        self.factors.push_back(factors)
        self.values.insert(values)
        for key in values.keys():
            symbol = gtsam.Symbol(key)
            if chr(symbol.chr()) == "x":
                self.poses.append(int(symbol.index()))

    def due(self) -> bool:
        """Whether iSAM2 holds more than twice ``size`` poses (then :meth:`slide`)."""
        return not self.stopped and len(self.poses) > 2 * self.size

    def slide(self, estimate: gtsam.Values) -> Marginalised:
        """What a fresh iSAM2 is to hold once all but the newest ``size`` poses are
        marginalised at ``estimate`` (iSAM2's full estimate). Nothing changes here until
        :meth:`commit` (a fresh iSAM2 that fails to take it leaves the window as it was)."""
        return marginalise_poses(self.factors, estimate, [X(i) for i in self.poses[: -self.size]])

    def commit(self, kept: Marginalised, estimate: gtsam.Values) -> None:
        """The fresh iSAM2 holds ``kept``: the dropped poses leave, at their ``estimate``."""
        for i in self.poses[: -self.size]:
            self.frozen.insert(X(i), estimate.atPose2(X(i)))
        self.poses = self.poses[-self.size:]
        self.factors, self.values = kept.factors, kept.values
        self.dropped_below = self.poses[0]
        self.slides += 1
