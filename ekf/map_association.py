"""EKF-SLAM's association problem, built from the filter's state: every id-less observation
of a step against every landmark of the map, linearised at the current estimate.

:func:`linearise_map` gives each (observation, landmark) pair its innovation and d² in one
vectorised pass, O(n·M); :func:`reduced_problem` cuts the state down to the pose and the
landmarks some observation could be paired with, which is what JCBB
(:func:`ekf.association.jcbb`) needs. The decisions themselves (gates, nearest neighbour,
JCBB) are in :mod:`ekf.association`; :class:`MapAssociation`, a mixin of
:class:`ekf.slam.EkfSlam`, poses the problem for a step, solves it and applies the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ekf.association import chi2_gate, gated_nearest_neighbour, jcbb, mahalanobis_squared, settle_pairing
from ekf.models import ROBOT_DIM
from ekf.observation import has_height
from slamio.geometry import wrap_angle
from slamio.log import Observation

__all__ = ["Linearised", "MapAssociation", "linearise_map", "reduced_problem"]


@dataclass(frozen=True)
class Linearised:
    """One step's association problem against the whole map (see :func:`linearise_map`)."""

    m: int
    nu: np.ndarray  # (n, M, m)
    d2: np.ndarray  # (n, M)
    dof: np.ndarray  # (n, M)
    H_pose: np.ndarray  # (M, 2, 3)
    H_landmark: np.ndarray  # (M, 2, 2)
    R: np.ndarray  # (n, m, m)
    obs_h: np.ndarray  # (n,) observation has a height
    lm_h: np.ndarray  # (M,) landmark has a height


def linearise_map(mean: np.ndarray, P: np.ndarray, x_index, h_index, observations: list[Observation]) -> Linearised:
    """Innovations, their covariances and d² of every (observation, landmark) pair, O(n·M).

    ``mean`` and ``P`` are the filter's state (robot first); landmark j's (x, y) sit at
    ``x_index[j]``, ``x_index[j] + 1`` and its height at ``h_index[j]`` (−1: none).
    Vectorised over the M landmarks: with ``e = landmark − position``, every landmark's
    ``J = [H_pose | H_landmark]`` (2×5) and ``S_j = J P_j Jᵀ``, where ``P_j`` is the 5×5
    block of P over the robot and that landmark. Height rows are
    added (m = 3) when some observation and some landmark carry a height; a pair where
    either lacks it gets a padded row (zero residual, unit variance, no correlation),
    which adds nothing to d² (see :mod:`ekf.association`).
    """
    n_obs, M = len(observations), len(x_index)
    obs_h = np.array([has_height(o) for o in observations], dtype=bool)
    xi = np.asarray(x_index, dtype=np.intp)
    hi = np.asarray(h_index, dtype=np.intp)
    lm_h = hi >= 0
    m = 3 if (obs_h.any() and lm_h.any()) else 2
    x, y, th = (float(v) for v in mean[:ROBOT_DIM])
    ex, ey = mean[xi] - x, mean[xi + 1] - y
    q = ex * ex + ey * ey
    degenerate = q < 1e-12
    q = np.where(degenerate, 1.0, q)
    r = np.sqrt(q)
    # J = [H_pose | H_landmark] (M, 2, 5) against each landmark's 5×5 block of P.
    J = np.zeros((M, 2, 5))
    J[:, 0, 0], J[:, 0, 1] = -ex / r, -ey / r
    J[:, 1, 0], J[:, 1, 1], J[:, 1, 2] = ey / q, -ex / q, -1.0
    J[:, 0, 3], J[:, 0, 4] = ex / r, ey / r
    J[:, 1, 3], J[:, 1, 4] = -ey / q, ex / q
    Hp, Hl = J[:, :, :3], J[:, :, 3:]
    block = np.empty((M, 5), dtype=np.intp)
    block[:, :3] = np.arange(3)
    block[:, 3], block[:, 4] = xi, xi + 1
    P5 = P[block[:, :, None], block[:, None, :]]  # (M, 5, 5)
    S_lm = np.zeros((M, m, m))
    S_lm[:, :2, :2] = J @ P5 @ np.swapaxes(J, 1, 2)

    z = np.array([[o.range_m, o.bearing_rad] for o in observations], dtype=float).reshape(n_obs, 2)
    nu = np.zeros((n_obs, M, m))
    nu[:, :, 0] = z[:, None, 0] - r[None, :]
    nu[:, :, 1] = wrap_angle(z[:, None, 1] - np.arctan2(ey, ex)[None, :] + th)
    R_obs = np.zeros((n_obs, m, m))
    R_obs[:, 0, 0] = [o.sigma_range_m**2 for o in observations]
    R_obs[:, 1, 1] = [o.sigma_bearing_rad**2 for o in observations]
    dof = np.full((n_obs, M), 2, dtype=int)
    if m == 3:
        hj = np.where(lm_h)[0]
        h_col = hi[hj]
        # S rows of the height: H_h = e_h, so S_hh = P_hh and S_(rb),h = H_p P_rh + H_l P_lh.
        P_rh = P[:ROBOT_DIM, h_col].T  # (k, 3)
        P_lh = np.stack([P[xi[hj], h_col], P[xi[hj] + 1, h_col]], axis=1)  # (k, 2)
        s_cross = (Hp[hj] @ P_rh[:, :, None])[:, :, 0] + (Hl[hj] @ P_lh[:, :, None])[:, :, 0]
        S_lm[hj, :2, 2] = s_cross
        S_lm[hj, 2, :2] = s_cross
        S_lm[hj, 2, 2] = P[h_col, h_col]
        h_obs = np.array([o.height_m if has_height(o) else 0.0 for o in observations], dtype=float)
        R_obs[:, 2, 2] = [o.sigma_height_m**2 if has_height(o) else 1.0 for o in observations]
        valid = obs_h[:, None] & lm_h[None, :]
        h_lm = np.where(lm_h, mean[np.where(lm_h, hi, 0)], 0.0)
        nu[:, :, 2] = np.where(valid, h_obs[:, None] - h_lm[None, :], 0.0)
        dof = np.where(valid, 3, 2)
        S = np.broadcast_to(S_lm, (n_obs, M, m, m)).copy()
        S[:, :, 2, :] *= valid[:, :, None]
        S[:, :, :, 2] *= valid[:, :, None]
        S = S + R_obs[:, None]
        d2 = mahalanobis_squared(nu, S)
    else:
        S = S_lm[None] + R_obs[:, None]
        a, b, c = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
        v0, v1 = nu[..., 0], nu[..., 1]
        d2 = (c * v0 * v0 - 2.0 * b * v0 * v1 + a * v1 * v1) / (a * c - b * b)
    d2 = np.where(degenerate[None, :], np.inf, d2)
    return Linearised(m, nu, d2, dof, Hp, Hl, R_obs, obs_h, lm_h)


def reduced_problem(lin: Linearised, compatible: np.ndarray, P: np.ndarray, x_index, h_index
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """JCBB's inputs over the reduced state: the pose and the landmarks that are candidates
    (``compatible``, n×M) of some observation.

    Returns ``(obs, cand, H, P_red)``: the observations that have a candidate, ordered
    fewest candidates first, then most distinctive (smallest best d²) first; the candidate
    landmarks; the Jacobians ``H`` (len(obs) × len(cand) × m × d) against the reduced state
    (pose, then each candidate's x, y, and h when m = 3 and it has one); and that state's
    d×d covariance ``P_red``.
    """
    obs = np.flatnonzero(compatible.any(axis=1))
    best_d2 = np.where(compatible[obs], lin.d2[obs], np.inf).min(axis=1)
    obs = obs[np.lexsort((best_d2, compatible[obs].sum(axis=1)))]
    cand = np.flatnonzero(compatible[obs].any(axis=0))
    m = lin.m
    columns = [0, 1, 2]
    offset = []
    for j in cand.tolist():
        offset.append(len(columns))
        columns += [x_index[j], x_index[j] + 1]
        if m == 3 and lin.lm_h[j]:
            columns.append(h_index[j])
    columns_arr = np.asarray(columns, dtype=np.intp)
    P_red = P[np.ix_(columns_arr, columns_arr)]
    H = np.zeros((len(obs), len(cand), m, len(columns)))
    for c, j in enumerate(cand.tolist()):
        o = offset[c]
        H[:, c, :2, :3] = lin.H_pose[j]
        H[:, c, :2, o : o + 2] = lin.H_landmark[j]
        if m == 3 and lin.lm_h[j]:
            H[:, c, 2, o + 2] = lin.obs_h[obs].astype(float)
    return obs, cand, H, P_red


class MapAssociation:
    """The filter's side of association (a mixin of :class:`ekf.slam.EkfSlam`, on the state
    its ``__init__`` sets up): one problem for a step's id-less observations against the
    map, solved by gated nearest neighbour or JCBB, then the updates and new landmarks it
    implies."""

    def association_distances(self, observations) -> tuple[list[int], np.ndarray, np.ndarray]:
        """``(keys, d2, dof)`` of observations against every landmark of the current map.

        ``d2[i, j]`` is the squared Mahalanobis distance of observation i to landmark
        ``keys[j]`` (innovation covariance ``H P Hᵀ + R`` at the current estimate, bearing
        residual wrapped; with the height row when both carry a height) and ``dof[i, j]`` its
        number of measured components. Nothing is changed.
        """
        problem = linearise_map(self._mean, self._cov, self._x_index, self._h_index, list(observations))
        return list(self._keys), problem.d2, problem.dof

    def _associate_and_apply(self, observations: list[Observation]) -> list[int | None]:
        """One association problem for the id-less observations of a step, then the updates
        and new landmarks it implies. Returns the key used by each observation (or None)."""
        n = len(observations)
        pairing: list[int | None] = [None] * n
        near = np.zeros(n, dtype=bool)
        if self._keys:
            lin = linearise_map(self._mean, self._cov, self._x_index, self._h_index, observations)
            candidate = lin.d2 <= chi2_gate(lin.dof, self.new_landmark_probability)  # the new-landmark gate
            near = candidate.any(axis=1)
            if self.association == "nn":
                pairing = gated_nearest_neighbour(lin.d2, chi2_gate(lin.dof, self.gate_probability))
            elif near.any():
                pairing = self._jcbb(lin, candidate)
                pairing, near = settle_pairing(candidate, lin.d2, pairing, self.ambiguity_margin)
        keys: list[int | None] = [None] * n
        for i, j in enumerate(pairing):
            if j is not None:
                key = self._keys[j]
                self._update(key, observations[i])
                keys[i] = key
        for i, observation in enumerate(observations):
            if pairing[i] is not None:
                continue
            if near[i]:
                self.rejected_observations += 1
                continue
            key = self._next_key
            self._next_key -= 1
            self._add_landmark(key, observation)
            self.landmarks_created += 1
            keys[i] = key
        return keys

    def _jcbb(self, lin: Linearised, compatible: np.ndarray) -> list[int | None]:
        """JCBB over the reduced state: the pose and the landmarks that are candidates
        (``compatible``, the new-landmark gate) of some observation."""
        obs, cand, H, P_red = reduced_problem(lin, compatible, self._cov, self._x_index, self._h_index)
        result = jcbb(
            lin.nu[np.ix_(obs, cand)],
            H,
            P_red,
            lin.R[obs],
            dof=lin.dof[np.ix_(obs, cand)],
            probability=self.gate_probability,
            candidate_probability=self.new_landmark_probability,
            joint_test=self.joint_test,
            max_nodes=self.max_jcbb_nodes,
        )
        self.jcbb_nodes_max = max(self.jcbb_nodes_max, result.nodes)
        self.jcbb_truncated += int(result.truncated)
        pairing: list[int | None] = [None] * lin.nu.shape[0]
        for a, c in enumerate(result.pairing):
            if c is not None:
                pairing[int(obs[a])] = int(cand[c])
        return pairing
