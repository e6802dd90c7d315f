"""Reading the smoother's answer: :class:`EstimateQueries`, the part of
:class:`~fgslam.smoother.isam2.Isam2Smoother` that answers questions — the online pose and
its covariance, the trajectory and landmarks, marginal covariances, predicted NIS, the whole
graph with its initial values and estimate, and the counters of withheld observations.

A mixin: it works on the state :class:`~fgslam.smoother.isam2.Isam2Smoother` sets up in its
``__init__``.
"""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

from fgslam.smoother.map_marginals import map_joint_blocks, whole_graph_bayes_tree
from fgslam.smoother.online import landmark_covariances
from slamio.errors import FgslamError
from slamio.log import Step


class EstimateQueries:
    """The estimates, covariances and graph the smoother answers with."""

    def current_pose(self) -> tuple[float, float, float]:
        """The online estimate of the latest pose (x_m, y_m, theta_rad).

        iSAM2's estimate when the latest step ran an update; otherwise the last iSAM2
        estimate composed with the odometry of the steps held since.
        """
        pose = self._online.pose
        if pose is None:
            raise FgslamError("Isam2Smoother: no step yet")
        return (pose.x(), pose.y(), pose.theta())

    def trajectory(self) -> np.ndarray:
        """(n, 3) array of every pose (x_m, y_m, theta_rad) as estimated now."""
        return self.trajectory_of(self._estimate())

    def trajectory_of(self, values: gtsam.Values) -> np.ndarray:
        """(n, 3) array of every pose for the keyframe (or all-pose) estimate ``values``
        (:meth:`fgslam.smoother.policy.Keyframes.trajectory`: with keyframes the poses between
        them are rebuilt from the odometry folded into their compound factor)."""
        return self._keyframes.trajectory(values, self._num_poses)

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark id → estimated world (x_m, y_m), for landmarks accepted into iSAM2
        (a tag's position is its centre)."""
        return self._landmarks.positions(self._estimate())

    def landmark_yaws(self) -> dict[int, float]:
        """Tag id → estimated world direction its face points to (rad); tags only (``tags=True``)."""
        return self._landmarks.yaws(self._estimate())

    def landmark_heights(self) -> dict[int, float]:
        """Landmark id → estimated height (m), for landmarks observed with a height."""
        return self._landmarks.heights(self._estimate())

    @property
    def num_poses(self) -> int:
        return self._num_poses

    def current_covariance(self, frame: str = "world") -> np.ndarray:
        """3×3 covariance of :meth:`current_pose`, the online estimate.

        iSAM2's marginal of the newest pose it holds (``isam.marginalCovariance``, which
        uses the Bayes tree and does not recompute the whole graph's marginals), carried
        through the odometry of any steps held since (first order: Σ ← Ad(z⁻¹) Σ Ad(z⁻¹)ᵀ + Σ_z
        per increment z), so asking does not change when iSAM2 updates. GTSAM expresses a
        Pose2's uncertainty in the robot's own frame (a perturbation ``pose ⊕ δ``). With
        ``frame="world"`` (the default) it is rotated into world (x, y, theta) coordinates,
        the same coordinates as the EKF's covariance and as a world-frame pose error, which
        is what NEES needs; ``frame="body"`` returns GTSAM's own.
        """
        if self._num_poses == 0:
            raise FgslamError("Isam2Smoother: no step yet")
        if frame not in ("world", "body"):
            raise FgslamError(f"current_covariance: frame must be 'world' or 'body', got {frame!r}")
        return self._online.covariance(self._marginals(), frame)

    def landmark_covariances(self) -> dict[int, np.ndarray]:
        """Landmark id → 2×2 marginal covariance of its (x, y) in the world frame
        (``isam.marginalCovariance``; for a tag, the position block of its Pose2 marginal
        rotated from the tag's frame). Flushes held steps.

        After :meth:`finish`, the whole graph's marginals at the final estimate: for a map of
        many landmarks, each one's block of their joint covariance, the poses eliminated first
        (:func:`fgslam.smoother.map_marginals.map_joint_blocks`); otherwise :meth:`_marginals`'."""
        self._flush()
        ids, tag_ids = self._landmarks.ids, self._landmarks.tag_ids
        if self._finished and self._final_map is None:
            self._final_map = map_joint_blocks(self._graph, self._estimate_cache, ids, tag_ids) or False
        marginals = self._final_map if self._finished and self._final_map else self._marginals()
        return landmark_covariances(marginals, self._estimate(), ids, tag_ids)

    def predicted_nis(self, step: Step) -> list[float | None]:
        """NIS of each observation of ``step`` against the smoother's prediction, before
        the step is added (nothing is changed; call it before :meth:`step`).

        The same question the EKF answers (:meth:`ekf.EkfSlam.predicted_nis`): the joint
        marginal of the newest iSAM2 pose and the observed landmarks
        (``isam.jointMarginalCovariance``), the pose carried through the odometry held since
        and this step's (Σ ← A Σ Aᵀ + Σ_z, cross-covariance ← A Σ_pl, A = Ad(z⁻¹)), rotated
        into world (x, y, θ), then :func:`ekf.models.range_bearing_nis`. None for an
        observation without an id, of a landmark iSAM2 does not hold yet, or of a tag, and
        for every observation of the step when iSAM2 cannot form the marginal (an
        indeterminate system, which real data with gross outliers can produce).
        """
        return self._online.predicted_nis(self._isam, step, self._landmarks.tag_ids)

    def graph(self) -> gtsam.NonlinearFactorGraph:
        """The whole problem: every factor accepted into iSAM2 (pending observations
        excluded), with a variable for every pose.

        Held steps are given to iSAM2 first, so the graph covers every step taken. With
        keyframes, each compound odometry factor iSAM2 holds is expanded back into its
        per-step factors, so this is the same graph as without keyframes."""
        self._flush()
        if not self.settings.keyframes:
            return gtsam.NonlinearFactorGraph(self._graph)
        return self._keyframes.expanded(self._graph)

    def initial_values(self) -> gtsam.Values:
        """A copy of the initial guess of every variable of :meth:`graph` (held steps flushed
        first; with keyframes, poses between keyframes dead-reckoned from the keyframe's)."""
        self._flush()
        values = gtsam.Values(self._initial)
        if self.settings.keyframes:
            self._keyframes.insert_between(values)
        return values

    def estimate(self) -> gtsam.Values:
        """A copy of iSAM2's current estimate of every variable of :meth:`graph` (one full
        back-substitution, ``calculateBestEstimate``; with keyframes, the poses between them as in :meth:`trajectory`)."""
        values = gtsam.Values(self._estimate())
        if self.settings.keyframes:
            trajectory = self.trajectory_of(values)
            keyframes = set(self._keyframes.indices)
            for i in range(self._num_poses):
                if i not in keyframes:
                    values.insert(X(i), gtsam.Pose2(*trajectory[i]))
        return values

    def error(self) -> float:
        """:meth:`graph`'s error at :meth:`estimate` (χ²/2, like ``graph.error``)."""
        if self.settings.keyframes:
            return float(self.graph().error(self.estimate()))
        return float(self._graph.error(self._estimate()))

    @property
    def window_slides(self) -> int:
        """How many times the sliding window (``window_poses``) marginalised the oldest poses."""
        return 0 if self._window is None else self._window.slides

    @property
    def pending_observations(self) -> int:
        """Observations withheld after a failed update, still to be retried."""
        return len(self._pending.withheld)

    @property
    def unconfirmed_observations(self) -> int:
        """Robust mode: first sightings of landmarks still waiting for a second that agrees."""
        return sum(len(q) for q in self._pending.unconfirmed.values())

    @property
    def dropped_observations(self) -> int:
        """Observations withheld after a failed update and then abandoned."""
        return self._pending.dropped

    @property
    def rejected_first_sightings(self) -> int:
        """Robust mode: first sightings no later observation agreed with (dropped)."""
        return self._pending.rejected_first_sightings

    def _marginals(self):
        """Where marginal covariances come from: iSAM2's Bayes tree during the run; after
        :meth:`finish`, the whole graph linearised at the final estimate and eliminated in
        the final Gauss–Newton steps' COLAMD ordering (built on the first question;
        :func:`~fgslam.smoother.map_marginals.whole_graph_bayes_tree`, what ``gtsam.Marginals``
        builds, bit for bit), since those steps moved the estimate past iSAM2's
        linearisation point."""
        if not self._finished:
            return self._isam
        if self._final_marginals is None:
            self._final_marginals = whole_graph_bayes_tree(self._graph, self._estimate_cache, self._final_ordering)
        return self._final_marginals

    def _estimate(self) -> gtsam.Values:
        self._flush()
        if self._estimate_cache is None:
            # the full back-substitution: with the default wildfire threshold (1.0)
            # calculateEstimate() would leave the deltas deep in the tree stale
            self._estimate_cache = self._best_estimate()
        return self._estimate_cache

    def _best_estimate(self) -> gtsam.Values:
        """iSAM2's full back-substitution (``calculateBestEstimate``), with the poses that
        left the sliding window at their estimates then."""
        values = self._isam.calculateBestEstimate()
        if self._window is not None:
            values.insert(self._window.frozen)
        return values
