"""SE(3) in 4×4 matrices: hat, exp/log, adjoint and the 6×6 "curly hat" (numpy only).

Twists are 6-vectors ``ξ = (ρ, φ)`` — translation part first, rotation part second — the
order seed 003 (and Barfoot's *State Estimation for Robotics*) uses for the IMU input
``u = (v, ω)``. (GTSAM's Pose3 tangent is ``(φ, ρ)``, rotation first: convert at that edge.)

* ``hat(ξ)``        4×4 ``[[φ^, ρ], [0, 0]]`` (the paper's ``û``);
* ``curly_hat(ξ)``  6×6 ``[[φ^, ρ^], [0, φ^]]`` (the paper's ``Û``, eq. 18), with
  ``expm(curly_hat(ξ)) = adjoint(exp_se3(ξ))``;
* ``exp_se3`` / ``log_se3`` closed forms (Rodrigues), ``adjoint(T)`` = ``[[R, p^R], [0, R]]``;
* ``odot(p)``       4×6 ``[[I, −p^], [0, 0]]`` for a homogeneous point, so that
  ``hat(ξ) p = odot(p) ξ``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "adjoint",
    "curly_hat",
    "exp_se3",
    "exp_so3",
    "hat",
    "inverse",
    "left_jacobian_so3",
    "log_se3",
    "log_so3",
    "odot",
    "quaternion_from_rotation",
    "rotation_from_quaternion",
    "skew",
    "yaw_from_quaternion",
]

_SMALL_ANGLE = 1e-8


def skew(w) -> np.ndarray:
    """3×3 skew-symmetric matrix ``w^`` with ``w^ a = w × a``."""
    x, y, z = (float(c) for c in w)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def hat(xi) -> np.ndarray:
    """4×4 se(3) matrix of the twist ``ξ = (ρ, φ)``: ``[[φ^, ρ], [0, 0]]``."""
    xi = np.asarray(xi, dtype=float)
    out = np.zeros((4, 4))
    out[:3, :3] = skew(xi[3:])
    out[:3, 3] = xi[:3]
    return out


def curly_hat(xi) -> np.ndarray:
    """6×6 ``ξ⋏ = [[φ^, ρ^], [0, φ^]]``: the adjoint of se(3) (seed 003's Û, eq. 18)."""
    xi = np.asarray(xi, dtype=float)
    out = np.zeros((6, 6))
    w = skew(xi[3:])
    out[:3, :3] = w
    out[3:, 3:] = w
    out[:3, 3:] = skew(xi[:3])
    return out


def exp_so3(phi) -> np.ndarray:
    """Rotation matrix ``exp(φ^)`` (Rodrigues)."""
    phi = np.asarray(phi, dtype=float)
    angle = float(np.linalg.norm(phi))
    W = skew(phi)
    if angle < _SMALL_ANGLE:
        return np.eye(3) + W + 0.5 * W @ W
    return np.eye(3) + math.sin(angle) / angle * W + (1.0 - math.cos(angle)) / angle**2 * W @ W


def left_jacobian_so3(phi) -> np.ndarray:
    """SO(3) left Jacobian ``J(φ)``: the translation of ``exp(ξ)`` is ``J(φ) ρ``."""
    phi = np.asarray(phi, dtype=float)
    angle = float(np.linalg.norm(phi))
    W = skew(phi)
    if angle < _SMALL_ANGLE:
        return np.eye(3) + 0.5 * W + W @ W / 6.0
    a2 = angle * angle
    return np.eye(3) + (1.0 - math.cos(angle)) / a2 * W + (angle - math.sin(angle)) / (a2 * angle) * W @ W


def exp_se3(xi) -> np.ndarray:
    """4×4 pose ``exp(ξ^)`` for the twist ``ξ = (ρ, φ)``."""
    xi = np.asarray(xi, dtype=float)
    T = np.eye(4)
    T[:3, :3] = exp_so3(xi[3:])
    T[:3, 3] = left_jacobian_so3(xi[3:]) @ xi[:3]
    return T


def log_so3(R) -> np.ndarray:
    """Rotation vector φ with ``exp(φ^) = R``, |φ| ≤ π."""
    R = np.asarray(R, dtype=float)
    cos_angle = min(1.0, max(-1.0, 0.5 * (np.trace(R) - 1.0)))
    angle = math.acos(cos_angle)
    vee = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < _SMALL_ANGLE:
        return 0.5 * vee
    if math.pi - angle < 1e-6:  # near π: axis from the symmetric part
        B = 0.5 * (R + np.eye(3))
        axis = np.sqrt(np.maximum(np.diag(B), 0.0))
        k = int(np.argmax(axis))
        axis = B[:, k] / axis[k]
        axis /= np.linalg.norm(axis)
        if np.dot(axis, vee) < 0.0:
            axis = -axis
        return angle * axis
    return angle / (2.0 * math.sin(angle)) * vee


def log_se3(T) -> np.ndarray:
    """Twist ``ξ = (ρ, φ)`` with ``exp_se3(ξ) = T``."""
    T = np.asarray(T, dtype=float)
    phi = log_so3(T[:3, :3])
    rho = np.linalg.solve(left_jacobian_so3(phi), T[:3, 3])
    return np.concatenate([rho, phi])


def adjoint(T) -> np.ndarray:
    """6×6 adjoint of a pose: ``[[R, p^ R], [0, R]]``, so ``T exp(ξ^) T⁻¹ = exp((Ad_T ξ)^)``."""
    T = np.asarray(T, dtype=float)
    R, p = T[:3, :3], T[:3, 3]
    out = np.zeros((6, 6))
    out[:3, :3] = R
    out[3:, 3:] = R
    out[:3, 3:] = skew(p) @ R
    return out


def inverse(T) -> np.ndarray:
    """Inverse of a 4×4 rigid transform without a general matrix inverse."""
    T = np.asarray(T, dtype=float)
    out = np.eye(4)
    R = T[:3, :3]
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def odot(p) -> np.ndarray:
    """4×6 ``p⊙ = [[s I, −ε^], [0, 0]]`` of a homogeneous point ``p = (ε, s)``: ``hat(ξ) p = p⊙ ξ``."""
    p = np.asarray(p, dtype=float)
    out = np.zeros((4, 6))
    out[:3, :3] = p[3] * np.eye(3)
    out[:3, 3:] = -skew(p[:3])
    return out


# --------------------------------------------------------------------------- quaternions (x, y, z, w)


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Heading (rotation about the vertical) of a quaternion, counter-clockwise."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def rotation_from_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray | None:
    """3×3 rotation matrix of a quaternion (normalised first); None for a zero quaternion."""
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 1e-12:
        return None
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_from_rotation(R: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a 3×3 rotation matrix (Shepperd's method: stable for every rotation)."""
    m = np.asarray(R, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        return ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 0.0))
    q = [0.0, 0.0, 0.0]
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    w = (m[k, j] - m[j, k]) / s
    return q[0], q[1], q[2], w
