"""A chain of odometry links folded into one compound relative pose, with its covariance.

Used twice: with keyframes the odometry between two keyframes becomes one
``BetweenFactorPose2`` (:mod:`fgslam.smoother.policy`), and the online covariance carries
iSAM2's marginal of its newest pose through the odometry of the steps since
(:mod:`fgslam.smoother.online`).
"""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X


class OdometryChain:
    """Odometry links folded into one compound relative pose (a keyframe's compound factor,
    or the odometry since the newest pose in iSAM2).

    Each link is an increment z_j with covariance Σ_j in GTSAM's convention (the error
    Log(z_j⁻¹ · T_{j−1}⁻¹ T_j) lives in the frame at the link's end). The compound
    z = z_1 ⋯ z_m carries Σ = Σ_j A_j Σ_j A_jᵀ with A_j = Ad((z_{j+1} ⋯ z_m)⁻¹), which moves
    link j's error to the frame at the chain's end: the first-order marginal of the poses
    in between, which only the chain constrains.
    """

    def __init__(self, start: int):
        self.start = start  # pose index the chain starts from (a keyframe)
        self.links: list[tuple[gtsam.Pose2, np.ndarray]] = []
        self.compound = gtsam.Pose2()
        self._cov = np.zeros((3, 3))

    def extended(self, increment: gtsam.Pose2, covariance: np.ndarray) -> tuple[gtsam.Pose2, np.ndarray]:
        """(compound, covariance) of this chain with one more link, the chain unchanged."""
        A = increment.inverse().AdjointMap()
        return self.compound.compose(increment), A @ self._cov @ A.T + covariance

    def append(self, increment: gtsam.Pose2, covariance: np.ndarray) -> None:
        self.compound, self._cov = self.extended(increment, covariance)
        self.links.append((increment, covariance))

    def covariance(self) -> np.ndarray:
        return 0.5 * (self._cov + self._cov.T)

    def dead_reckoned(self, start: gtsam.Pose2) -> np.ndarray:
        """(m, 3): the poses after ``start``, composed link by link."""
        out, pose = np.empty((len(self.links), 3)), start
        for j, (z, _) in enumerate(self.links):
            pose = pose.compose(z)
            out[j] = (pose.x(), pose.y(), pose.theta())
        return out

    def poses(self, start: gtsam.Pose2, end: gtsam.Pose2) -> np.ndarray:
        """(m − 1, 3): the interior poses, given the estimates of both ends.

        The chain's residual ξ = Log(z⁻¹ · start⁻¹ · end) is split over the links by least
        squares: ε_j = Σ_j A_jᵀ Σ⁻¹ ξ (the most probable link errors that add up to ξ), and
        pose i = start · z_1 Exp(ε_1) ⋯ z_i Exp(ε_i). With ε_j so chosen the links' cost
        Σ ε_jᵀ Σ_j⁻¹ ε_j equals ξᵀ Σ⁻¹ ξ, the compound factor's.
        """
        xi = gtsam.Pose2.Logmap(self.compound.between(start.between(end)))
        weight = np.linalg.solve(self.covariance(), xi)  # Σ⁻¹ ξ
        suffix = gtsam.Pose2()  # z_{j+1} ⋯ z_m, built from the end
        eps = [None] * len(self.links)
        for j in range(len(self.links) - 1, -1, -1):
            z, cov = self.links[j]
            A = suffix.inverse().AdjointMap()
            eps[j] = cov @ (A.T @ weight)
            suffix = z.compose(suffix)
        out, pose = np.empty((len(self.links) - 1, 3)), start
        for j in range(len(self.links) - 1):
            pose = pose.compose(self.links[j][0]).compose(gtsam.Pose2.Expmap(eps[j]))
            out[j] = (pose.x(), pose.y(), pose.theta())
        return out


def add_links(graph: gtsam.NonlinearFactorGraph, chain: OdometryChain) -> None:
    """One ``BetweenFactorPose2`` per odometry link of ``chain``."""
    for j, (z, cov) in enumerate(chain.links):
        a = chain.start + j
        graph.add(gtsam.BetweenFactorPose2(X(a), X(a + 1), z, gtsam.noiseModel.Gaussian.Covariance(cov)))
