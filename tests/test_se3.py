"""slamio.se3 and slamio.stereo against scipy's matrix exponential and numerical derivatives."""

import numpy as np
import pytest
from scipy.linalg import expm

from jacobians import numeric_jacobian

from slamio.se3 import adjoint, curly_hat, exp_se3, hat, inverse, log_se3, odot, skew
from slamio.stereo import (
    point_from_stereo,
    point_from_stereo_jacobian,
    projection,
    projection_jacobian,
    stereo_matrix,
    stereo_pixels,
)

RNG = np.random.default_rng(3)
TWISTS = [RNG.normal(size=6) for _ in range(5)] + [np.array([1.0, 2.0, 3.0, 1e-10, 0.0, 0.0]), np.array([0.1, 0, 0, 0, 0, np.pi - 1e-9])]
K = np.array([[707.09, 0.0, 601.89], [0.0, 707.09, 183.11], [0.0, 0.0, 1.0]])




@pytest.mark.parametrize("xi", TWISTS)
def test_exp_matches_scipy_expm(xi):
    assert np.allclose(exp_se3(xi), expm(hat(xi)), atol=1e-10)


@pytest.mark.parametrize("xi", TWISTS)
def test_log_inverts_exp(xi):
    assert np.allclose(exp_se3(log_se3(exp_se3(xi))), exp_se3(xi), atol=1e-8)


@pytest.mark.parametrize("xi", TWISTS[:5])
def test_curly_hat_exponential_is_the_adjoint(xi):
    assert np.allclose(expm(curly_hat(xi)), adjoint(exp_se3(xi)), atol=1e-9)


@pytest.mark.parametrize("xi", TWISTS[:5])
def test_adjoint_moves_a_twist_through_a_pose(xi):
    T = exp_se3(RNG.normal(size=6))
    assert np.allclose(T @ hat(xi) @ inverse(T), hat(adjoint(T) @ xi), atol=1e-10)
    assert np.allclose(inverse(T), np.linalg.inv(T), atol=1e-12)


def test_curly_hat_is_the_lie_bracket():
    a, b = RNG.normal(size=6), RNG.normal(size=6)
    bracket = hat(a) @ hat(b) - hat(b) @ hat(a)
    assert np.allclose(hat(curly_hat(a) @ b), bracket, atol=1e-12)


def test_odot_and_skew():
    p = np.append(RNG.normal(size=3), 1.0)
    xi = RNG.normal(size=6)
    assert np.allclose(hat(xi) @ p, odot(p) @ xi)
    a, b = RNG.normal(size=3), RNG.normal(size=3)
    assert np.allclose(skew(a) @ b, np.cross(a, b))


def test_stereo_matrix_is_equation_1_and_projects_a_known_point():
    M = stereo_matrix(K, 0.5)
    # a point 10 m ahead on the optical axis: both u at c_u except for the disparity f b / z
    z = stereo_pixels(M, [0.0, 0.0, 10.0])
    assert np.allclose(z, [601.89, 183.11, 601.89 - 707.09 * 0.5 / 10.0, 183.11])
    q = np.array([1.0, -2.0, 8.0, 1.0])
    assert np.allclose(projection_jacobian(q), numeric_jacobian(projection, q), atol=1e-9)


@pytest.mark.parametrize("point", [[1.0, -2.0, 8.0], [-4.0, 1.0, 30.0], [0.2, 0.3, 3.0]])
def test_back_projection_inverts_projection_with_its_jacobian(point):
    M = stereo_matrix(K, 0.537)
    z = stereo_pixels(M, point)
    assert np.allclose(point_from_stereo(z, K, 0.537), point, atol=1e-9)
    J = point_from_stereo_jacobian(z, K, 0.537)
    assert np.allclose(J, numeric_jacobian(lambda zz: point_from_stereo(zz, K, 0.537), z, h=1e-4), atol=1e-6)
