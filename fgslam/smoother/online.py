"""The online estimate: the newest pose, its covariance, predicted NIS, landmark marginals.

:class:`OnlinePose` is what a live robot acts on: iSAM2's estimate of the newest pose it
holds, composed with the odometry of the steps since (held steps, or the poses after the
last keyframe). Its covariance is iSAM2's marginal of that pose carried through the same
odometry, so asking for it never flushes held steps nor changes when iSAM2 updates.
Marginals come from ``isam.marginalCovariance`` / ``jointMarginalCovariance``, which use
the Bayes tree and do not recompute the whole graph's marginals.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import L, T, X

from ekf.observation import observation_nis
from fgslam.smoother.chain import FloatChain, OdometryChain
from fgslam.smoother.factors import end_frame_covariance_entries, odometry_noise_covariance
from slamio.geometry import wrap_angle
from slamio.log import Odometry, Step


class OnlinePose:
    """The newest pose and the odometry since the newest pose in iSAM2."""

    def __init__(self):
        self.pose: gtsam.Pose2 | None = None  # latest pose: iSAM2's after an update, else ⊕ odometry
        # odometry records since the newest pose in iSAM2, for the online covariance, each
        # with the observations the online correction used at that step; kept raw (their
        # Pose2 increments are built only when a covariance is asked for), so a step costs
        # one list append
        self._since: list[tuple[Odometry, tuple]] = []
        self._anchor: gtsam.Pose2 | None = None  # iSAM2's estimate of its newest pose
        # current_covariance() is asked at every step (NEES): the marginal is kept until
        # iSAM2 changes, and the held odometry is propagated only once per record
        self._marginal: np.ndarray | None = None
        # for the association (fgslam.smoother.pairings): built when first asked for after an
        # update (None until then: most updates of a log with ids never need it)
        self._since_chain: OdometryChain | None = None
        self._float_chain = FloatChain(0)  # the same in floats, for the covariance and the NIS
        # predicted_nis() asks at every step with readings for the joint marginal of the newest
        # iSAM2 pose and the landmarks read; until iSAM2 changes one joint over every landmark
        # asked for so far serves them all (a superset's blocks are the subset's joint marginal)
        self._joint: tuple[dict[int, int], np.ndarray] | None = None
        # current_covariance() of a corrected pose replays the correction's steps as an EKF
        # (_corrected_covariance); the replay is kept and carried on until iSAM2 changes
        self._replay: _Replay | None = None

    def moved(self, odometry: Odometry, used: tuple = ()) -> None:
        """Note one more step's odometry since the newest pose in iSAM2, and the
        observations the online correction used at it: ``(landmark_id, landmark_xy, range_m, bearing_rad, R)``."""
        self._since.append((odometry, used))

    def updated(self, pose: gtsam.Pose2, newest_in_isam: int, steps_after: int, anchor: gtsam.Pose2) -> None:
        """After an iSAM2 update: ``pose`` is the newest pose; the newest pose iSAM2 holds is
        ``newest_in_isam`` (estimated at ``anchor``) and only the last ``steps_after`` steps
        (the open keyframe chain) follow it."""
        self.pose = pose
        self._anchor = anchor
        self._since = self._since[len(self._since) - steps_after :] if steps_after else []
        self._since_chain = None
        self._float_chain = FloatChain(newest_in_isam)
        self.forget_marginal()

    def forget_marginal(self) -> None:
        """iSAM2 changed (an update, or the final updates without new poses): recompute the
        marginal, the NIS's joint and the replay when asked."""
        self._marginal = None
        self._joint = None
        self._replay = None

    def _joint_marginal(self, isam: gtsam.ISAM2, x_key: int, ids: list[int]) -> tuple[dict[int, int], np.ndarray]:
        """iSAM2's joint marginal of ``x_key`` and the landmarks ``ids`` (and of every landmark
        asked for since iSAM2 last changed: one joint serves later steps that read a subset), as
        ``(landmark id → its first row, the whole matrix)``, the pose in rows 0–2."""
        if self._joint is None or not set(ids) <= self._joint[0].keys():
            wanted = _union(sorted(self._joint[0]) if self._joint else (), ids)
            joint = isam.jointMarginalCovariance(gtsam.KeyVector([x_key] + [L(i) for i in wanted]))
            self._joint = ({lid: 3 + 2 * j for j, lid in enumerate(wanted)}, np.asarray(joint.fullMatrix(), dtype=float))
        return self._joint

    def _caught_up_since_chain(self) -> OdometryChain:
        """The odometry since the newest iSAM2 pose, with the records held since the last call."""
        chain = self._since_chain
        if chain is None:
            chain = self._since_chain = OdometryChain(self._float_chain.start)
        for odo, _ in self._since[len(chain.links) :]:
            chain.append(gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad), odometry_noise_covariance(odo))
        return chain

    def _caught_up_float_chain(self) -> FloatChain:
        """:meth:`_caught_up_since_chain` in floats (:class:`~fgslam.smoother.chain.FloatChain`)."""
        chain = self._float_chain
        for odo, _ in self._since[chain.count :]:
            chain.append(odo.dx_m, odo.dy_m, odo.dtheta_rad, end_frame_covariance_entries(odo.covariance, odo.dtheta_rad))
        return chain

    def covariance(self, isam: gtsam.ISAM2, frame: str) -> np.ndarray:
        """3×3 covariance of :attr:`pose` (see :meth:`Isam2Smoother.current_covariance`).
        ``isam`` may be a ``gtsam.Marginals`` when no step since the newest iSAM2 pose was
        corrected (after :meth:`Isam2Smoother.finish`)."""
        if any(used for _, used in self._since):  # the online correction moved the pose: the replay's
            cov = self._corrected_covariance(isam)  # (neither the pose's marginal nor the chain needed)
            if frame == "body":
                J = body_to_world(self.pose.theta())
                cov = J.T @ cov @ J
            return 0.5 * (cov + cov.T)
        chain = self._caught_up_float_chain()
        if self._marginal is None:
            self._marginal = np.asarray(isam.marginalCovariance(X(chain.start)), dtype=float)
        cov = self._marginal
        if chain.count:
            A = chain.compound.inverse().AdjointMap()
            cov = A @ cov @ A.T + chain.covariance()
        if frame == "world":
            J = body_to_world(self.pose.theta())
            cov = J @ cov @ J.T
        return 0.5 * (cov + cov.T)

    def _corrected_covariance(self, isam: gtsam.ISAM2) -> np.ndarray:
        """World-frame covariance of the corrected online pose, asked for only (never on the
        step path): the correction's steps replayed as a full EKF over the pose and the
        landmarks it used, from iSAM2's joint marginal of its newest pose and those
        landmarks, so the landmarks' uncertainty and their correlation with the pose count
        (the correction itself takes them as known).

        The replay is linearised where that joint marginal is: at iSAM2's linearisation
        point, not at its estimate. The two differ by up to a relinearisation threshold,
        and the joint's thin directions (a landmark seen a moment ago from the newest pose,
        to a few mm) are thin along the old geometry: a reading's Jacobian at the estimate
        cuts across them and reads information that is not there (a replayed live run:
        heading σ 0.003 rad against a 0.04 rad error, NEES up to 4 000). For the same reason
        the replay stays on the prediction from there (the linearisation point's pose ⊕ the
        odometry): moving its mean by the readings would turn the Jacobians again."""
        ids = [lid for _, used in self._since for lid, *_ in used]
        replay = self._replay
        if replay is None or not set(ids) <= set(replay.column):  # a landmark not in it: start over with all
            replay = self._replay = _Replay.start(isam, self._float_chain.start,
                                                  _union(replay.column if replay else (), ids))
        replay.run(self._since)  # only the steps since the last call: O(k) per step, not O(k²) per update
        return replay.P[:3, :3]

    def predicted_nis(self, isam: gtsam.ISAM2, step: Step, tag_ids: set[int]) -> list[float | None]:
        """NIS of each observation of ``step`` (see :meth:`Isam2Smoother.predicted_nis`)."""
        out: list[float | None] = [None] * len(step.observations)
        if self.pose is None or step.odometry is None:
            return out
        wanted = [
            (j, o) for j, o in enumerate(step.observations)
            if o.landmark_id is not None and o.landmark_id not in tag_ids
            and isam.valueExists(L(o.landmark_id))
        ]
        if not wanted:
            return out
        chain = self._caught_up_float_chain()
        odo = step.odometry
        compound, moved_cov = chain.extended(odo.dx_m, odo.dy_m, odo.dtheta_rad,
                                             end_frame_covariance_entries(odo.covariance, odo.dtheta_rad))
        A = compound.inverse().AdjointMap()
        # the prediction whose covariance this is: iSAM2's newest pose ⊕ the odometry since
        # (not the corrected online pose, whose correlation with the landmarks is unknown)
        pose = self._anchor.compose(compound)
        to_world = body_to_world(pose.theta())  # body → world at the new pose
        J = to_world @ A  # perturbation of the newest iSAM2 pose → world perturbation of the new pose
        x_key = X(chain.start)
        ids = list(dict.fromkeys(o.landmark_id for _, o in wanted))
        try:
            row, joint = self._joint_marginal(isam, x_key, ids)
        except RuntimeError:  # gtsam.IndeterminateSystemException: no marginal, so no NIS
            return out
        pose_cov = J @ joint[:3, :3] @ J.T + to_world @ moved_cov @ to_world.T
        mean = np.array([pose.x(), pose.y(), pose.theta()])
        for j, o in wanted:
            key = L(o.landmark_id)
            k = row[o.landmark_id]
            cov = np.empty((5, 5))
            cov[:3, :3] = pose_cov
            cov[:3, 3:] = J @ joint[:3, k : k + 2]
            cov[3:, :3] = cov[:3, 3:].T
            cov[3:, 3:] = joint[k : k + 2, k : k + 2]
            landmark = isam.calculateEstimatePoint2(key)
            out[j] = observation_nis(mean, landmark, cov, o)
        return out


def world_joint_marginal(isam: gtsam.ISAM2, since: OdometryChain, pose: gtsam.Pose2,
                         landmark_ids: list[int]) -> np.ndarray | None:
    """Covariance of [pose (world x, y, θ), landmark 0 (x, y), …] for the new pose ``pose``,
    which the odometry ``since`` links to the newest pose iSAM2 holds: iSAM2's joint marginal
    of that pose and ``L(id)`` for ``landmark_ids``, the pose carried through the odometry
    (Σ ← A Σ Aᵀ + Σ_z, cross-covariance ← A Σ_pl, A = Ad(z⁻¹)) and rotated into world
    (x, y, θ), as :meth:`fgslam.smoother.online.OnlinePose.predicted_nis` does. None when
    iSAM2 cannot form it."""
    x_key = X(since.start)
    if not isam.valueExists(x_key):
        return None
    to_world = body_to_world(pose.theta())
    J = to_world @ since.compound.inverse().AdjointMap()
    moved_world = to_world @ since.covariance() @ to_world.T
    try:
        if landmark_ids:  # one matrix, blocks in the keys' order (the same numbers as its at() blocks)
            keys = gtsam.KeyVector([x_key] + [L(i) for i in landmark_ids])
            joint = np.asarray(isam.jointMarginalCovariance(keys).fullMatrix(), dtype=float)
        else:
            joint = np.asarray(isam.marginalCovariance(x_key), dtype=float)
    except RuntimeError:  # gtsam.IndeterminateSystemException
        return None
    P = np.empty_like(joint)
    P[:3, :3] = J @ joint[:3, :3] @ J.T + moved_world
    P[:3, 3:] = J @ joint[:3, 3:]
    P[3:, :3] = P[:3, 3:].T
    P[3:, 3:] = joint[3:, 3:]
    return 0.5 * (P + P.T)


def _union(kept, ids) -> list[int]:
    """The landmarks of ``kept`` and then of ``ids``, each once, in that order."""
    return list(dict.fromkeys([*kept, *ids]))


class _Replay:
    """The full EKF :meth:`OnlinePose._corrected_covariance` replays over the newest iSAM2 pose
    and the landmarks the correction used, kept between calls: ``P`` and ``mean`` after the
    first ``steps`` held steps, linearised at iSAM2's linearisation point."""

    def __init__(self, P: np.ndarray, mean: np.ndarray, column: dict[int, int], landmark_at: dict[int, np.ndarray]):
        self.P, self.mean, self.column, self.landmark_at, self.steps = P, mean, column, landmark_at, 0

    @classmethod
    def start(cls, isam: gtsam.ISAM2, newest: int, ids: list[int]) -> "_Replay":
        """From iSAM2's joint marginal of pose ``newest`` and the landmarks ``ids``, in the world
        frame at iSAM2's linearisation point (:func:`world_joint_marginal`)."""
        linearisation = isam.getLinearizationPoint()
        anchor = linearisation.atPose2(X(newest))
        P = world_joint_marginal(isam, OdometryChain(newest), anchor, ids)
        if P is None:
            raise RuntimeError(f"iSAM2 cannot form the joint marginal of pose {newest} and landmarks {ids}")
        landmark_at = {lid: np.asarray(linearisation.atPoint2(L(lid)), dtype=float) for lid in ids}
        column = {lid: 3 + 2 * j for j, lid in enumerate(ids)}
        return cls(P, np.array([anchor.x(), anchor.y(), anchor.theta()]), column, landmark_at)

    def run(self, since: list) -> None:
        """Replay the held steps not replayed yet: predict with each odometry, then update
        with the readings the correction used there, along the prediction.

        The EKF of :mod:`ekf.models` (``F = ∂(pose ⊕ u)/∂pose``, ``G = ∂(pose ⊕ u)/∂u``, the
        range-bearing Jacobians) written for its sparsity: the predictions between two
        readings are gathered in a :class:`_Motion` (their F's product and pose noise, in
        floats) and applied to P at once, where F P Fᵀ is two row and two column updates in
        place; a reading's H has two non-zero blocks, so P Hᵀ is two block products and
        P − K S Kᵀ = P − K (P Hᵀ)ᵀ."""
        P = self.P
        x, y, th = (float(v) for v in self.mean)
        motion = _Motion()
        for odo, used in since[self.steps :]:
            dx, dy = odo.dx_m, odo.dy_m
            c, s = math.cos(th), math.sin(th)
            motion.add(-s * dx - c * dy, c * dx - s * dy, c, s, odo.covariance)
            x, y, th = x + c * dx - s * dy, y + s * dx + c * dy, wrap_angle(th + odo.dtheta_rad)
            if used:
                motion.apply(P)
                for lid, _, _, bearing_rad, R in used:
                    P = self._update(P, (x, y), lid, 2 if bearing_rad is not None else 1, R)
        motion.apply(P)
        self.P, self.mean, self.steps = P, np.array([x, y, th]), len(since)

    def _update(self, P: np.ndarray, position: tuple[float, float], lid: int, rows: int, R) -> np.ndarray:
        """P after one reading of landmark ``lid`` (``rows`` 1: its range alone) from ``position``."""
        landmark = self.landmark_at[lid]
        ex, ey = float(landmark[0]) - position[0], float(landmark[1]) - position[1]
        q = ex * ex + ey * ey
        r = math.sqrt(q)
        col = self.column[lid]
        rows_at = [0, 1, 2, col, col + 1]  # H = [H_pose | H_landmark] sits in these columns
        H = np.array([[-ex / r, -ey / r, 0.0, ex / r, ey / r], [ey / q, -ex / q, -1.0, -ey / q, ex / q]][:rows])
        U = P[:, rows_at] @ H.T  # P Hᵀ, n × rows
        S = H @ U[rows_at] + R
        if rows == 2:  # S⁻¹ of a 2×2 in closed form (numpy.linalg's call costs more than the sum)
            (s00, s01), (s10, s11) = S.tolist()
            d = s00 * s11 - s01 * s10
            S_inv = np.array([[s11 / d, -s01 / d], [-s10 / d, s00 / d]])
        else:
            S_inv = 1.0 / S
        K = U @ S_inv
        P = P - K @ U.T
        return 0.5 * (P + P.T)


class _Motion:
    """The odometry of replayed steps not yet applied to a replay's covariance P, in floats
    (numpy's per-call cost is most of a 3×3 product's): the product of their motion
    Jacobians, F = [[1, 0, a], [0, 1, b], [0, 0, 1]] (such F commute and their product adds
    the a's and b's), and the pose noise they added, each step's G Σ Gᵀ carried through the
    later steps' F (``q``, 3×3 row by row). Applying it to P is F P Fᵀ + q on the pose rows
    and columns: the per-step prediction's result, to rounding."""

    __slots__ = ("a", "b", "q")

    def __init__(self) -> None:
        self.a, self.b, self.q = 0.0, 0.0, None

    def add(self, a: float, b: float, c: float, s: float, covariance) -> None:
        """One step: its F (``a``, ``b``), and G = [[c, −s, 0], [s, c, 0], [0, 0, 1]] with the
        odometry's 3×3 ``covariance`` Σ."""
        (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = covariance
        m00, m01, m02 = c * s00 - s * s10, c * s01 - s * s11, c * s02 - s * s12  # G Σ
        m10, m11, m12 = s * s00 + c * s10, s * s01 + c * s11, s * s02 + c * s12
        added = [m00 * c - m01 * s, m00 * s + m01 * c, m02,  # (G Σ) Gᵀ
                 m10 * c - m11 * s, m10 * s + m11 * c, m12,
                 s20 * c - s21 * s, s20 * s + s21 * c, s22]
        q = self.q
        if q is not None:  # F q Fᵀ first: rows 0 and 1 gain a and b times row 2, then the columns
            q0, q1, q2, q3, q4, q5, q6, q7, q8 = q
            q0, q1, q2 = q0 + a * q6, q1 + a * q7, q2 + a * q8
            q3, q4, q5 = q3 + b * q6, q4 + b * q7, q5 + b * q8
            q0, q3, q6 = q0 + a * q2, q3 + a * q5, q6 + a * q8
            q1, q4, q7 = q1 + b * q2, q4 + b * q5, q7 + b * q8
            added = [q0 + added[0], q1 + added[1], q2 + added[2], q3 + added[3], q4 + added[4],
                     q5 + added[5], q6 + added[6], q7 + added[7], q8 + added[8]]
        self.q, self.a, self.b = added, self.a + a, self.b + b

    def apply(self, P: np.ndarray) -> None:
        """P ← F P Fᵀ + q in place on its pose rows and columns; then nothing is held."""
        if self.q is None:
            return
        a, b = self.a, self.b
        P[0, :] += a * P[2, :]
        P[1, :] += b * P[2, :]
        P[:, 0] += a * P[:, 2]
        P[:, 1] += b * P[:, 2]
        P[:3, :3] += np.array(self.q).reshape(3, 3)
        self.a, self.b, self.q = 0.0, 0.0, None


def landmark_covariances(marginals, estimate: gtsam.Values, landmark_ids, tag_ids) -> dict[int, np.ndarray]:
    """Landmark id → 2×2 world-frame marginal covariance of its (x, y) (for a tag, the
    position block of its Pose2 marginal rotated from the tag's frame, at its heading in
    ``estimate``). ``marginals`` is an ``ISAM2`` or a ``gtsam.Marginals``: anything with
    ``marginalCovariance(key)``."""
    out = {}
    for lid in landmark_ids:
        if lid in tag_ids:
            cov = np.asarray(marginals.marginalCovariance(T(lid)), dtype=float)[:2, :2]
            th = estimate.atPose2(T(lid)).theta()
            c, s = math.cos(th), math.sin(th)
            rot = np.array([[c, -s], [s, c]])
            out[lid] = rot @ cov @ rot.T
        else:
            out[lid] = np.asarray(marginals.marginalCovariance(L(lid)), dtype=float)
    return out


def body_to_world(theta_rad: float) -> np.ndarray:
    """3×3 map of a Pose2 perturbation in the robot's frame (GTSAM's convention) to world
    (x, y, θ) at heading ``theta_rad``."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
