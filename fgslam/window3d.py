"""A bounded iSAM2 for the 3-D smoother: old poses and the landmarks only they saw are marginalised.

Why: with every variable in iSAM2 the memory of ``isam2-3d`` grows faster than the graph.
Stereo tracks of up to 40 steps at 40 features a step make wide cliques: on the long
simulated drive of ``scripts/bench_vio.py`` (1 089 steps, 42 742 sightings) iSAM2 alone
reached 1.3 GB of resident memory and its updates 80–170 ms a step by the end
(docs/performance.md, "A bounded isam2-3d").

What :class:`StereoWindow` does: it counts the factors the current iSAM2 holds. Once they
are more than ``max_factors`` (:meth:`StereoWindow.due`), the newest poses that together
brought at most ``keep_fraction`` of that many are kept, every older pose leaves, and so
does every landmark last seen before the first pose kept. The factors that touch what leaves
are linearised at iSAM2's estimate and those variables eliminated from them
(:func:`fgslam.smoother.window.marginalise_poses`, the 2-D window's, which takes any keys);
what is left is a Gaussian on the poses and landmarks they shared with the window, and a
fresh iSAM2 holds it with the window's own factors. What left keeps its estimate of then
(:attr:`StereoWindow.frozen`). So iSAM2 never holds more than about ``max_factors`` factors
plus that marginal, however long the drive.

A landmark seen again after it left re-enters iSAM2 as a new variable
(:meth:`StereoWindow.landmark_key`: ``m0``, ``m1``, … in GTSAM's symbols), started at its
frozen estimate: the window no longer knows what it knew of it (a loop closed through it is
not closed online). The whole graph, kept by the smoother with one variable per landmark,
still has it: the batch solve sees every factor.
"""

from __future__ import annotations

import gtsam
from gtsam.symbol_shorthand import L, X

from fgslam.smoother.window import Marginalised, marginalise_poses

__all__ = ["StereoWindow", "RE_ENTERED"]

#: GTSAM symbol character of the keys of landmarks that re-entered iSAM2 after they left it.
RE_ENTERED = "m"


class StereoWindow:
    """What the current iSAM2 holds, what left it (at which estimate), and which key each
    landmark has in it now.

    ``factors`` and ``values``: what the current iSAM2 was given (its factors, and each
    variable's value when it entered): what a rebuild after a failed update starts from.
    """

    def __init__(self, max_factors: int, keep_fraction: float = 0.5, min_poses: int = 2,
                 max_load: float | None = None):
        if max_factors < 1 or not 0.0 < keep_fraction < 1.0 or min_poses < 1 or (max_load is not None and max_load <= 0):
            raise ValueError(f"max_factors ≥ 1, 0 < keep_fraction < 1, min_poses ≥ 1, max_load > 0 or None; got "
                             f"{max_factors}, {keep_fraction}, {min_poses}, {max_load}")
        self.max_factors = int(max_factors)
        self.max_load = None if max_load is None else float(max_load)
        self.brought = 0  # factors the held poses brought (the marginal's factors not counted)
        self.keep_fraction = float(keep_fraction)
        self.min_poses = int(min_poses)
        self.factors = gtsam.NonlinearFactorGraph()
        self.values = gtsam.Values()
        self.poses: list[tuple[int, int]] = []  # (pose index, factors it brought), oldest first
        self.held_factors = 0  # factors the current iSAM2 was given (marginals included)
        self.last_seen: dict[int, int] = {}  # landmark key held → last step it was seen
        self.key_of: dict[int, int] = {}  # landmark id → its key now
        self.frozen = gtsam.Values()  # variables that left, at their estimate then
        self.re_entered = 0  # landmarks that came back under a new key
        self.slides = 0
        self.stopped = False  # a fresh iSAM2 could not take a slide: nothing leaves from then on

    # ------------------------------------------------------------------ bookkeeping

    def landmark_key(self, landmark_id: int) -> tuple[int, bool]:
        """(key of landmark ``landmark_id`` in iSAM2, whether that key is new): ``L(id)`` the
        first time, the held key while it is held, a fresh ``m<n>`` once it has left."""
        key = self.key_of.get(landmark_id)
        if key is None:
            return L(landmark_id), True
        if key in self.last_seen:
            return key, False
        key = gtsam.symbol(RE_ENTERED, self.re_entered)
        self.re_entered += 1
        return key, True

    def left_estimate(self, landmark_id: int):
        """The estimate landmark ``landmark_id`` had when it last left iSAM2."""
        return self.frozen.atPoint3(self.key_of[landmark_id])

    def entered(self, step: int, factors: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                seen: dict[int, int]) -> None:
        """Note step ``step``'s factors and new variables; ``seen``: landmark id → key for
        every landmark sighted in it."""
        self.factors.push_back(factors)
        self.values.insert(values)
        self.poses.append((step, factors.size()))
        self.held_factors += factors.size()
        self.brought += factors.size()
        for landmark_id, key in seen.items():
            self.key_of[landmark_id] = key
            self.last_seen[key] = step

    def bound(self) -> float:
        """The most factors iSAM2 may hold now: ``max_factors``, and with ``max_load`` at most
        ``max_load`` / (the factors a held step brought, on average) — the *load* of what it
        holds, factors held × factors a step brings, is what an update's cost grows with."""
        if self.max_load is None or not self.poses:
            return float(self.max_factors)
        return min(float(self.max_factors), self.max_load * len(self.poses) / max(self.brought, 1))

    def due(self) -> bool:
        """Whether iSAM2 holds more than :meth:`bound` factors (then :meth:`slide`)."""
        return not self.stopped and self.held_factors > self.bound() and len(self.poses) > self.min_poses

    # ------------------------------------------------------------------ the slide

    def leaving(self) -> tuple[list[int], list[int]]:
        """(pose indices, landmark keys) that a slide now takes out of iSAM2."""
        budget = self.keep_fraction * self.bound()
        first = len(self.poses) - self.min_poses
        kept = sum(n for _, n in self.poses[first:])
        while first > 0 and kept + self.poses[first - 1][1] <= budget:
            first -= 1
            kept += self.poses[first][1]
        kept_from = self.poses[first][0]
        poses = [i for i, _ in self.poses[:first]]
        landmarks = [k for k, last in self.last_seen.items() if last < kept_from]
        return poses, landmarks

    def slide(self, estimate: gtsam.Values) -> Marginalised:
        """What a fresh iSAM2 is to hold once :meth:`leaving` is marginalised at ``estimate``
        (iSAM2's full estimate). Nothing changes here until :meth:`commit`."""
        poses, landmarks = self.leaving()
        return marginalise_poses(self.factors, estimate, [X(i) for i in poses] + landmarks)

    def commit(self, kept: Marginalised, estimate: gtsam.Values) -> None:
        """The fresh iSAM2 holds ``kept``: what left is frozen at ``estimate``."""
        poses, landmarks = self.leaving()
        for i in poses:
            self.frozen.insert(X(i), estimate.atPose3(X(i)))
        for key in landmarks:
            self.frozen.insert(key, estimate.atPoint3(key))
            del self.last_seen[key]
        self.brought -= sum(n for _, n in self.poses[:len(poses)])
        self.poses = self.poses[len(poses):]
        self.factors, self.values = kept.factors, kept.values
        self.held_factors = kept.factors.size()
        self.slides += 1

    # ------------------------------------------------------------------ the whole estimate

    def whole_estimate(self, held: gtsam.Values, n_poses: int, landmark_ids) -> gtsam.Values:
        """Every pose ``X(t)`` and landmark ``L(id)`` of the whole graph: from iSAM2's
        estimate ``held`` where it still holds them, else as they left (a landmark that came
        back: its newest key's)."""
        values = gtsam.Values()
        for t in range(n_poses):
            values.insert(X(t), _pose(held, self.frozen, X(t)))
        for landmark_id in landmark_ids:
            key = self.key_of[landmark_id]
            values.insert(L(landmark_id), held.atPoint3(key) if held.exists(key) else self.frozen.atPoint3(key))
        return values


def _pose(held: gtsam.Values, frozen: gtsam.Values, key: int) -> gtsam.Pose3:
    return held.atPose3(key) if held.exists(key) else frozen.atPose3(key)
