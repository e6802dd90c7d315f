"""The update policy: when steps go to iSAM2, and which poses become its variables.

By default steps are held and go to iSAM2 once they carry 20 observations (and 10 steps)
or 50 steps wait (sooner when a step is urgent: a landmark iSAM2 does not hold yet, or an
observation the online correction finds unlikely), and every pose is a variable.
``update_observations``, ``update_every`` / ``update_on`` set how steps are held (:class:`HeldSteps`); ``keyframes`` makes
only poses with observations variables and folds the odometry in between
(:class:`Keyframes`). :data:`FAST_SETTINGS` is the preset that uses both. The measured
effects are in docs/performance.md.
"""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

from fgslam.smoother.chain import OdometryChain, add_links
from fgslam.smoother.factors import FactorBuilder, PendingObservation
from fgslam.smoother.variables import poses_of

#: The ``isam2-fast`` preset: settings tuned on Victoria Park (docs/performance.md), for long
#: runs and large maps where even the default's updates cost too much. Only steps with
#: observations become iSAM2 variables (keyframes; the odometry between them is folded into
#: one factor, and the poses in between are rebuilt on demand); steps are held and go to
#: iSAM2 in one update at the first step with observations once 50 are waiting; iSAM2
#: relinearises every 20th update, a variable whose step exceeds 1 m or 0.05 rad; the
#: online pose is read back with a loose wildfire threshold. ``finish()`` then runs full
#: Gauss–Newton steps. On Victoria Park the final χ²/2 of the whole graph is 0.08 % above
#: the batch optimum, and on MRCLAM Dataset 6 robot 1 1.8 % above it (keyframes are exact
#: only to first order), so it is not the default. Between updates the online correction
#: works as in the default (without it this preset's online ATE on Victoria Park was 5.9 %
#: above the default's); the default's information triggers (20 observations, an unlikely
#: innovation) are off, so it still updates once per 50 steps.
FAST_SETTINGS = {
    "keyframes": True,
    "relinearize_threshold": (1.0, 0.05),
    "relinearize_skip": 20,
    "relinearize_max_variables": None,  # as tuned: every variable past its threshold
    "update_every": 50,
    "update_on": "observations",
    "wildfire_threshold": 1.0,
    "update_observations": None,
    "update_tail": 0.0,
}


class HeldSteps:
    """Steps taken but not yet given to iSAM2 (``update_every`` / ``update_on``).

    Their odometry/prior/height factors and pose/height seeds (``core``, ``values``), their
    observation factors (``entries``), the range factors of range-only landmarks already
    placed (``ranges``), how many steps wait and whether any of them observed something:
    run in one update later. ``core`` and ``values`` are plain lists until then: an
    odometry record is held as ``(k, record)`` and becomes its factor, and the seeds go
    into one ``gtsam.Values``, only in :meth:`take` (a step then costs list appends, not a
    factor, a noise model and a ``Values.insert``, each a call through GTSAM's bindings).

    ``urgent`` marks a step that should not wait: it saw a landmark iSAM2 does not hold yet, or an observation the online correction did not use
    (:mod:`fgslam.smoother.correction`); ``unlikely``, an observation the correction found
    unlikely (the update then waits for ``update_tail_min_steps`` held steps);
    ``uncorrected``, an observation without an id (the correction cannot use it, so the online
    pose dead-reckons until iSAM2 has associated it: the update waits for
    ``update_observations_min_steps`` held steps, not for ``update_observations``).
    """

    def __init__(self):
        self._empty()

    def _empty(self) -> None:
        """Nothing held."""
        # the prior, odometry and height terms in step order: a factor, or (k, odometry
        # record) for step k's odometry factor, built in take()
        self.core: list = []
        self.values: list[tuple[int, object]] = []  # (key, seed) of each held variable
        self.entries: list[PendingObservation] = []
        self.ranges: list[PendingObservation] = []
        self.steps = 0
        self.observed = False
        self.urgent = False
        self.unlikely = False
        self.uncorrected = False

    @property
    def observations(self) -> int:
        """Observation factors held (range-bearing, tag and range-only)."""
        return len(self.entries) + len(self.ranges)

    def take(self, factors: FactorBuilder) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values,
                                                  list[PendingObservation], list[PendingObservation]]:
        """(core, values, entries, ranges) of every held step, the odometry factors built by
        ``factors`` (:meth:`FactorBuilder.odometry`); nothing is held afterwards."""
        core = gtsam.NonlinearFactorGraph()
        odometry, add = factors.odometry, core.add
        for term in self.core:
            add(odometry(*term) if type(term) is tuple else term)
        values = gtsam.Values()
        insert, pose2 = values.insert, gtsam.Pose2
        for key, seed in self.values:
            # by keyword: pybind11 tries Values.insert's overloads in order and a Pose2's is
            # the 9th; the keyword skips the eight before it (3.6 µs a pose against 6.7)
            if type(seed) is pose2:
                insert(key, pose2=seed)
            else:
                insert(key, seed)
        taken = core, values, self.entries, self.ranges
        self._empty()
        return taken


class Keyframes:
    """Which poses are iSAM2 variables, and the odometry chains between them.

    Without keyframes (``enabled=False``) every pose is a variable and this only lists
    them. With keyframes only a pose with observations (or ``max_gap`` steps after the
    last keyframe) is a variable ``X(k)``; the odometry since the last keyframe is folded
    into one compound ``BetweenFactorPose2`` (:class:`OdometryChain`), and the poses in
    between are rebuilt from it on demand.
    """

    def __init__(self, enabled: bool, max_gap: int):
        self.enabled = enabled
        self.max_gap = max_gap
        self.indices: list[int] = []  # pose indices with a variable X(k)
        self.chains: dict[int, OdometryChain] = {}  # keyframe b → the chain from the keyframe before
        self.open = OdometryChain(0)  # the chain since the last keyframe

    @property
    def last(self) -> int:
        """The newest pose with a variable."""
        return self.indices[-1]

    def fold(self, k: int, increment: gtsam.Pose2, covariance: np.ndarray, observed: bool) -> OdometryChain | None:
        """Add step ``k``'s odometry to the open chain; when ``k`` is a keyframe (``observed``
        or ``max_gap`` links), close the chain and return it (its compound becomes a factor)."""
        self.open.append(increment, covariance)
        if observed or len(self.open.links) >= self.max_gap:
            chain, self.open = self.open, OdometryChain(k)
            self.chains[k] = chain
            return chain
        return None

    def latest_pose(self, last_key_pose: gtsam.Pose2) -> gtsam.Pose2:
        """The newest pose from its keyframe's estimate (⊕ the open chain, with keyframes)."""
        return last_key_pose.compose(self.open.compound) if self.open.links else last_key_pose

    def trajectory(self, values: gtsam.Values, num_poses: int) -> np.ndarray:
        """(n, 3) array of every pose for the keyframe (or all-pose) estimate ``values``.

        Without keyframes, the poses in ``values``. With them, each pose between two
        keyframes a and b is rebuilt from the odometry folded into their compound factor
        and its least-squares share of that factor's residual (:meth:`OdometryChain.poses`);
        poses after the last keyframe are its estimate ⊕ the odometry since (nothing else
        constrains them).
        """
        if not self.enabled:
            return poses_of(values, num_poses)
        out = np.empty((num_poses, 3))
        for k in self.indices:
            p = values.atPose2(X(k))
            out[k] = (p.x(), p.y(), p.theta())
        for b, chain in self.chains.items():
            if len(chain.links) > 1:
                start, end = values.atPose2(X(chain.start)), values.atPose2(X(b))
                out[chain.start + 1 : b] = chain.poses(start, end)
        if self.open.links:
            last = self.last
            out[last + 1 :] = self.open.dead_reckoned(values.atPose2(X(last)))
        return out

    def expanded(self, graph: gtsam.NonlinearFactorGraph) -> gtsam.NonlinearFactorGraph:
        """``graph`` (iSAM2's factors) with each compound odometry factor expanded back into
        its per-step factors, plus the steps after the last keyframe: the graph without keyframes."""
        out = gtsam.NonlinearFactorGraph()
        for i in range(graph.size()):
            factor = graph.at(i)
            chain = self._folded_chain(factor)
            if chain is None:
                out.add(factor)
                continue
            add_links(out, chain)
        add_links(out, self.open)  # the steps after the last keyframe (not in iSAM2 yet)
        return out

    def insert_between(self, values: gtsam.Values) -> None:
        """Add to ``values`` the poses between keyframes and after the last one, dead-reckoned
        from the keyframe before each."""
        for b, chain in self.chains.items():
            for j, pose in enumerate(chain.dead_reckoned(values.atPose2(X(chain.start)))[:-1]):
                values.insert(X(chain.start + 1 + j), gtsam.Pose2(*pose))
        if self.open.links:
            last = self.last
            for j, pose in enumerate(self.open.dead_reckoned(values.atPose2(X(last)))):
                values.insert(X(last + 1 + j), gtsam.Pose2(*pose))

    def _folded_chain(self, factor) -> OdometryChain | None:
        """The chain a compound odometry factor of iSAM2's graph stands for (None otherwise)."""
        if not isinstance(factor, gtsam.BetweenFactorPose2):
            return None
        a, b = (gtsam.Symbol(key) for key in factor.keys())
        if chr(a.chr()) != "x" or chr(b.chr()) != "x":
            return None
        chain = self.chains.get(int(b.index()))
        if chain is None or chain.start != int(a.index()) or len(chain.links) < 2:
            return None
        return chain
