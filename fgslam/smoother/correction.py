"""The online pose between iSAM2 updates: a 3-state EKF against the mapped landmarks.

iSAM2 updates only every few steps (:class:`~fgslam.smoother.isam2.Isam2Smoother`'s
``update_observations`` / ``update_every``). Between updates the newest pose would otherwise be the last iSAM2
estimate ⊕ the odometry since (dead reckoning). :class:`PoseCorrector` does better for a
few microseconds a step: it propagates that pose with the odometry and corrects it with
each observation of a landmark iSAM2 already holds (range and bearing, or a range alone
for a range-only landmark), treating the landmark's last iSAM2 estimate as known (a pose-only EKF; the landmark's own uncertainty and its correlation
with the pose are ignored). At every iSAM2 update its mean is replaced by iSAM2's estimate
of the newest pose; its covariance carries on, so it stays the filter's own bookkeeping of
how far odometry and observations are trusted. It is the online estimate only: the factor
graph, and so the final estimate, never sees it (except that new poses are seeded from
it, a better linearisation point than dead reckoning). Each observation's NIS is also
kept as a χ² tail probability (:attr:`PoseCorrector.last_tail`): the smoother asks iSAM2
for an update when one is unlikely, and does not use one that is very unlikely
(:data:`SURPRISE_TAIL`).

Frames: the state is ``(x_m, y_m, theta_rad)`` in the world frame, its covariance in
world (x, y, θ) coordinates — the EKF's (:mod:`ekf.models`), whose motion and observation
models and Jacobians this reuses. An odometry record's covariance is over the increment's
numbers in the robot frame, as in the log.
"""

from __future__ import annotations

import math


#: An observation whose NIS against the pose-only prediction has a χ² tail probability below
#: this is not used by the correction; the smoother then gives the held steps to iSAM2 at once
#: (a surprise is what the full smoother is for). A range-bearing NIS is χ² with 2 degrees of
#: freedom, a range-only NIS with 1 (whose 0.999 point is 10.83).
SURPRISE_TAIL = 0.001
#: The same threshold on a range-bearing NIS: χ²₂ at 0.999 (13.82), P(χ²₂ > x) = e^(−x/2).
SURPRISE_NIS = -2.0 * math.log(SURPRISE_TAIL)


def chi2_tail(nis: float, dof: int) -> float:
    """P(χ²_dof > nis) for 1 or 2 degrees of freedom (closed forms: erfc(√(x/2)), e^(−x/2))."""
    if not nis >= 0.0:  # NaN
        return 0.0
    return math.exp(-0.5 * nis) if dof == 2 else math.erfc(math.sqrt(0.5 * nis))

# The maths below is written out in scalars: on 3×3 matrices numpy's per-call overhead is
# ten times the arithmetic, and this runs for every observation of every step.
# Covariances are 3×3 nested lists (symmetric), poses (x_m, y_m, theta_rad) tuples.
# Angles are wrapped as ekf.models.wrap_angle wraps a float — (a + π) mod 2π − π, the same
# operations, so the same bits — written out, without its call and its test for an array.
_PI = math.pi
_TWO_PI = 2.0 * math.pi


def predict(mean, P, increment, Q_increment) -> tuple[tuple[float, float, float], list[list[float]]]:
    """EKF prediction of a pose by one odometry increment: ``(mean ⊕ u, F P Fᵀ + G Q Gᵀ)``.

    ``increment`` is ``(dx_m, dy_m, dtheta_rad)`` in the robot frame and ``Q_increment`` its
    3×3 covariance over those numbers; ``F = ∂(mean ⊕ u)/∂mean`` and ``G = ∂(mean ⊕ u)/∂u``
    are :func:`ekf.models.motion_jacobians`'s.
    """
    x, y, th = mean
    dx, dy, dth = increment
    c, s = math.cos(th), math.sin(th)
    a, b = -s * dx - c * dy, c * dx - s * dy  # F = [[1, 0, a], [0, 1, b], [0, 0, 1]]
    (p00, p01, p02), (_, p11, p12), (_, _, p22) = P
    # F P Fᵀ
    f00 = p00 + 2.0 * a * p02 + a * a * p22
    f01 = p01 + a * p12 + b * p02 + a * b * p22
    f02 = p02 + a * p22
    f11 = p11 + 2.0 * b * p12 + b * b * p22
    f12 = p12 + b * p22
    # G Q Gᵀ with G = blockdiag(R(θ), 1)
    (q00, q01, q02), (_, q11, q12), (_, _, q22) = Q_increment
    g00 = c * c * q00 - 2.0 * c * s * q01 + s * s * q11
    g11 = s * s * q00 + 2.0 * c * s * q01 + c * c * q11
    g01 = c * s * (q00 - q11) + (c * c - s * s) * q01
    g02 = c * q02 - s * q12
    g12 = s * q02 + c * q12
    m00, m01, m02, m11, m12, m22 = f00 + g00, f01 + g01, f02 + g02, f11 + g11, f12 + g12, p22 + q22
    moved = (x + c * dx - s * dy, y + s * dx + c * dy, (th + dth + _PI) % _TWO_PI - _PI)
    return moved, [[m00, m01, m02], [m01, m11, m12], [m02, m12, m22]]


def correct(mean, P, landmark_xy, range_m: float, bearing_rad: float, R) -> tuple[tuple, list[list[float]], float]:
    """EKF update of a pose by one range-bearing observation of a landmark at a known point.

    Innovation ν = z − h(mean, landmark) (bearing wrapped; h and its Jacobian H are
    :func:`ekf.models.range_bearing` / ``range_bearing_jacobians``), S = H P Hᵀ + R,
    K = P Hᵀ S⁻¹; returns ``(mean + K ν, P − K S Kᵀ, νᵀ S⁻¹ ν)``, the NIS of the
    prediction. ``R`` is the 2×2 covariance of (range_m, bearing_rad).
    """
    x, y, th = mean
    ex, ey = landmark_xy[0] - x, landmark_xy[1] - y
    q = ex * ex + ey * ey
    r = math.sqrt(q)
    nu_r = range_m - r
    nu_b = (bearing_rad - ((math.atan2(ey, ex) - th + _PI) % _TWO_PI - _PI) + _PI) % _TWO_PI - _PI
    # H = [[h0, h1, 0], [h2, h3, -1]]
    h0, h1, h2, h3 = -ex / r, -ey / r, ey / q, -ex / q
    (p00, p01, p02), (_, p11, p12), (_, _, p22) = P
    # U = P Hᵀ (3×2)
    u00 = p00 * h0 + p01 * h1
    u10 = p01 * h0 + p11 * h1
    u20 = p02 * h0 + p12 * h1
    u01 = p00 * h2 + p01 * h3 - p02
    u11 = p01 * h2 + p11 * h3 - p12
    u21 = p02 * h2 + p12 * h3 - p22
    # S = H U + R
    s00 = h0 * u00 + h1 * u10 + R[0][0]
    s01 = h0 * u01 + h1 * u11 + R[0][1]
    s11 = h2 * u01 + h3 * u11 - u21 + R[1][1]
    det = s00 * s11 - s01 * s01
    if not det > 0.0:
        return mean, P, math.inf
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det  # S⁻¹
    nis = nu_r * (i00 * nu_r + i01 * nu_b) + nu_b * (i01 * nu_r + i11 * nu_b)
    # K = U S⁻¹ (3×2)
    k00, k01 = u00 * i00 + u01 * i01, u00 * i01 + u01 * i11
    k10, k11 = u10 * i00 + u11 * i01, u10 * i01 + u11 * i11
    k20, k21 = u20 * i00 + u21 * i01, u20 * i01 + u21 * i11
    heading = th + k20 * nu_r + k21 * nu_b
    updated = (x + k00 * nu_r + k01 * nu_b, y + k10 * nu_r + k11 * nu_b, (heading + _PI) % _TWO_PI - _PI)
    # P − K S Kᵀ = P − K Uᵀ
    c00 = p00 - (k00 * u00 + k01 * u01)
    c01 = p01 - (k00 * u10 + k01 * u11)
    c02 = p02 - (k00 * u20 + k01 * u21)
    c11 = p11 - (k10 * u10 + k11 * u11)
    c12 = p12 - (k10 * u20 + k11 * u21)
    c22 = p22 - (k20 * u20 + k21 * u21)
    return updated, [[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]], nis


def correct_range(mean, P, landmark_xy, range_m: float, var_range_m2: float) -> tuple[tuple, list[list[float]], float]:
    """EKF update of a pose by one range-only observation of a landmark at a known point.

    The range row of :func:`correct`: ν = z − ‖landmark − position‖, H = [−eₓ/r, −e_y/r, 0],
    S = H P Hᵀ + σ², K = P Hᵀ / S; returns ``(mean + K ν, P − K S Kᵀ, ν² / S)``.
    """
    x, y, th = mean
    ex, ey = landmark_xy[0] - x, landmark_xy[1] - y
    r = math.sqrt(ex * ex + ey * ey)
    if not r > 0.0:
        return mean, P, math.inf
    h0, h1 = -ex / r, -ey / r
    nu = range_m - r
    (p00, p01, p02), (_, p11, p12), (_, _, p22) = P
    u0, u1, u2 = p00 * h0 + p01 * h1, p01 * h0 + p11 * h1, p02 * h0 + p12 * h1  # P Hᵀ
    S = h0 * u0 + h1 * u1 + var_range_m2
    if not S > 0.0:
        return mean, P, math.inf
    k0, k1, k2 = u0 / S, u1 / S, u2 / S
    updated = (x + k0 * nu, y + k1 * nu, (th + k2 * nu + _PI) % _TWO_PI - _PI)
    P_new = [[p00 - k0 * u0, p01 - k0 * u1, p02 - k0 * u2],
             [p01 - k0 * u1, p11 - k1 * u1, p12 - k1 * u2],
             [p02 - k0 * u2, p12 - k1 * u2, p22 - k2 * u2]]
    return updated, P_new, nu * nu / S


class PoseCorrector:
    """The pose-only EKF that gives the online pose between iSAM2 updates (module docstring)."""

    def __init__(self, start_pose, start_covariance_world):
        self.mean = tuple(float(v) for v in start_pose)
        self.P = [[float(v) for v in row] for row in start_covariance_world]
        self.corrections = 0  # observations used
        self.surprises = 0  # observations gated out (χ² tail < SURPRISE_TAIL)
        self.last_tail = 1.0  # χ² tail probability of the last observation's NIS

    def reset(self, pose) -> None:
        """iSAM2 has updated: its estimate of the newest pose replaces the mean."""
        self.mean = (float(pose[0]), float(pose[1]), float(pose[2]))

    def predict(self, increment, Q_increment) -> None:
        self.mean, self.P = predict(self.mean, self.P, increment, Q_increment)

    def correct(self, landmark_xy, range_m: float, bearing_rad: float | None, R) -> bool:
        """Use one observation unless it is a surprise; return whether it was used.

        ``R``: the 2×2 covariance of (range_m, bearing_rad), or with ``bearing_rad=None``
        (a range-only observation) the range's variance."""
        if bearing_rad is None:  # a range-only observation: R is the range's variance
            mean, P, nis = correct_range(self.mean, self.P, landmark_xy, range_m, R)
            self.last_tail = chi2_tail(nis, 1)
        else:
            mean, P, nis = correct(self.mean, self.P, landmark_xy, range_m, bearing_rad, R)
            self.last_tail = chi2_tail(nis, 2)
        if not self.last_tail >= SURPRISE_TAIL:
            self.surprises += 1
            return False
        self.mean, self.P = mean, P
        self.corrections += 1
        return True
