"""A chain of odometry links folded into one compound relative pose, with its covariance.

Used twice: with keyframes the odometry between two keyframes becomes one
``BetweenFactorPose2`` (:mod:`fgslam.smoother.policy`), and the online covariance carries
iSAM2's marginal of its newest pose through the odometry of the steps since
(:mod:`fgslam.smoother.online`).
"""

from __future__ import annotations

import math

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


class FloatChain:
    """:class:`OdometryChain`'s compound and covariance kept in Python floats, for the online
    covariance and predicted NIS (:mod:`fgslam.smoother.online`), which rebuild the chain of
    every step held since iSAM2's last update at each step they are taken at: there a
    ``gtsam.Pose2`` and numpy 3×3 products per link cost most of the work. The same maths
    (compound z = z_1 ⋯ z_m, Σ ← A Σ Aᵀ + Σ_j with A = Ad(z_j⁻¹)), so the same numbers to
    rounding; the association (:mod:`fgslam.smoother.pairings`) keeps :class:`OdometryChain`.

    Links are odometry increments ``(dx_m, dy_m, dθ_rad)`` with their covariance in GTSAM's
    end-frame convention, given as its upper triangle ``(xx, xy, xθ, yy, yθ, θθ)``
    (:func:`fgslam.smoother.factors.end_frame_covariance_entries`)."""

    __slots__ = ("start", "count", "_x", "_y", "_c", "_s", "_cov")

    def __init__(self, start: int):
        self.start = start  # pose index the chain starts from
        self.count = 0  # links so far
        self._x, self._y, self._c, self._s = 0.0, 0.0, 1.0, 0.0  # the compound: translation, cos and sin of its turn
        self._cov = (0.0,) * 9  # row by row

    def append(self, dx: float, dy: float, dtheta: float, covariance) -> None:
        self._x, self._y, self._c, self._s, self._cov = self._extended(dx, dy, dtheta, covariance)
        self.count += 1

    def extended(self, dx: float, dy: float, dtheta: float, covariance) -> tuple[gtsam.Pose2, np.ndarray]:
        """(compound, covariance) with one more link, the chain unchanged."""
        x, y, c, s, cov = self._extended(dx, dy, dtheta, covariance)
        return gtsam.Pose2(x, y, math.atan2(s, c)), _symmetric(cov)

    @property
    def compound(self) -> gtsam.Pose2:
        return gtsam.Pose2(self._x, self._y, math.atan2(self._s, self._c))

    def covariance(self) -> np.ndarray:
        return _symmetric(self._cov)

    def _extended(self, dx, dy, dtheta, covariance):
        cd, sd = math.cos(dtheta), math.sin(dtheta)
        x, y, c, s = self._x, self._y, self._c, self._s
        # A = Ad(z⁻¹) for z = (dx, dy, dθ): z⁻¹ = (Rᵀ(−t), −dθ), Ad(R, t) = [[R, (t_y, −t_x)ᵀ], [0, 0, 1]]
        tx, ty = -cd * dx - sd * dy, sd * dx - cd * dy
        a00, a01, a02, a10, a11, a12 = cd, sd, ty, -sd, cd, -tx
        p0, p1, p2, p3, p4, p5, p6, p7, p8 = self._cov
        m00, m01, m02 = a00 * p0 + a01 * p3 + a02 * p6, a00 * p1 + a01 * p4 + a02 * p7, a00 * p2 + a01 * p5 + a02 * p8
        m10, m11, m12 = a10 * p0 + a11 * p3 + a12 * p6, a10 * p1 + a11 * p4 + a12 * p7, a10 * p2 + a11 * p5 + a12 * p8
        xx, xy, xt, yy, yt, tt = covariance
        cov = (a00 * m00 + a01 * m01 + a02 * m02 + xx, a10 * m00 + a11 * m01 + a12 * m02 + xy, m02 + xt,
               a00 * m10 + a01 * m11 + a02 * m12 + xy, a10 * m10 + a11 * m11 + a12 * m12 + yy, m12 + yt,
               a00 * p6 + a01 * p7 + a02 * p8 + xt, a10 * p6 + a11 * p7 + a12 * p8 + yt, p8 + tt)
        return x + c * dx - s * dy, y + s * dx + c * dy, c * cd - s * sd, s * cd + c * sd, cov


def _symmetric(entries) -> np.ndarray:
    """½ (Σ + Σᵀ) of a 3×3 given row by row."""
    cov = np.reshape(entries, (3, 3))
    return 0.5 * (cov + cov.T)
