"""Right-invariant EKF-SLAM (``ekf-inv``): the textbook filter with its error taken on the
group, so that no linearisation point makes the global heading observable.

Why
---
Nothing a robot senses fixes the world frame: a rotation of the whole solution about any
point leaves every reading the same. The textbook EKF (:class:`ekf.slam.EkfSlam`) keeps the
covariance of the *additive* error ``δ = x − x̂`` and, after an update moves the estimate,
goes on as if that covariance were still about the old estimate; the next prediction's
Jacobian, taken at the new one, then "sees" a rotation direction the readings never gave
(Huang, Mourikis and Roumeliotis 2008). Its heading variance shrinks below the truth and a
heading error made while the map is young is locked in: on MRCLAM Dataset 6 with the noise
learned from each log (``--noise self``) its map ends turned by 12–15° on three robots while
it states a heading σ of about 1° (docs/results-datasets.md, 2026-12-07, "the EKF's lock-in").
``ekf-fej`` removes the spurious information by freezing the Jacobians at first estimates,
but a landmark first placed while the heading is 30° off keeps a Jacobian metres off, and
on one of those robots the filter diverges.

The invariant error (Barrau and Bonnabel, *An EKF-SLAM algorithm with consistency
properties*, 2015; Zhang, Wu, Song and Huang, RA-L 2017)
---------------------------------------------------------
The state ``(θ, p, l₁ … l_K)`` is an element of SE_{K+1}(2), and its right-invariant error
linearises to ``ξ = T(x̂) δ``::

    ξ_θ = δθ,   ξ_p = δp − J p̂ δθ,   ξ_lᵢ = δlᵢ − J l̂ᵢ δθ,   J = [[0, −1], [1, 0]]

(heights and the readings' Gauss–Markov errors, which do not turn with the frame, are
unchanged). In ξ the motion model's Jacobian is the identity and every reading's Jacobian
has a zero heading column (a range-bearing reading sees ``R(θ̂)ᵀ(ξ_l − ξ_p)``): the
unobservable directions — a shift of every position, a turn ``ξ_θ`` — do not depend on the
estimate, so no linearisation point can observe them, with every Jacobian taken at the
latest estimate (no first estimates to go stale).

This filter keeps the textbook filter's state and covariance in additive coordinates (its
prediction, landmark initialisation, gates, NIS and association are then exactly the
invariant filter's: ``T(x̂⁺)⁻¹ T(x̂) = Φ``, the textbook propagation Jacobian, and the
textbook ``H`` and ``G`` are ``H_ξ T`` and ``T⁻¹ G_ξ``). Only an update differs:

* the correction ``ξ̂ = T(x̂) K ν`` moves the estimate on the group,
  ``x̂⁺ = exp(ξ̂) x̂``: every position ``q`` (robot and landmarks) goes to
  ``R(ξ̂_θ) q + V(ξ̂_θ) ξ̂_q`` and the heading to ``θ̂ + ξ̂_θ``;
* the Joseph-form covariance, which is about ``x̂``, is carried to ``x̂⁺``:
  ``P ← M P Mᵀ`` with ``M = T(x̂⁺)⁻¹ T(x̂) = I + u e_θᵀ``, ``u`` holding
  ``J (q⁺ − q)`` in each position's rows. This is the step the textbook filter leaves out.

Cost: one more rank-2 O(n²) pass per update (:func:`transport_factors`).
"""

from __future__ import annotations

import math

import numpy as np

from ekf.covariance import add_low_rank_in_place, joseph_factors
from ekf.slam import EkfSlam
from slamio.geometry import wrap_angle
from slamio.log import Header

__all__ = ["InvariantEkfSlam", "group_correction", "se2_left_jacobian", "transport_factors"]

_J = np.array([[0.0, -1.0], [1.0, 0.0]])


def se2_left_jacobian(turn_rad: float) -> np.ndarray:
    """``V(φ) = [[sin φ/φ, −(1 − cos φ)/φ], [(1 − cos φ)/φ, sin φ/φ]]``, the translation part of
    SE(2)'s exponential (the identity at φ = 0; a series below 1e-6 rad)."""
    phi = float(turn_rad)
    if abs(phi) < 1e-6:
        a, b = 1.0 - phi * phi / 6.0, phi / 2.0
    else:
        a, b = math.sin(phi) / phi, (1.0 - math.cos(phi)) / phi
    return np.array([[a, -b], [b, a]])


def group_correction(positions_m: np.ndarray, shift_m: np.ndarray, turn_rad: float) -> np.ndarray:
    """Positions (m×2) moved by the additive correction ``(shift_m (m×2), turn_rad)`` taken as the
    invariant error: ``ξ_q = δq − J q δθ``, then ``q⁺ = R(δθ) q + V(δθ) ξ_q``. To first order this
    is ``q + δq``; it differs when the turn is large, where the textbook filter's straight
    shift would not keep the positions' distances."""
    q = np.asarray(positions_m, dtype=float)
    xi = np.asarray(shift_m, dtype=float) - turn_rad * (q @ _J.T)
    c, s = math.cos(turn_rad), math.sin(turn_rad)
    rotation = np.array([[c, -s], [s, c]])
    return q @ rotation.T + xi @ se2_left_jacobian(turn_rad).T


def transport_factors(P: np.ndarray, heading_index: int, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Factors ``(X, Y)``, n×2, with ``M P Mᵀ = P + X Yᵀ`` for ``M = I + u e_hᵀ`` (h the heading's
    index, ``u[h] = 0``): ``X = [u, c]``, ``Y = [c + P_hh u, u]`` with ``c = P e_h``."""
    c = np.array(P[:, heading_index], dtype=float)
    p_hh = float(P[heading_index, heading_index])
    return np.column_stack([u, c]), np.column_stack([c + p_hh * u, u])


class InvariantEkfSlam(EkfSlam):
    """:class:`~ekf.slam.EkfSlam` with the right-invariant error (see the module docstring).

    Takes the same keyword arguments; ``name`` is "ekf-inv" ("ekf-inv-nn" with
    ``association="nn"``, "ekf-inv-ids" with None).
    """

    name = "ekf-inv"

    def __init__(self, header: Header, **kwargs):
        super().__init__(header, **kwargs)
        self.name = "ekf-inv" + self.name[len("ekf"):]

    def _position_rows(self) -> np.ndarray:
        """Index of x of every position in the state: the robot's, then each landmark's."""
        return np.array([0] + list(self._x_index), dtype=int)

    def _correct(self, n: int, P: np.ndarray, cols: np.ndarray, H_cols: np.ndarray, K: np.ndarray, R: np.ndarray,
                 innovation: np.ndarray) -> None:
        delta = K @ innovation
        add_low_rank_in_place(self._cov, n, *joseph_factors(P, cols, H_cols, K, R))
        mean = self._mean[:n]
        rows = self._position_rows()
        before = np.column_stack([mean[rows], mean[rows + 1]])
        after = group_correction(before, np.column_stack([delta[rows], delta[rows + 1]]), float(delta[2]))
        mean += delta  # heights and reading errors: additive; positions set below
        mean[rows], mean[rows + 1] = after[:, 0], after[:, 1]
        mean[2] = wrap_angle(float(mean[2]))
        u = np.zeros(n)
        moved = (after - before) @ _J.T
        u[rows], u[rows + 1] = moved[:, 0], moved[:, 1]
        add_low_rank_in_place(self._cov, n, *transport_factors(self._cov[:n, :n], 2, u))
