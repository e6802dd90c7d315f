"""Motion and observation models of 2-D landmark SLAM, with analytic Jacobians.

Everything here is a small pure function of numbers; nothing holds state. Poses are
``(x_m, y_m, theta_rad)`` in the world frame (theta counter-clockwise from the world x
axis), landmarks are points ``(x_m, y_m)`` in the world frame, and the robot frame is
x forward, y left (see ``slamio.geometry``).

Motion model
    The odometry of a run log is an SE(2) increment ``(dx_m, dy_m, dtheta_rad)`` expressed
    in the frame of the previous pose, so the new pose is the composition

        x' = x + cos θ · dx − sin θ · dy
        y' = y + sin θ · dx + cos θ · dy
        θ' = wrap(θ + dθ)

    This is exactly GTSAM's ``BetweenFactorPose2`` model, so the EKF and the factor graph
    use the same motion model and differ only in how they estimate.

Observation model
    A landmark at ``(lx, ly)`` seen from pose ``(x, y, θ)`` gives

        range   = sqrt((lx − x)² + (ly − y)²)
        bearing = wrap(atan2(ly − y, lx − x) − θ)      (counter-clockwise from forward)

Inverse observation model (landmark initialisation)
    The point a range/bearing measurement puts the landmark at:

        lx = x + range · cos(θ + bearing),   ly = y + range · sin(θ + bearing)

Every Jacobian below is derived by hand and checked against central finite differences in
``tests/test_ekf.py``.
"""

from __future__ import annotations

import math

import numpy as np

from slamio.geometry import wrap_angle

__all__ = [
    "ROBOT_DIM",
    "LANDMARK_DIM",
    "predict_pose",
    "motion_jacobians",
    "range_bearing",
    "range_bearing_jacobians",
    "landmark_from_range_bearing",
    "landmark_init_jacobians",
    "range_bearing_nis",
    "range_nis",
]

ROBOT_DIM = 3  # x_m, y_m, theta_rad
LANDMARK_DIM = 2  # x_m, y_m


# --------------------------------------------------------------------------- motion


def predict_pose(pose, increment) -> np.ndarray:
    """The pose after applying an odometry increment: ``pose ⊕ increment``.

    ``pose`` is ``(x_m, y_m, theta_rad)`` in the world frame; ``increment`` is
    ``(dx_m, dy_m, dtheta_rad)`` in the frame of ``pose``. Returns a length-3 array with
    the heading wrapped into [−π, π).
    """
    x, y, th = (float(v) for v in pose)
    dx, dy, dth = (float(v) for v in increment)
    c, s = math.cos(th), math.sin(th)
    return np.array([x + c * dx - s * dy, y + s * dx + c * dy, wrap_angle(th + dth)])


def motion_jacobians(pose, increment) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of :func:`predict_pose`: ``(F_pose, F_increment)``, both 3×3.

    ``F_pose = ∂(pose ⊕ u)/∂pose`` propagates the state covariance and
    ``F_increment = ∂(pose ⊕ u)/∂u`` maps the increment's covariance Σ (given in the robot
    frame) into the world frame: the process noise is ``Q = F_increment Σ F_incrementᵀ``.
    """
    th = float(pose[2])
    dx, dy = float(increment[0]), float(increment[1])
    c, s = math.cos(th), math.sin(th)
    F_pose = np.array(
        [
            [1.0, 0.0, -s * dx - c * dy],
            [0.0, 1.0, c * dx - s * dy],
            [0.0, 0.0, 1.0],
        ]
    )
    F_increment = np.array(
        [
            [c, -s, 0.0],
            [s, c, 0.0],
            [0.0, 0.0, 1.0],
        ]
    )
    return F_pose, F_increment


# --------------------------------------------------------------------------- observation


def range_bearing(pose, landmark_xy) -> tuple[float, float]:
    """The ``(range_m, bearing_rad)`` at which ``pose`` sees the landmark at ``landmark_xy``.

    The bearing is counter-clockwise from the robot's forward axis, wrapped into [−π, π).
    """
    x, y, th = (float(v) for v in pose)
    ex, ey = float(landmark_xy[0]) - x, float(landmark_xy[1]) - y
    return math.hypot(ex, ey), wrap_angle(math.atan2(ey, ex) - th)


def range_bearing_jacobians(pose, landmark_xy) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of :func:`range_bearing`: ``(H_pose 2×3, H_landmark 2×2)``.

    With ``e = landmark − position``, ``q = |e|²`` and ``r = √q``::

        H_pose     = [[−ex/r, −ey/r,  0],      H_landmark = [[ ex/r, ey/r],
                      [ ey/q, −ex/q, −1]]                    [−ey/q, ex/q]]

    Undefined when the landmark sits exactly on the robot (r = 0).
    """
    x, y = float(pose[0]), float(pose[1])
    ex, ey = float(landmark_xy[0]) - x, float(landmark_xy[1]) - y
    q = ex * ex + ey * ey
    r = math.sqrt(q)
    H_landmark = np.array([[ex / r, ey / r], [-ey / q, ex / q]])
    H_pose = np.array(
        [
            [-ex / r, -ey / r, 0.0],
            [ey / q, -ex / q, -1.0],
        ]
    )
    return H_pose, H_landmark


# --------------------------------------------------------------------------- inverse observation


def landmark_from_range_bearing(pose, range_m: float, bearing_rad: float) -> tuple[float, float]:
    """The world point ``(x_m, y_m)`` that ``pose`` sees at ``(range_m, bearing_rad)``."""
    x, y, th = (float(v) for v in pose)
    a = th + float(bearing_rad)
    return x + range_m * math.cos(a), y + range_m * math.sin(a)


def landmark_init_jacobians(pose, range_m: float, bearing_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of :func:`landmark_from_range_bearing`: ``(G_pose 2×3, G_measurement 2×2)``.

    With ``a = θ + bearing``::

        G_pose        = [[1, 0, −r sin a],     G_measurement = [[cos a, −r sin a],
                         [0, 1,  r cos a]]                      [sin a,  r cos a]]

    A new landmark's covariance is ``G_pose P_rr G_poseᵀ + G_measurement R G_measurementᵀ``
    and its cross-covariance with any other state block b is ``G_pose P_rb``.
    """
    a = float(pose[2]) + float(bearing_rad)
    c, s = math.cos(a), math.sin(a)
    G_pose = np.array([[1.0, 0.0, -range_m * s], [0.0, 1.0, range_m * c]])
    G_measurement = np.array([[c, -range_m * s], [s, range_m * c]])
    return G_pose, G_measurement


# --------------------------------------------------------------------------- consistency


def range_bearing_nis(pose, landmark_xy, joint_covariance, range_m: float, bearing_rad: float, R) -> float:
    """Normalised innovation squared of one range-bearing observation: ``νᵀ S⁻¹ ν``.

    ``ν = z − h(pose, landmark)`` (bearing wrapped) and ``S = H Σ Hᵀ + R``, where
    ``H = [H_pose | H_landmark]`` (2×5) and ``joint_covariance`` Σ is the 5×5 covariance of
    ``(x, y, θ, lx, ly)`` *before* the observation is used — the prior of the step that
    makes it, cross-covariance included. ``R`` is the 2×2 measurement covariance. For a
    consistent estimator the value is χ²-distributed with 2 degrees of freedom (mean 2).
    Returns NaN when S is not positive definite.
    """
    predicted_range, predicted_bearing = range_bearing(pose, landmark_xy)
    nu = np.array([range_m - predicted_range, wrap_angle(bearing_rad - predicted_bearing)])
    H_pose, H_landmark = range_bearing_jacobians(pose, landmark_xy)
    H = np.hstack([H_pose, H_landmark])
    S = H @ np.asarray(joint_covariance, dtype=float) @ H.T + np.asarray(R, dtype=float)
    return normalised_innovation_squared(nu, S)


def range_nis(pose, landmark_xy, joint_covariance, range_m: float, sigma_range_m: float) -> float:
    """Normalised innovation squared of one range-only reading (a ranging radio): the range
    row of :func:`range_bearing_nis`, ``ν = r − |l − p|``, ``S = h Σ hᵀ + σ²`` with
    ``h = [H_pose | H_landmark]``'s first row. χ²-distributed with 1 degree of freedom
    (mean 1) for a consistent estimator; NaN when S is not positive."""
    predicted_range, _ = range_bearing(pose, landmark_xy)
    H_pose, H_landmark = range_bearing_jacobians(pose, landmark_xy)
    h = np.hstack([H_pose[0], H_landmark[0]])
    S = float(h @ np.asarray(joint_covariance, dtype=float) @ h) + float(sigma_range_m) ** 2
    return float((range_m - predicted_range) ** 2 / S) if S > 0.0 else float("nan")


def normalised_innovation_squared(nu, S) -> float:
    """``νᵀ S⁻¹ ν`` through S's Cholesky factor; NaN when S is not positive definite.

    A 2×2 S (a range-bearing reading, the common case) is factored in closed form, the
    same operations as LAPACK's Cholesky and triangular solve (numpy's calls cost more than
    the sums)."""
    if len(nu) == 2:
        (s00, s01), (s10, s11) = np.asarray(S, dtype=float).tolist()
        if not s00 > 0.0:  # also NaN
            return float("nan")
        l00 = math.sqrt(s00)
        l10 = 0.5 * (s10 + s01) / l00
        d = s11 - l10 * l10
        if not d > 0.0:
            return float("nan")
        w0 = float(nu[0]) / l00
        w1 = (float(nu[1]) - l10 * w0) / math.sqrt(d)
        return w0 * w0 + w1 * w1
    try:
        L = np.linalg.cholesky(0.5 * (S + S.T))
    except np.linalg.LinAlgError:
        return float("nan")
    w = np.linalg.solve(L, nu)
    return float(w @ w)
