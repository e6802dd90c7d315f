"""Tests of ``ekf.association`` against independent references (all randomness seeded).

* Mahalanobis distances against a direct ``inv(S)`` computation; the gate against scipy;
* gated nearest neighbour against a brute-force implementation of its own rule;
* JCBB against an exhaustive search over every hypothesis of small random problems
  (both joint-test modes), including padded height rows;
* a hand-made ambiguous scene where NN mis-associates and JCBB is right;
* the node cap.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.stats import chi2

from ekf.association import (
    DEFAULT_AMBIGUITY_MARGIN,
    ambiguous_pairs,
    chi2_gate,
    free_candidates,
    gated_nearest_neighbour,
    individual_compatibility,
    innovation_covariances,
    jcbb,
    joint_mahalanobis_squared,
    mahalanobis_squared,
    settle_pairing,
)
from ekf.models import range_bearing, range_bearing_jacobians
from slamio.geometry import wrap_angle

# --------------------------------------------------------------------------- problems


def random_spd(rng, n, scale=1.0):
    """A random symmetric positive-definite n×n matrix of order ``scale`` (A·Aᵀ/n + 0.1·I):
    eigenvalues down to 0.1·scale, so some directions are much tighter than others (not
    test_ekf's, which is kept well conditioned)."""
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T / n + 0.1 * np.eye(n))


def make_problem(rng, n_obs, n_lm, *, spread_m=0.6, pose_sigma_m=0.25, heights=False):
    """A linearised association problem from a small, deliberately ambiguous scene.

    Robot at the origin with an uncertain pose; ``n_lm`` landmarks clustered ~3 m ahead,
    ``spread_m`` apart; ``n_obs`` observations of a random subset of them (and of unmapped
    clutter points when there are more observations than landmarks), made from a true
    pose and true landmarks drawn from the filter's own distribution. Returns
    ``(nu, H, P, R, dof)`` over the reduced state (pose, landmarks) — with a padded third
    row (height) when ``heights`` is set.
    """
    k = 3 if heights else 2
    d = 3 + k * n_lm
    P = np.zeros((d, d))
    P[:3, :3] = np.diag([pose_sigma_m**2, pose_sigma_m**2, (0.3 * pose_sigma_m) ** 2])
    P[3:, 3:] = random_spd(rng, d - 3, 0.01)
    # correlate the map with the pose, keeping P positive definite
    L = np.linalg.cholesky(P)
    mix = np.eye(d)
    mix[3:, :3] = rng.normal(scale=0.3, size=(d - 3, 3))
    L = mix @ L
    P = L @ L.T
    pose = np.zeros(3)
    lm = np.column_stack([3.0 + spread_m * rng.normal(size=n_lm), spread_m * rng.normal(size=n_lm)])
    lm_h = rng.uniform(0.2, 0.8, size=n_lm)
    has_h_lm = rng.random(n_lm) < 0.7 if heights else np.zeros(n_lm, bool)
    state = np.concatenate([pose] + [np.r_[lm[j], lm_h[j]][:k] for j in range(n_lm)])
    true_state = state + L @ rng.normal(size=d)
    sigma_r, sigma_b, sigma_h = 0.03, 0.01, 0.02
    seen = rng.permutation(n_lm + max(0, n_obs - n_lm))[:n_obs]
    nu = np.zeros((n_obs, n_lm, 3 if heights else 2))
    H = np.zeros(nu.shape + (d,))
    R = np.zeros((n_obs, nu.shape[2], nu.shape[2]))
    dof = np.full((n_obs, n_lm), 2, dtype=int)
    for i, t in enumerate(seen):
        if t < n_lm:
            p_true = true_state[3 + k * t : 3 + k * t + 2]
            h_true = true_state[3 + k * t + 2] if heights else 0.5
        else:  # clutter: an unmapped point near the cluster
            p_true = np.array([3.0, 0.0]) + spread_m * rng.normal(size=2)
            h_true = 0.5
        r, b = range_bearing(true_state[:3], p_true)
        z = np.array([r + sigma_r * rng.normal(), wrap_angle(b + sigma_b * rng.normal())])
        obs_h = heights and rng.random() < 0.7
        R[i, 0, 0], R[i, 1, 1] = sigma_r**2, sigma_b**2
        if heights:
            R[i, 2, 2] = sigma_h**2 if obs_h else 1.0
        for j in range(n_lm):
            zh = np.array(range_bearing(pose, lm[j]))
            Hp, Hl = range_bearing_jacobians(pose, lm[j])
            nu[i, j, 0] = z[0] - zh[0]
            nu[i, j, 1] = wrap_angle(z[1] - zh[1])
            H[i, j, :2, :3] = Hp
            H[i, j, :2, 3 + k * j : 3 + k * j + 2] = Hl
            if heights and obs_h and has_h_lm[j]:
                nu[i, j, 2] = (h_true + sigma_h * rng.normal()) - lm_h[j]
                H[i, j, 2, 3 + k * j + 2] = 1.0
                dof[i, j] = 3
    return nu, H, P, R, dof


def exhaustive(nu, H, P, R, dof, probability, candidate_probability, joint_test):
    """Best hypothesis by brute force: every injective partial map over the candidate
    pairs; feasible when the whole hypothesis (and, for "prefix", every prefix in
    observation order) is jointly compatible. Most pairs, then least D²."""
    n, M = nu.shape[:2]
    d2 = individual_compatibility(nu, H, P, R)
    inside = d2 <= chi2.ppf(candidate_probability, dof)
    candidates = [[None] + [j for j in range(M) if inside[i, j]] for i in range(n)]
    best = (0, 0.0, (None,) * n)
    for hypothesis in itertools.product(*candidates):
        used = [j for j in hypothesis if j is not None]
        if len(used) != len(set(used)) or len(used) < best[0]:
            continue
        prefixes = range(1, n + 1) if joint_test == "prefix" else [n]
        feasible = True
        for end in prefixes:
            partial = list(hypothesis[:end]) + [None] * (n - end)
            if end < n and hypothesis[end - 1] is None:
                continue
            D2, f = joint_mahalanobis_squared(partial, nu, H, P, R, dof)
            if f and D2 > chi2.ppf(probability, f):
                feasible = False
                break
        if not feasible:
            continue
        D2, _ = joint_mahalanobis_squared(hypothesis, nu, H, P, R, dof)
        if len(used) > best[0] or (len(used) == best[0] and D2 < best[1]):
            best = (len(used), D2, hypothesis)
    return best


# --------------------------------------------------------------------------- distances and gate


def test_gate_matches_scipy():
    for p in (0.9, 0.95, 0.99, 0.999, 0.999999):
        for dof in range(1, 40):
            assert chi2_gate(dof, p) == pytest.approx(chi2.ppf(p, dof), rel=1e-12)
        np.testing.assert_allclose(chi2_gate(np.array([[2, 3], [4, 2]]), p), chi2.ppf(p, [[2, 3], [4, 2]]), rtol=1e-12)
    assert chi2_gate(2, 0.99) == pytest.approx(9.21034037, rel=1e-8)
    with pytest.raises(ValueError):
        chi2_gate(2, 1.0)


def test_mahalanobis_distances_match_direct_computation():
    rng = np.random.default_rng(1)
    nu, H, P, R, dof = make_problem(rng, 4, 5)
    d2 = individual_compatibility(nu, H, P, R)
    for i in range(4):
        for j in range(5):
            S = H[i, j] @ P @ H[i, j].T + R[i]
            assert d2[i, j] == pytest.approx(nu[i, j] @ np.linalg.inv(S) @ nu[i, j], rel=1e-10)
    S = innovation_covariances(H, P, R)
    np.testing.assert_allclose(S, np.swapaxes(S, -1, -2), atol=0)
    # joint distance of a single pair is the individual one; of a hypothesis, the stacked form
    assert joint_mahalanobis_squared([1, None, None, None], nu, H, P, R)[0] == pytest.approx(d2[0, 1], rel=1e-10)
    pairing = [0, None, 3, 1]
    rows = [(0, 0), (2, 3), (3, 1)]
    v = np.concatenate([nu[i, j] for i, j in rows])
    Hs = np.vstack([H[i, j] for i, j in rows])
    Rs = np.zeros((6, 6))
    for k, (i, _) in enumerate(rows):
        Rs[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = R[i]
    expected = v @ np.linalg.inv(Hs @ P @ Hs.T + Rs) @ v
    D2, f = joint_mahalanobis_squared(pairing, nu, H, P, R)
    assert D2 == pytest.approx(expected, rel=1e-10) and f == 6
    assert mahalanobis_squared(np.array([3.0, 4.0]), np.eye(2) * 4.0) == pytest.approx(25.0 / 4.0)


def test_padded_height_rows_add_nothing():
    rng = np.random.default_rng(2)
    nu, H, P, R, dof = make_problem(rng, 5, 4, heights=True)
    d2 = individual_compatibility(nu, H, P, R)
    d2_rb = individual_compatibility(nu[..., :2], H[..., :2, :], P, R[:, :2, :2])
    padded = dof == 2
    assert padded.any() and (~padded).any()
    np.testing.assert_allclose(d2[padded], d2_rb[padded], rtol=1e-10)
    assert np.all(d2[~padded] >= d2_rb[~padded] - 1e-9)  # a real height row can only add


# --------------------------------------------------------------------------- nearest neighbour


def nn_brute_force(d2, gate):
    """The NN rule spelled out with loops: nearest compatible landmark per observation;
    a landmark chosen by several goes to the smallest d² (lower index on ties)."""
    n, M = d2.shape
    choice = []
    for i in range(n):
        best_j, best_d = None, math.inf
        for j in range(M):
            if d2[i, j] <= gate and d2[i, j] < best_d:
                best_j, best_d = j, d2[i, j]
        choice.append(best_j)
    result = [None] * n
    for i in range(n):
        j = choice[i]
        if j is None:
            continue
        rivals = [k for k in range(n) if choice[k] == j]
        winner = min(rivals, key=lambda k: (d2[k, j], k))
        if winner == i:
            result[i] = j
    return result


def test_nearest_neighbour_matches_brute_force():
    rng = np.random.default_rng(3)
    conflicts = 0
    for trial in range(300):
        n, M = rng.integers(1, 7), rng.integers(1, 7)
        d2 = rng.exponential(8.0, size=(n, M))
        if trial % 3 == 0:
            d2 = np.round(d2)  # exact ties
        got = gated_nearest_neighbour(d2, 9.21)
        assert got == nn_brute_force(d2, 9.21)
        chosen = [j for j in got if j is not None]
        assert len(chosen) == len(set(chosen))
        conflicts += sum(1 for i in range(n) if got[i] is None and np.any(d2[i] <= 9.21))
    assert conflicts > 20  # the conflict rule was exercised
    assert gated_nearest_neighbour(np.zeros((3, 0)), 9.21) == [None, None, None]
    # per-pair gates (different dof)
    d2 = np.array([[10.0, 12.0]])
    assert gated_nearest_neighbour(d2, np.array([[9.21, 11.34]])) == [None]
    assert gated_nearest_neighbour(d2, np.array([[11.0, 13.0]])) == [0]


# --------------------------------------------------------------------------- JCBB


@pytest.mark.parametrize("joint_test", ["final", "prefix"])
def test_jcbb_matches_exhaustive_search(joint_test):
    rng = np.random.default_rng(4 if joint_test == "final" else 5)
    ambiguous = 0
    for trial in range(60):
        n, M = int(rng.integers(1, 7)), int(rng.integers(1, 7))
        heights = trial % 4 == 3
        nu, H, P, R, dof = make_problem(rng, n, M, spread_m=rng.choice([0.15, 0.4, 1.0]), heights=heights)
        p, p_cand = 0.99, (0.99 if trial % 2 else 0.999999)
        got = jcbb(nu, H, P, R, dof=dof, probability=p, candidate_probability=p_cand, joint_test=joint_test)
        pairs, D2, hypothesis = exhaustive(nu, H, P, R, dof, p, p_cand, joint_test)
        assert got.pairs == pairs, (trial, got, hypothesis)
        assert got.joint_d2 == pytest.approx(D2, rel=1e-8, abs=1e-10)
        # the returned hypothesis is what it claims to be
        D2_direct, f = joint_mahalanobis_squared(got.pairing, nu, H, P, R, dof)
        assert got.joint_d2 == pytest.approx(D2_direct, rel=1e-8, abs=1e-10) and got.dof == f
        assert sum(j is not None for j in got.pairing) == got.pairs
        assert not got.truncated
        d2 = individual_compatibility(nu, H, P, R)
        ambiguous += int(np.sum(d2 <= chi2.ppf(p, dof)) > n)
    assert ambiguous > 15  # many problems had more compatible pairs than observations


def test_final_joint_test_never_pairs_fewer_than_prefix():
    rng = np.random.default_rng(6)
    for _ in range(40):
        nu, H, P, R, dof = make_problem(rng, int(rng.integers(2, 7)), int(rng.integers(2, 7)), spread_m=0.3)
        final = jcbb(nu, H, P, R, dof=dof, joint_test="final")
        prefix = jcbb(nu, H, P, R, dof=dof, joint_test="prefix")
        assert final.pairs >= prefix.pairs
        if final.pairs == prefix.pairs:
            assert final.joint_d2 <= prefix.joint_d2 + 1e-9


def ambiguous_scene():
    """Two landmarks 0.4 m apart on the robot's x axis, the robot's x uncertain (σ 0.3 m)
    and really 0.4 m further forward than estimated: the observation of L1 looks like L0
    and the observation of L0 looks like nothing mapped (but fits L0 within the gate)."""
    P = np.diag([0.3**2, 0.01**2, 0.002**2, 1e-6, 1e-6, 1e-6, 1e-6])
    landmarks = [np.array([3.0, 0.0]), np.array([3.4, 0.02])]
    true_pose = np.array([0.4, 0.0, 0.0])
    sigma_r, sigma_b = 0.02, 0.005
    R = np.tile(np.diag([sigma_r**2, sigma_b**2]), (2, 1, 1))
    nu = np.zeros((2, 2, 2))
    H = np.zeros((2, 2, 2, 7))
    for i, true_lm in enumerate(landmarks):
        z = np.array(range_bearing(true_pose, true_lm))
        for j, lm in enumerate(landmarks):
            zh = np.array(range_bearing(np.zeros(3), lm))
            Hp, Hl = range_bearing_jacobians(np.zeros(3), lm)
            nu[i, j] = [z[0] - zh[0], wrap_angle(z[1] - zh[1])]
            H[i, j, :, :3] = Hp
            H[i, j, :, 3 + 2 * j : 5 + 2 * j] = Hl
    return nu, H, P, R


def test_ambiguous_scene_nn_wrong_jcbb_right():
    nu, H, P, R = ambiguous_scene()
    d2 = individual_compatibility(nu, H, P, R)
    gate = chi2_gate(2, 0.99)
    assert np.all(d2 <= gate)  # every pairing is individually plausible
    nn = gated_nearest_neighbour(d2, gate)
    assert nn == [None, 0]  # L1's observation taken as L0; L0's observation rejected
    for joint_test in ("final", "prefix"):
        result = jcbb(nu, H, P, R, probability=0.99, joint_test=joint_test)
        assert result.pairing == (0, 1) and result.pairs == 2
    # the swapped hypothesis is jointly incompatible, the right one is not
    assert joint_mahalanobis_squared([1, 0], nu, H, P, R)[0] > chi2_gate(4, 0.99)
    assert joint_mahalanobis_squared([0, 1], nu, H, P, R)[0] < chi2_gate(4, 0.99)


def test_jcbb_node_cap_returns_best_so_far():
    rng = np.random.default_rng(7)
    nu, H, P, R, dof = make_problem(rng, 6, 6, spread_m=0.1, pose_sigma_m=0.6)
    full = jcbb(nu, H, P, R, dof=dof)
    capped = jcbb(nu, H, P, R, dof=dof, max_nodes=5)
    assert full.nodes > 5 and not full.truncated
    assert capped.truncated and capped.nodes == 5
    assert capped.pairs <= full.pairs
    if capped.pairs:
        D2, _ = joint_mahalanobis_squared(capped.pairing, nu, H, P, R, dof)
        assert D2 <= chi2_gate(capped.dof, 0.99)


def test_jcbb_trivial_inputs():
    empty = jcbb(np.zeros((0, 3, 2)), np.zeros((0, 3, 2, 9)), np.eye(9), np.zeros((0, 2, 2)))
    assert empty.pairing == () and empty.pairs == 0
    none = jcbb(np.full((2, 1, 2), 100.0), np.zeros((2, 1, 2, 5)), np.eye(5), np.tile(np.eye(2), (2, 1, 1)))
    assert none.pairing == (None, None) and none.joint_d2 == 0.0
    with pytest.raises(ValueError):
        jcbb(np.zeros((1, 1, 2)), np.zeros((1, 1, 2, 5)), np.eye(5), np.eye(2)[None], joint_test="bogus")


# --------------------------------------------------------------------------- after JCBB


def test_a_landmark_taken_in_the_frame_is_no_candidate_for_the_others():
    candidate = np.array([[True, False, False], [True, False, False], [True, False, True], [False, False, False]])
    free = free_candidates(candidate, [0, None, None, None])
    # obs 1 could only be landmark 0, which obs 0 saw: a landmark not in the map;
    # obs 2 could still be landmark 2; obs 3 has no candidate at all
    assert free.tolist() == [False, False, True, False]
    assert free_candidates(candidate, [None] * 4).tolist() == [True, True, True, False]


def test_a_pair_is_ambiguous_when_another_free_landmark_is_less_than_100_times_less_likely():
    assert DEFAULT_AMBIGUITY_MARGIN == pytest.approx(2.0 * math.log(100.0))
    d2 = np.array([[1.0, 9.0, 60.0], [2.0, 20.0, 3.0], [0.5, 40.0, 40.0]])
    pairing = [0, None, None]
    # likelihood ratio of the chosen landmark to the best free other one, exp(-d²/2) each
    ratio = [math.exp(-d2[0, 0] / 2) / math.exp(-d2[0, 1] / 2)]
    assert ratio[0] < 100.0
    assert ambiguous_pairs(d2, pairing).tolist() == [True, False, False]
    # obs 0 with landmark 1 and obs 1 with landmark 0: landmark 2 is the only free one;
    # obs 0: 60 - 9 apart (not ambiguous), obs 1: 3 - 2 (ambiguous)
    assert ambiguous_pairs(d2, [1, 0, None]).tolist() == [False, True, False]
    assert not ambiguous_pairs(d2, [0, 1, 2]).any()  # nothing free: nothing to confuse it with


def test_settle_pairing_drops_ambiguous_pairs_and_rejects_them():
    d2 = np.array([[1.0, 9.0], [40.0, 50.0]])
    candidate = d2 <= chi2_gate(2, 0.999999)
    pairing, near = settle_pairing(candidate, d2, [0, None])
    assert pairing == [None, None] and near.tolist() == [True, False]  # 9 - 1 < 9.2: rejected
    pairing, near = settle_pairing(candidate, d2, [0, None], margin=None)
    assert pairing == [0, None] and near.tolist() == [False, False]
    # a clear pair is kept; the other observation, whose only candidate it took, is new
    d2 = np.array([[1.0, 80.0], [5.0, 90.0]])
    pairing, near = settle_pairing(d2 <= chi2_gate(2, 0.999999), d2, [0, None])
    assert pairing == [0, None] and near.tolist() == [False, False]
