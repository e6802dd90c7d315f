"""Central finite differences, the independent reference every analytic Jacobian is tested
against, and the random poses those tests draw."""

from __future__ import annotations

import math

import numpy as np

from slamio.geometry import wrap_angle


def numeric_jacobian(f, x, angle_rows=(), h=1e-6):
    """Central differences of f at x; output rows in ``angle_rows`` are wrapped."""
    x = np.asarray(x, dtype=float)
    f0 = np.atleast_1d(np.asarray(f(x), dtype=float))
    J = np.zeros((f0.size, x.size))
    for j in range(x.size):
        d = np.zeros_like(x)
        d[j] = h
        diff = np.atleast_1d(np.asarray(f(x + d), dtype=float)) - np.atleast_1d(np.asarray(f(x - d), dtype=float))
        for r in angle_rows:
            diff[r] = wrap_angle(diff[r])
        J[:, j] = diff / (2.0 * h)
    return J


def assert_jacobians_match(f, x, y, J_x, J_y, angle_rows=()):
    """``J_x`` and ``J_y`` are the derivatives of ``f(x, y)`` by ``x`` and by ``y`` (central
    differences, to 1e-7); ``J_x=None`` checks only ``J_y``."""
    if J_x is not None:
        np.testing.assert_allclose(J_x, numeric_jacobian(lambda v: f(v, y), x, angle_rows=angle_rows), atol=1e-7)
    np.testing.assert_allclose(J_y, numeric_jacobian(lambda v: f(x, v), y, angle_rows=angle_rows), atol=1e-7)


def random_poses(rng, count):
    """Random poses, a quarter of them with headings within 1e-3 rad of ±π."""
    poses = rng.uniform([-10, -10, -math.pi], [10, 10, math.pi], size=(count, 3))
    near = rng.uniform(-1e-3, 1e-3, size=count // 4)
    poses[: count // 4, 2] = wrap_angle(math.pi + near)
    return poses
