"""``ekf-vio``: a textbook visual-inertial EKF-SLAM on SE(3) for seed 003's drives (numpy only).

State: the IMU pose ``T = world_T_imu`` and every initialised landmark ``m_j`` (world,
metres). Covariance over ``(δ, m_1, …, m_n)`` with ``δ = (ρ, φ)`` the *right* perturbation
``T = T̂ exp(δ^)``. Unlike seed 003, the camera corrects the pose and the landmarks jointly.

* **Prediction** with the IMU twist ``u = (v, ω)`` held over τ:
  ``T ← T exp(τ u^)``, ``Σ_δδ ← F Σ_δδ Fᵀ + G Σ_u Gᵀ``, ``Σ_δm ← F Σ_δm`` with
  ``F = Ad(exp(−τ u^)) = exp(−τ Û)`` (seed 003's 6×6 matrix) and ``G = τ J_r(τ u)``.
* **Observation** of landmark m: ``p = T⁻¹ m`` (IMU frame), ``q = ₒT_I p``,
  ``z = M π(q)`` (slamio.stereo), with Jacobians
  ``∂z/∂δ = −M π′(q) ₒT_I p⊙`` and ``∂z/∂m = M π′(q) ₒT_I T⁻¹ D``.
* **Update**: every known landmark seen now is gated alone (NIS against χ²₄ at
  ``gate``, χ²₄ at 0.999 by default; rejected ones are counted), the survivors are stacked and applied
  in one update ``Σ ← Σ − K S Kᵀ`` (symmetrised; O(n² m)); the pose takes ``T ← T exp(δ̂^)``.
* **New landmarks** (disparity ≥ ``min_disparity_px``): back-projected through the
  current pose, with the cross-covariance of a proper EKF-SLAM augmentation
  ``Σ_mm = A Σ_δδ Aᵀ + B R Bᵀ``, ``Σ_mx = A Σ_δx``, ``A = R_wi [I, −p^]``,
  ``B = R_wi R_ic ∂(back-projection)/∂z``.

The pixel noise R is the 4×4 covariance of (u_L, v_L, u_R, v_R) (``StereoImuNoise.pixel_cov``:
σ_px² I, or a stated covariance with σ_u ≠ σ_v and v_L, v_R correlated); a stacked update
uses R on each landmark's block.

**First-estimate Jacobians** (``first_estimates=True``, the estimator ``ekf-vio-fej``;
Huang, Mourikis & Roumeliotis' FEJ-EKF carried to this right-perturbation SE(3) state).
The system is invariant under a global rigid motion of the world (no gravity here), so
the linearised system should have the 6-D unobservable subspace
``N = [Ad(T⁻¹); m⊙ …]``; the EKF loses it because each Jacobian is evaluated at a
different estimate, and then gains information along it (the NEES grows). With FEJ:

* the unobservable subspace is the one at the first estimates: ``N = [Ad(T_fe⁻¹); [I, −m_fe^] …]``
  with ``m_fe`` each landmark's first estimate (its back-projection) and ``T_fe`` the
  pose's prior ``T_{k|k−1}``;
* the propagation Jacobian becomes ``F = Ad(T_fe,k+1⁻¹ T_fe,k) = Ad(exp(−τ u^) T_{k|k}⁻¹ T_{k|k−1})``
  (equal to the usual one when step k had no update), so that ``F N_k = N_{k+1}``;
* a new landmark's ``∂m/∂δ`` is evaluated at ``T_fe`` too, so its rows of N are ``[I, −m_fe^]``;
* each observation's Jacobian ``H = [∂z/∂δ, ∂z/∂m]`` is evaluated at the prior pose and the
  landmark's *current* estimate, then projected so that it is blind to N
  (:func:`constrained_jacobians`: ``H (I − U (UᵀU)⁻¹ Uᵀ)``, ``U`` the pose's and this
  landmark's rows of N; the observability-constrained EKF of Huang, Mourikis & Roumeliotis
  2010 and Hesch et al. 2014). ``projected_jacobians=False`` evaluates H at ``m_fe``
  instead (plain FEJ), which satisfies ``H U = 0`` too but keeps a landmark's first depth
  error in its Jacobian for good: a far point back-projected 5 m too near or too far scales
  the translation columns by ±15 % against the rotation ones, and the filter then separates
  pitch and roll from height more sharply than the data allow (measured in docs/seed003.md).

Residuals always use the current estimates; only the Jacobians change.

**A bounded state** (``marginalise_after``, ``max_landmarks``). Keeping every landmark ever
seen makes the state grow with the drive and each update cost O(n²): a 1 100-step drive
with 2 000 features took minutes and gigabytes. A landmark whose id has not been in a step's
observations for ``marginalise_after`` steps (default :data:`MARGINALISE_AFTER`) is
*marginalised* at the end of the step: its three rows and columns leave the state and the
covariance. For a Gaussian that is the exact marginal (the remaining block of Σ is the
covariance of the remaining variables; nothing else changes), so as long as the landmark is
never observed again the filter's pose and every other landmark are exactly those of the
filter that keeps it (the update reads only the pose's and the seen landmarks' columns).
A landmark seen again after it was marginalised starts afresh as a new landmark (its old
information about the pose is kept in the pose; the link to its old estimate — a loop
closure — is what is given up). ``max_landmarks`` (default :data:`MAX_LANDMARKS`) caps the
state even when many features are in view: beyond it, the least recently seen landmarks go
first. ``landmarks()`` still reports every landmark: a marginalised one with its estimate
at the moment it left. ``None`` for either keeps every landmark (the unbounded filter).
"""

from __future__ import annotations

import numpy as np

from slamio.se3 import adjoint, curly_hat, exp_se3, inverse, log_se3, odot, skew
from slamio.stereo import (
    point_from_stereo,
    point_from_stereo_jacobian,
    projection,
    projection_jacobian,
    stereo_matrix,
)
from slamio.datasets.seed003 import StereoImuNoise

__all__ = [
    "CHI2_4_999",
    "VioEkf",
    "constrained_jacobians",
    "observation_jacobians",
    "pose_nees",
    "predict_stereo",
    "right_jacobian_se3",
]

POSE_DIM = 6
#: steps a landmark may go unseen before it is marginalised (seed 003's real tracks have no gaps)
MARGINALISE_AFTER = 10
#: the most landmarks kept in the state (the least recently seen are marginalised first)
MAX_LANDMARKS = 300
CHI2_4_999 = 18.4668  # χ²₄ quantile at 0.999
_EYE3 = np.eye(3)


def right_jacobian_se3(xi, terms: int = 12) -> np.ndarray:
    """SE(3) right Jacobian ``J_r(ξ) = Σ_k (−ξ⋏)^k / (k+1)!`` (series; |ξ| here is small)."""
    A = -curly_hat(xi)
    out = np.eye(6)
    term = np.eye(6)
    for k in range(1, terms):
        term = term @ A / (k + 1)
        out = out + term
    return out


def predict_stereo(world_T_imu, m_world, cam_T_imu, M) -> np.ndarray:
    """Predicted pixels (u_L, v_L, u_R, v_R) of world point ``m_world`` from pose ``world_T_imu``."""
    q = cam_T_imu @ inverse(world_T_imu) @ np.append(m_world, 1.0)
    return M @ projection(q)


def observation_jacobians(world_T_imu, m_world, cam_T_imu, M) -> tuple[np.ndarray, np.ndarray]:
    """(4×6 ∂z/∂δ for the right pose perturbation, 4×3 ∂z/∂m)."""
    return _observation_jacobians(inverse(world_T_imu), m_world, cam_T_imu, M)


def _homogeneous(m) -> np.ndarray:
    """``(m, 1)``: ``np.append(m, 1.0)`` of a 3-vector, without its generality."""
    out = np.empty(4)
    out[:3] = m
    out[3] = 1.0
    return out


def _observation_jacobians(T_inv, m_world, cam_T_imu, M) -> tuple[np.ndarray, np.ndarray]:
    """:func:`observation_jacobians` given ``T_inv`` = ``inverse(world_T_imu)`` (one per step)."""
    p = T_inv @ _homogeneous(m_world)
    q = cam_T_imu @ p
    A = M @ projection_jacobian(q) @ cam_T_imu
    return -A @ odot(p), A[:, :3] @ T_inv[:3, :3]


def constrained_jacobians(world_T_imu, m_world, m_first, cam_T_imu, M) -> tuple[np.ndarray, np.ndarray]:
    """:func:`observation_jacobians` at ``(world_T_imu, m_world)``, projected (least change in
    the Frobenius norm) onto the matrices blind to a rigid motion of the world linearised at
    ``(world_T_imu, m_first)``: ``H U = 0`` with ``U = [Ad(T⁻¹); [I, −m_first^]]`` (9×6)."""
    T_inv = inverse(world_T_imu)
    return _constrained_jacobians(T_inv, adjoint(T_inv), m_world, m_first, cam_T_imu, M)


def _constrained_jacobians(T_inv, adjoint_T_inv, m_world, m_first, cam_T_imu, M) -> tuple[np.ndarray, np.ndarray]:
    """:func:`constrained_jacobians` given ``T_inv`` and ``adjoint(T_inv)`` (one per step)."""
    H = np.empty((4, POSE_DIM + 3))
    H[:, :POSE_DIM], H[:, POSE_DIM:] = _observation_jacobians(T_inv, m_world, cam_T_imu, M)
    U = np.zeros((POSE_DIM + 3, POSE_DIM))  # [Ad(T⁻¹); [I, −m_first^]]
    U[:POSE_DIM] = adjoint_T_inv
    U[POSE_DIM:, :3] = _EYE3
    U[POSE_DIM:, 3:] = -skew(m_first)
    H = H - (H @ U) @ np.linalg.solve(U.T @ U, U.T)
    return H[:, :POSE_DIM], H[:, POSE_DIM:]


class VioEkf:
    """Joint pose + landmark EKF (implements the ``ekf.drive3d`` step protocol).

    ``VioEkf(K, baseline_m, cam_T_imu, noise=StereoImuNoise(), min_disparity_px=4.0,
    gate=CHI2_4_999, marginalise_after=MARGINALISE_AFTER, max_landmarks=MAX_LANDMARKS)``
    (``gate=None``: no gating; ``marginalise_after=None, max_landmarks=None``: every landmark
    stays in the state). ``first_estimates=True`` is ``ekf-vio-fej`` (module docstring), with
    its observation Jacobians projected unless ``projected_jacobians=False``. Counters:
    ``updates``, ``landmarks_added``, ``marginalised``, ``rejected`` (gated out),
    ``skipped_small_disparity``, ``skipped_behind``.
    """

    name = "ekf-vio"

    def __init__(
        self,
        K,
        baseline_m: float,
        cam_T_imu,
        noise: StereoImuNoise = StereoImuNoise(),
        *,
        min_disparity_px: float = 4.0,
        gate: float | None = CHI2_4_999,
        start_sigma: float = 1e-6,
        first_estimates: bool = False,
        projected_jacobians: bool = True,
        marginalise_after: int | None = MARGINALISE_AFTER,
        max_landmarks: int | None = MAX_LANDMARKS,
    ):
        for value, what in ((marginalise_after, "marginalise_after"), (max_landmarks, "max_landmarks")):
            if value is not None and int(value) < 1:
                raise ValueError(f"{what} must be at least 1 (or None: keep every landmark), got {value!r}")
        self.marginalise_after = None if marginalise_after is None else int(marginalise_after)
        self.max_landmarks = None if max_landmarks is None else int(max_landmarks)
        self._k = -1  # index of the current step
        self._last_seen: dict[int, int] = {}  # landmark in the state → last step its id was observed
        self._left: dict[int, np.ndarray] = {}  # marginalised landmark → its estimate when it left
        self.first_estimates = bool(first_estimates)
        self.projected_jacobians = bool(projected_jacobians)  # with first_estimates (module docstring)
        if self.first_estimates:
            self.name = "ekf-vio-fej"
        self._T_fe = np.eye(4)  # the pose's prior T_{k|k−1} (first-estimate Jacobians)
        self._m_fe: dict[int, np.ndarray] = {}  # each landmark's first estimate
        self.K = np.asarray(K, dtype=float)
        self.baseline_m = float(baseline_m)
        self.cam_T_imu = np.asarray(cam_T_imu, dtype=float)
        self.imu_T_cam = inverse(self.cam_T_imu)
        self.M = stereo_matrix(self.K, self.baseline_m)
        self.noise = noise
        self.min_disparity_px = float(min_disparity_px)
        self.gate = gate
        self._R = noise.pixel_cov()
        self._T = np.eye(4)
        self._x = np.zeros(0)  # landmark coordinates, 3 per landmark in slot order
        self._P = start_sigma**2 * np.eye(POSE_DIM)
        self._slot: dict[int, int] = {}
        self._trajectory: list[np.ndarray] = []
        self._nis: list[float] = []
        self.updates = 0
        self.landmarks_added = 0
        self.marginalised = 0
        self.rejected = 0
        self.skipped_small_disparity = 0
        self.skipped_behind = 0

    # ------------------------------------------------------------------ protocol

    def step(self, dt_s, twist, ids, pixels) -> None:
        if dt_s is not None:
            self._predict(float(dt_s), np.asarray(twist, dtype=float))
        self._k += 1
        ids = [int(i) for i in ids]
        pixels = np.asarray(pixels, dtype=float).reshape(-1, 4)
        known = [(lid, z) for lid, z in zip(ids, pixels) if lid in self._slot]
        if known:
            self._update(known)
        for lid, z in zip(ids, pixels):
            if lid not in self._slot:
                self._add(lid, z)
        for lid in ids:
            if lid in self._slot:
                self._last_seen[lid] = self._k
        self.marginalise(self._stale())
        self._trajectory.append(self._T.copy())

    def current_pose(self) -> np.ndarray:
        return self._T.copy()

    def current_covariance(self) -> np.ndarray:
        """6×6 covariance of the right perturbation (ρ, φ) of the current pose."""
        return self._P[:POSE_DIM, :POSE_DIM].copy()

    def trajectory(self) -> np.ndarray:
        return np.array(self._trajectory).reshape(-1, 4, 4)

    def landmarks(self) -> dict[int, np.ndarray]:
        """Every landmark's estimate: those in the state now, and the marginalised ones as they
        were when they left (a landmark re-initialised since then: its new estimate)."""
        live = {lid: self._x[3 * s : 3 * s + 3].copy() for lid, s in self._slot.items()}
        return {**{lid: m.copy() for lid, m in self._left.items() if lid not in live}, **live}

    def state_landmark_ids(self) -> list[int]:
        """The landmarks in the state now, in slot order."""
        return sorted(self._slot, key=self._slot.__getitem__)

    def state_covariance(self) -> np.ndarray:
        """The whole covariance over (δ, m_1, …, m_n), slots in :meth:`state_landmark_ids` order."""
        return self._P.copy()

    def marginalise(self, lids) -> None:
        """Marginalise the landmarks ``lids`` (those in the state): drop their rows and columns
        of the mean and the covariance — the exact Gaussian marginal of the rest."""
        drop = {int(lid) for lid in lids if int(lid) in self._slot}
        if not drop:
            return
        kept = [lid for lid in self.state_landmark_ids() if lid not in drop]
        slots = np.array([self._slot[lid] for lid in kept], dtype=int)
        idx = np.concatenate([np.arange(POSE_DIM), (POSE_DIM + 3 * slots[:, None] + np.arange(3)).ravel()])
        for lid in drop:
            self._left[lid] = self._landmark(lid).copy()
            self._m_fe.pop(lid, None)
            self._last_seen.pop(lid, None)
        self._x = self._x[(3 * slots[:, None] + np.arange(3)).ravel()]
        self._P = self._P[np.ix_(idx, idx)]
        self._slot = {lid: i for i, lid in enumerate(kept)}
        self.marginalised += len(drop)

    def _stale(self) -> list[int]:
        """The landmarks to marginalise after this step: unseen for ``marginalise_after`` steps,
        then the least recently seen beyond ``max_landmarks``."""
        last = self._last_seen
        stale = []
        if self.marginalise_after is not None:
            stale = [lid for lid, k in last.items() if self._k - k >= self.marginalise_after]
        excess = len(self._slot) - len(stale) - (self.max_landmarks if self.max_landmarks is not None else len(self._slot))
        if excess > 0:
            gone = set(stale)
            rest = sorted((lid for lid in self._slot if lid not in gone), key=lambda lid: (last[lid], self._slot[lid]))
            stale += rest[:excess]
        return stale

    def nis(self) -> np.ndarray:
        """NIS of every accepted single-landmark innovation (χ²₄ if consistent)."""
        return np.array(self._nis)

    # ------------------------------------------------------------------ the steps

    def _predict(self, tau: float, u: np.ndarray) -> None:
        if self.first_estimates:  # F N_k = N_{k+1} with N at the priors (module docstring)
            F = adjoint(exp_se3(-tau * u) @ inverse(self._T) @ self._T_fe)
        else:
            F = adjoint(exp_se3(-tau * u))
        self._T = self._T @ exp_se3(tau * u)
        self._T_fe = self._T.copy()
        G = tau * right_jacobian_se3(tau * u)
        P = self._P
        P[:POSE_DIM, :] = F @ P[:POSE_DIM, :]
        P[:, :POSE_DIM] = P[:, :POSE_DIM] @ F.T
        P[:POSE_DIM, :POSE_DIM] += G @ self.noise.velocity_cov() @ G.T

    def _landmark(self, lid: int) -> np.ndarray:
        s = 3 * self._slot[lid]
        return self._x[s : s + 3]

    def _update(self, known) -> None:
        n = self._P.shape[0]
        rows_H, rows_r = [], []
        # the pose is the same for every landmark of the step: its inverse (and adjoint) once
        T_inv = inverse(self._T)
        cam_T_inv = self.cam_T_imu @ T_inv
        adjoint_T_inv = adjoint(T_inv) if self.first_estimates and self.projected_jacobians else None
        for lid, z in known:
            m = self._landmark(lid)
            q = cam_T_inv @ _homogeneous(m)
            if not q[2] > 0.0:
                self.skipped_behind += 1
                continue
            # the pose's Jacobian at self._T, which is still the prior T_fe
            if not self.first_estimates:
                J_pose, J_m = _observation_jacobians(T_inv, m, self.cam_T_imu, self.M)
            elif self.projected_jacobians:
                J_pose, J_m = _constrained_jacobians(T_inv, adjoint_T_inv, m, self._m_fe[lid], self.cam_T_imu, self.M)
            else:
                J_pose, J_m = _observation_jacobians(T_inv, self._m_fe[lid], self.cam_T_imu, self.M)
            H = np.zeros((4, n))
            H[:, :POSE_DIM] = J_pose
            s = POSE_DIM + 3 * self._slot[lid]
            H[:, s : s + 3] = J_m
            r = z - self.M @ projection(q)
            idx = np.array((0, 1, 2, 3, 4, 5, s, s + 1, s + 2))  # the pose's and this landmark's
            H_idx = H[:, idx]
            S = H_idx @ self._P[idx[:, None], idx] @ H_idx.T + self._R
            nis = float(r @ np.linalg.solve(S, r))
            if self.gate is not None and nis > self.gate:
                self.rejected += 1
                continue
            self._nis.append(nis)
            rows_H.append(H)
            rows_r.append(r)
        if not rows_H:
            return
        H = np.vstack(rows_H)
        r = np.concatenate(rows_r)
        cols = np.flatnonzero(np.any(H != 0.0, axis=0))  # the pose and the landmarks seen
        Hc = H[:, cols]
        PHt = self._P[:, cols] @ Hc.T  # n × m: H is sparse, so this is O(n m)
        S = Hc @ PHt[cols] + np.kron(np.eye(len(rows_H)), self._R)
        K = np.linalg.solve(S, PHt.T).T
        dx = K @ r
        # Σ − K S Kᵀ (= the Joseph form for this optimal gain), O(n² m), kept symmetric
        self._P = self._P - K @ PHt.T
        self._P = 0.5 * (self._P + self._P.T)
        self._T = self._T @ exp_se3(dx[:POSE_DIM])
        self._x = self._x + dx[POSE_DIM:]
        self.updates += 1

    def _add(self, lid: int, z: np.ndarray) -> None:
        if not z[0] - z[2] >= self.min_disparity_px:
            self.skipped_small_disparity += 1
            return
        p_cam = point_from_stereo(z, self.K, self.baseline_m)
        p_imu = self.imu_T_cam[:3, :3] @ p_cam + self.imu_T_cam[:3, 3]
        R_wi = self._T[:3, :3]
        m = R_wi @ p_imu + self._T[:3, 3]
        if self.first_estimates:  # ∂m/∂δ at the pose's prior, so that A Ad(T_fe⁻¹) = m⊙
            p_fe = inverse(self._T_fe) @ np.append(m, 1.0)
            A = self._T_fe[:3, :3] @ np.hstack([np.eye(3), -skew(p_fe[:3])])
        else:
            A = R_wi @ np.hstack([np.eye(3), -skew(p_imu)])  # ∂m/∂δ
        B = R_wi @ self.imu_T_cam[:3, :3] @ point_from_stereo_jacobian(z, self.K, self.baseline_m)
        n = self._P.shape[0]
        cross = A @ self._P[:POSE_DIM, :]  # 3 × n
        P = np.zeros((n + 3, n + 3))
        P[:n, :n] = self._P
        P[n:, :n] = cross
        P[:n, n:] = cross.T
        P[n:, n:] = A @ self._P[:POSE_DIM, :POSE_DIM] @ A.T + B @ self._R @ B.T
        self._P = P
        self._x = np.concatenate([self._x, m])
        self._m_fe[lid] = m.copy()
        self._slot[lid] = len(self._slot)
        self.landmarks_added += 1


def pose_nees(estimate, covariance, truth) -> float:
    """NEES of one pose: ``e = log(T̂⁻¹ T_true)`` (right perturbation), ``eᵀ Σ⁻¹ e`` (χ²₆)."""
    e = log_se3(inverse(estimate) @ truth)
    return float(e @ np.linalg.solve(covariance, e))

