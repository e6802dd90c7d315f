"""Textbook range-bearing EKF-SLAM with known landmark ids (Thrun et al., *Probabilistic
Robotics*, ch. 10), written so that every step costs O(n) or O(n²) in the state size n.

State layout
    ``mean = [x, y, θ, l1x, l1y, l2x, l2y, ...]`` — the robot pose first, then one 2-D
    point per landmark in the order the landmarks were first seen. ``P`` is the full
    joint covariance. Both live in buffers that grow by doubling their capacity, so adding
    thousands of landmarks copies the n×n matrix only O(log n) times. The covariance
    buffer is Fortran-ordered so that the one O(n²) pass of an update is a single in-place
    BLAS call (see :func:`add_low_rank_in_place`).

One step (:meth:`EkfSlam.step`)
    1. Predict with the odometry increment u (SE(2), previous robot frame) and its 3×3
       covariance Σ: ``pose ← pose ⊕ u``, ``Q = F_u Σ F_uᵀ``. Only the robot rows and
       columns of P change: ``P_rr ← F P_rr Fᵀ + Q`` and ``P_rm ← F P_rm`` — O(n).
    2. For every observation with a known ``landmark_id``, in log order:
       * first sighting → *augment* the state with the landmark placed by the inverse
         observation model, with its full cross-covariance to the robot and to every other
         landmark (``P_ll = G_p P_rr G_pᵀ + G_z R G_zᵀ``, ``P_lx = G_p P_rx``). The
         measurement is then fully used: it is not applied a second time as an update;
       * later sightings → one sequential EKF update with the bearing innovation wrapped,
         the Joseph-form covariance update in O(n²) (see :func:`joseph_factors`) and the
         heading wrapped.
       Observations with ``landmark_id is None`` are skipped and counted (data association
       is a separate concern).

The module-level functions are the filter's arithmetic (each one small and testable on
its own); :class:`EkfSlam` only holds the state and the bookkeeping.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import blas as _blas

from ekf.models import (
    landmark_from_range_bearing,
    landmark_init_jacobians,
    motion_jacobians,
    predict_pose,
    range_bearing,
    range_bearing_jacobians,
)
from slamio.geometry import wrap_angle
from slamio.log import Header, Observation, Step

__all__ = [
    "EkfSlam",
    "measurement_covariance",
    "predict_covariance",
    "augment_covariance",
    "kalman_gain",
    "joseph_factors",
    "joseph_update",
    "add_low_rank_in_place",
]

ROBOT_DIM = 3  # x_m, y_m, theta_rad
LANDMARK_DIM = 2  # x_m, y_m


# --------------------------------------------------------------------------- filter arithmetic


def measurement_covariance(observation: Observation) -> np.ndarray:
    """R = diag(σ_range², σ_bearing²) from the observation's own standard deviations."""
    return np.diag([observation.sigma_range_m**2, observation.sigma_bearing_rad**2])


def predict_covariance(P: np.ndarray, F_pose: np.ndarray, Q: np.ndarray) -> None:
    """Propagate the covariance through the motion model, **in place**, in O(n).

    ``P`` is the n×n joint covariance with the robot in rows/columns 0–2. The motion
    Jacobian of the full state is ``blockdiag(F_pose, I)``, so only the robot rows and
    columns change::

        P_rr ← F P_rr Fᵀ + Q,    P_rm ← F P_rm,    P_mr ← P_rmᵀ
    """
    r = slice(0, ROBOT_DIM)
    m = slice(ROBOT_DIM, P.shape[0])
    P[r, r] = F_pose @ P[r, r] @ F_pose.T + Q
    P[r, m] = F_pose @ P[r, m]
    P[m, r] = P[r, m].T


def augment_covariance(
    P: np.ndarray, n: int, G_pose: np.ndarray, G_measurement: np.ndarray, R: np.ndarray
) -> None:
    """Fill rows/columns ``n, n+1`` of ``P`` for a new landmark, **in place**, in O(n).

    ``P[:n, :n]`` is the covariance before augmentation; ``P`` must have room for two more
    rows and columns. The new landmark l = g(pose, z) gets

        P_ll = G_p P_rr G_pᵀ + G_z R G_zᵀ     (own covariance)
        P_lx = G_p P_rx                        (with the robot and every old landmark)
    """
    new = slice(n, n + LANDMARK_DIM)
    P_lx = G_pose @ P[:ROBOT_DIM, :n]  # 2×n
    P[new, :n] = P_lx
    P[:n, new] = P_lx.T
    P[new, new] = G_pose @ P[:ROBOT_DIM, :ROBOT_DIM] @ G_pose.T + G_measurement @ R @ G_measurement.T


def kalman_gain(
    P: np.ndarray, cols: np.ndarray, H_cols: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kalman gain for a measurement whose Jacobian H is zero outside the columns ``cols``.

    ``H_cols`` (m×k) holds the non-zero columns of the m×n Jacobian H. Returns
    ``(K n×m, S m×m, PHt n×m)`` with ``PHt = P Hᵀ``, ``S = H P Hᵀ + R`` and
    ``K = PHt S⁻¹``, all in O(n·k).
    """
    PHt = P[:, cols] @ H_cols.T
    S = H_cols @ PHt[cols, :] + R
    S = 0.5 * (S + S.T)
    K = np.linalg.solve(S, PHt.T).T
    return K, S, PHt


def joseph_factors(
    P: np.ndarray, cols: np.ndarray, H_cols: np.ndarray, K: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Factors ``(X, Y)``, both n×4m, of the Joseph-form update: ``P_new = P + X Yᵀ``.

    The Joseph form ``P_new = (I − KH) P (I − KH)ᵀ + K R Kᵀ`` is valid for any gain K
    (not only the optimal one). H is given by its non-zero columns ``cols`` and their values
    ``H_cols`` (m×k, k = 5 for a landmark observation), which makes it O(n²) instead of
    the O(n³) of the dense formula:

    * ``A = (I − KH) P = P − K (P Hᵀ)ᵀ``; only A's columns ``cols`` are formed (n×k);
    * ``A (I − KH)ᵀ = A − (A Hᵀ) Kᵀ`` with ``A Hᵀ = A[:, cols] H_colsᵀ`` (n×m);
    * so ``P_new = P + U Vᵀ`` with ``U = [−K, K R − A Hᵀ]`` and ``V = [P Hᵀ, K]`` (n×2m).

    The increment is returned symmetrised, ``½(U Vᵀ + V Uᵀ) = X Yᵀ`` with
    ``X = ½[U, V]`` and ``Y = [V, U]``: for a symmetric P this *is* the symmetric part of
    ``P + U Vᵀ``, obtained without a pass over P (``P ← ½(P + Pᵀ)`` would cost two, one
    of them a cache-unfriendly transpose). P stays symmetric to round-off, without drift.
    Everything here is O(n·k); no n×n identity or n×n×n product is formed.
    """
    Pc = P[:, cols]  # n×k
    PHt = Pc @ H_cols.T  # n×m
    A_cols = Pc - K @ PHt[cols, :].T  # columns `cols` of A = (I − KH) P
    AHt = A_cols @ H_cols.T  # A Hᵀ
    U = np.hstack([-K, K @ R - AHt])  # n×2m
    V = np.hstack([PHt, K])  # n×2m
    return 0.5 * np.hstack([U, V]), np.hstack([V, U])


def joseph_update(
    P: np.ndarray, cols: np.ndarray, H_cols: np.ndarray, K: np.ndarray, R: np.ndarray
) -> None:
    """Joseph-form covariance update ``P ← (I − KH) P (I − KH)ᵀ + K R Kᵀ``, **in place**, O(n²).

    See :func:`joseph_factors` for the arithmetic; the result is symmetrised.
    """
    X, Y = joseph_factors(P, cols, H_cols, K, R)
    P += X @ Y.T


def add_low_rank_in_place(buffer: np.ndarray, n: int, X: np.ndarray, Y: np.ndarray) -> None:
    """``buffer[:n, :n] += X Yᵀ`` for n×r factors X, Y, without an n×n temporary.

    This is the single O(n²) pass of an EKF update, so it is worth doing well: when
    ``buffer`` is Fortran-ordered, its first n columns ``buffer[:, :n]`` are one contiguous
    block and BLAS ``dgemm`` accumulates into it directly (X is padded with zero rows to
    the buffer's height, so rows n and beyond get ``+= 0``). That is about 3× faster than
    numpy's ``P += X @ Y.T`` on a strided view, which writes and re-reads a temporary.
    Any other buffer takes the plain numpy path.
    """
    block = buffer[:, :n]
    if block.flags.f_contiguous and buffer.dtype == np.float64:
        X_padded = np.zeros((buffer.shape[0], X.shape[1]), order="F")
        X_padded[:n] = X
        out = _blas.dgemm(1.0, X_padded, Y, beta=1.0, c=block, trans_b=1, overwrite_c=1)
        if not np.shares_memory(out, block):  # the wrapper had to copy: write it back
            block[...] = out
    else:
        buffer[:n, :n] += X @ Y.T


# --------------------------------------------------------------------------- the filter


class EkfSlam:
    """Range-bearing EKF-SLAM with known landmark ids (implements ``slamio.estimator.Estimator``).

    Built from the log header: the start mean is ``header.start_pose`` and the start
    covariance ``diag(header.start_sigma²)``. Feed it every :class:`~slamio.log.Step` in
    order with :meth:`step`; read the estimate with the accessors.

    Counters: ``updates`` (EKF updates applied), ``landmarks_added`` (state augmentations),
    ``skipped_unknown_id`` (observations without a landmark id, ignored).

    ``landmark_capacity`` is only the initial room for landmarks; the storage doubles
    whenever it is full, so it never limits the map.
    """

    name = "ekf"

    def __init__(self, header: Header, *, landmark_capacity: int = 16):
        capacity = ROBOT_DIM + LANDMARK_DIM * max(1, int(landmark_capacity))
        self._mean = np.zeros(capacity)
        self._cov = np.zeros((capacity, capacity), order="F")  # see add_low_rank_in_place
        self._dim = ROBOT_DIM
        self._mean[:ROBOT_DIM] = header.start_pose
        self._mean[2] = wrap_angle(float(self._mean[2]))
        self._cov[:ROBOT_DIM, :ROBOT_DIM] = np.diag(np.square(header.start_sigma))
        self._slot: dict[int, int] = {}  # landmark id → index of its x in the state
        self._trajectory: list[tuple[float, float, float]] = []
        self.updates = 0
        self.landmarks_added = 0
        self.skipped_unknown_id = 0

    # ------------------------------------------------------------------ protocol

    def step(self, step: Step) -> None:
        """Predict with ``step.odometry`` (if any), then apply each observation in turn."""
        if step.odometry is not None:
            self._predict(step.odometry)
        for observation in step.observations:
            if observation.landmark_id is None:
                self.skipped_unknown_id += 1
            elif observation.landmark_id in self._slot:
                self._update(observation)
            else:
                self._add_landmark(observation)
        self._trajectory.append(self.current_pose())

    def current_pose(self) -> tuple[float, float, float]:
        """The current robot pose estimate ``(x_m, y_m, theta_rad)``."""
        x, y, th = self._mean[:ROBOT_DIM]
        return float(x), float(y), float(th)

    def finish(self) -> None:
        """Nothing to do: a filter's estimate is final as soon as a step is consumed."""

    def trajectory(self) -> np.ndarray:
        """(n, 3) array: the pose estimate right after each step (for a filter, online = final)."""
        return np.array(self._trajectory, dtype=float).reshape(-1, ROBOT_DIM)

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark id → estimated ``(x_m, y_m)``, in the order the landmarks were first seen."""
        return {lid: (float(self._mean[i]), float(self._mean[i + 1])) for lid, i in self._slot.items()}

    # ------------------------------------------------------------------ more accessors

    def current_covariance(self) -> np.ndarray:
        """3×3 covariance of the current robot pose (a copy)."""
        return self._cov[:ROBOT_DIM, :ROBOT_DIM].copy()

    def landmark_covariance(self, landmark_id: int) -> np.ndarray:
        """2×2 covariance of one landmark (a copy). Raises ``KeyError`` for an unseen id."""
        i = self._slot[landmark_id]
        return self._cov[i : i + LANDMARK_DIM, i : i + LANDMARK_DIM].copy()

    def state_mean(self) -> np.ndarray:
        """The full state vector ``[x, y, θ, l1x, l1y, ...]`` (a copy)."""
        return self._mean[: self._dim].copy()

    def state_covariance(self) -> np.ndarray:
        """The full n×n joint covariance (a copy; O(n²))."""
        return self._cov[: self._dim, : self._dim].copy()

    def landmark_index(self, landmark_id: int) -> int:
        """Index of the landmark's x coordinate in :meth:`state_mean` (y follows it)."""
        return self._slot[landmark_id]

    @property
    def capacity(self) -> int:
        """Allocated state size; grows by doubling (always ≥ the state size)."""
        return self._mean.shape[0]

    # ------------------------------------------------------------------ the three operations

    def _predict(self, odometry) -> None:
        increment = (odometry.dx_m, odometry.dy_m, odometry.dtheta_rad)
        pose = self._mean[:ROBOT_DIM]
        F_pose, F_increment = motion_jacobians(pose, increment)
        Q = F_increment @ np.asarray(odometry.covariance, dtype=float) @ F_increment.T
        self._mean[:ROBOT_DIM] = predict_pose(pose, increment)
        predict_covariance(self._cov[: self._dim, : self._dim], F_pose, Q)

    def _add_landmark(self, observation: Observation) -> None:
        n = self._dim
        self._reserve(n + LANDMARK_DIM)
        pose = self._mean[:ROBOT_DIM]
        R = measurement_covariance(observation)
        self._mean[n : n + LANDMARK_DIM] = landmark_from_range_bearing(
            pose, observation.range_m, observation.bearing_rad
        )
        G_pose, G_measurement = landmark_init_jacobians(pose, observation.range_m, observation.bearing_rad)
        augment_covariance(self._cov, n, G_pose, G_measurement, R)
        self._slot[observation.landmark_id] = n  # type: ignore[index]
        self._dim = n + LANDMARK_DIM
        self.landmarks_added += 1

    def _update(self, observation: Observation) -> None:
        n = self._dim
        i = self._slot[observation.landmark_id]  # type: ignore[index]
        mean = self._mean[:n]
        P = self._cov[:n, :n]
        pose, landmark = mean[:ROBOT_DIM], mean[i : i + LANDMARK_DIM]
        predicted_range, predicted_bearing = range_bearing(pose, landmark)
        H_pose, H_landmark = range_bearing_jacobians(pose, landmark)
        cols = np.array([0, 1, 2, i, i + 1])
        H_cols = np.hstack([H_pose, H_landmark])
        R = measurement_covariance(observation)
        innovation = np.array(
            [
                observation.range_m - predicted_range,
                wrap_angle(observation.bearing_rad - predicted_bearing),
            ]
        )
        K, _, _ = kalman_gain(P, cols, H_cols, R)
        mean += K @ innovation
        mean[2] = wrap_angle(float(mean[2]))
        add_low_rank_in_place(self._cov, n, *joseph_factors(P, cols, H_cols, K, R))
        self.updates += 1

    def _reserve(self, needed: int) -> None:
        """Make room for a state of size ``needed``, doubling the capacity when it is full."""
        capacity = self._mean.shape[0]
        if needed <= capacity:
            return
        while capacity < needed:
            capacity *= 2
        n = self._dim
        mean = np.zeros(capacity)
        mean[:n] = self._mean[:n]
        cov = np.zeros((capacity, capacity), order="F")
        cov[:n, :n] = self._cov[:n, :n]
        self._mean, self._cov = mean, cov
