"""Data association for landmarks without ids: χ² gate, gated nearest neighbour, JCBB.

Pure functions of numbers (numpy/scipy only); :class:`ekf.slam.EkfSlam` builds their inputs
from its state. One association problem is all the id-less observations of one step
against the landmarks of the map, linearised at the current estimate.

The linearised problem
    For observation i and landmark j, ``nu[i, j]`` is the innovation ``z_i − h_j(x̂)``
    (bearing component wrapped by the caller) and ``H[i, j]`` its Jacobian with respect to a
    *reduced state* of dimension d (the robot pose and the candidate landmarks; everything
    else in the filter has a zero Jacobian and does not matter). ``P`` is the d×d covariance
    of that reduced state and ``R[i]`` the measurement covariance of observation i.

    Measurements of different sizes (range/bearing with or without a height) are padded to
    a common size m: a padded row has ``nu = 0``, ``H = 0`` and a positive ``R`` on the
    diagonal (0 off it, e.g. 1), so it is an independent row with a zero residual and adds
    exactly 0 to every Mahalanobis distance, individual or joint. ``dof[i, j]`` says how many rows are real; the
    χ² gates use it.

Individual compatibility
    ``S_ij = H_ij P H_ijᵀ + R_i`` and ``d²_ij = nu_ijᵀ S_ij⁻¹ nu_ij``; the pair is
    compatible when ``d²_ij ≤ χ²_{dof_ij}(p)`` (:func:`chi2_gate`).

Gated nearest neighbour (:func:`gated_nearest_neighbour`)
    Each observation chooses, among the landmarks in its gate, the one with the smallest
    d². **Conflict rule:** a landmark can be used at most once per step (one camera frame
    sees a landmark at most once), so when several observations choose the same landmark,
    the one with the smallest d² keeps it and the others are left unpaired — they are *not*
    re-assigned to their second choice, because the conflict itself says the scene is
    ambiguous. (Ties go to the lower observation index.) Landmarks are judged one pair at a
    time: NN ignores that all innovations of a step share the same robot-pose error.

JCBB (:func:`jcbb`; Neira & Tardós, IEEE T-RA 17(6), 2001)
    A depth-first branch and bound over the *interpretation tree*: level i decides
    observation i, whose branches are its candidate landmarks not yet used in the
    hypothesis (nearest first), then the "unpaired" branch (∗). A hypothesis H is
    *jointly compatible* when, with the stacked innovation ν_H and the joint covariance
    ``S_H = H_H P H_Hᵀ + R_H`` (whose off-diagonal blocks ``H_a P H_bᵀ`` carry the shared
    robot-pose error), ``D²_H = ν_Hᵀ S_H⁻¹ ν_H ≤ χ²_{Σdof}(p)``. D² is updated
    incrementally when a pair p is added, from S_H⁻¹ and the Schur complement — O((mk)²)
    for k pairs instead of a new factorisation::

        C = H_H P H_pᵀ,   Σ = S_pp − Cᵀ S_H⁻¹ C,   y = ν_p − Cᵀ S_H⁻¹ ν_H,
        D²_{H+p} = D²_H + yᵀ Σ⁻¹ y.

    The best hypothesis is the one with the most pairs, ties broken by the lower D².

    Bounds. Every increment ``yᵀ Σ⁻¹ y`` is ≥ 0, so D² never decreases along a branch.
    (1) The paper's bound: a node with k pairs at level i can end with at most
    ``k + (n − i)`` pairs; it is pruned when that is below the best so far, or equal to it
    and ``D² ≥ best D²`` (the tie-break extension). (2) Joint compatibility, in one of two
    modes (``joint_test``):

    * ``"prefix"`` — as in the paper, every partial hypothesis must itself pass
      ``χ²_{its dof}(p)``. This prunes hard but is a heuristic: a prefix can fail while a
      longer hypothesis, with a larger threshold, passes, so the result depends on the
      order of the observations;
    * ``"final"`` (default) — only complete hypotheses are tested; a partial one is pruned
      when its D² already exceeds the threshold of the *largest* hypothesis it could grow
      into (its dof plus the most the remaining observations can add). Exact: the result
      is the optimum over all hypotheses whose pairs are candidates and whose whole is
      jointly compatible, whatever the order. ``tests/test_association.py`` checks both
      modes against exhaustive search.

    Candidates. The pairs JCBB may use are those inside an individual gate
    (``candidate_probability``, default ``probability``). ``EkfSlam`` sets it to its wider
    new-landmark gate: the joint test decides, and the per-pair gate only says which
    landmarks an observation could be at all. For one observation alone the joint test
    *is* the individual test at ``probability``; with several, a marginal pair is accepted
    when the others agree with it.

    Work. Fast path: when every observation has exactly one candidate and they are all
    different (the usual case in a well-localised run), the only hypothesis with n pairs
    is tested directly and returned if jointly compatible. Otherwise the search runs, and
    stops after ``max_nodes`` visited nodes (default 20 000), returning the best hypothesis
    found so far, flagged ``truncated``. Candidates are tried nearest first, so the first
    complete hypothesis reached is the greedy one and the cap only cuts the search for
    better ones. On the simulated runs of the project the cap was never reached (largest
    search: 62 nodes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from slamio.chi2 import chi2_ppf

__all__ = [
    "DEFAULT_GATE_PROBABILITY",
    "DEFAULT_MAX_NODES",
    "chi2_gate",
    "mahalanobis_squared",
    "innovation_covariances",
    "individual_compatibility",
    "joint_mahalanobis_squared",
    "gated_nearest_neighbour",
    "DEFAULT_AMBIGUITY_MARGIN",
    "ambiguous_pairs",
    "free_candidates",
    "settle_pairing",
    "JcbbResult",
    "jcbb",
]

#: Probability mass inside the χ² gate. With a consistent filter a true pairing falls
#: outside its gate with probability 1 − p and is lost (rejected). 0.99, the textbook
#: choice, caps the association rate at about 99 % (measured: 98.9–99.6 % on the arena,
#: nearly all losses being such rejections); 0.999 loses 0.1 %. The landmarks of the
#: simulated scenes are far apart compared with the gate, so the wider gate costs nothing
#: there; JCBB's joint test is what guards against ambiguity (see docs/estimators.md).
DEFAULT_GATE_PROBABILITY = 0.999

#: A pairing is kept only when its landmark is at least 100 times as likely as any other
#: landmark the step leaves free (``d²`` at least 2 ln 100 = 9.2 apart): about a 1 % chance of
#: taking a neighbour for the landmark when both are equally likely a priori. A rejected
#: reading only loses information; a wrong pairing pulls the pose and the map towards the
#: neighbour and makes the next readings go wrong too. Measured on MRCLAM Dataset 6
#: (docs/estimators.md): 2 ln 10 = 4.6 left 2–4 times as many wrong pairings.
DEFAULT_AMBIGUITY_MARGIN = 2.0 * math.log(100.0)

#: Nodes JCBB may visit before it returns the best hypothesis found so far.
DEFAULT_MAX_NODES = 20_000


# --------------------------------------------------------------------------- distances


def chi2_gate(dof, probability: float = DEFAULT_GATE_PROBABILITY):
    """The χ² gate: ``scipy.stats.chi2.ppf(probability, dof)`` (:func:`slamio.chi2.chi2_ppf`) (float, or array for an array of dof)."""
    if not 0.0 < probability < 1.0:
        raise ValueError(f"gate probability must be in (0, 1), got {probability!r}")
    if np.ndim(dof) == 0:
        return _gate_table(float(probability), int(dof))[int(dof)]
    dof = np.asarray(dof, dtype=int)
    if dof.size == 0:
        return np.zeros(dof.shape)
    return _gate_table(float(probability), int(dof.max()))[dof]


@lru_cache(maxsize=64)
def _gate_table_cached(probability: float, size: int) -> np.ndarray:
    table = np.asarray(chi2_ppf(probability, np.arange(size + 1)), dtype=float)
    table[0] = 0.0  # zero degrees of freedom: nothing measured, nothing allowed
    table.setflags(write=False)
    return table


def _gate_table(probability: float, max_dof: int) -> np.ndarray:
    """χ² quantiles for dof 0 … ≥ max_dof (cached; sizes rounded up to a power of two)."""
    size = 8
    while size < max_dof:
        size *= 2
    return _gate_table_cached(probability, size)


def mahalanobis_squared(innovation, covariance) -> np.ndarray:
    """``νᵀ S⁻¹ ν``, batched over leading dimensions: ν (..., m), S (..., m, m) → (...)."""
    nu = np.asarray(innovation, dtype=float)
    S = np.asarray(covariance, dtype=float)
    x = np.linalg.solve(S, nu[..., None])[..., 0]
    return np.sum(nu * x, axis=-1)


def innovation_covariances(H, P, R) -> np.ndarray:
    """``S[i, j] = H[i, j] P H[i, j]ᵀ + R[i]`` for H (n, M, m, d), P (d, d), R (n, m, m)."""
    H = np.asarray(H, dtype=float)
    S = H @ np.asarray(P, dtype=float) @ np.swapaxes(H, -1, -2)
    S = S + np.asarray(R, dtype=float)[:, None, :, :]
    return 0.5 * (S + np.swapaxes(S, -1, -2))


def individual_compatibility(nu, H, P, R) -> np.ndarray:
    """(n, M) squared Mahalanobis distances ``d²_ij`` of every observation to every landmark."""
    return mahalanobis_squared(nu, innovation_covariances(H, P, R))


def joint_mahalanobis_squared(pairing, nu, H, P, R, dof=None) -> tuple[float, int]:
    """Direct (non-incremental) joint distance of a hypothesis: ``(D², Σ dof)``.

    ``pairing[i]`` is the landmark index of observation i or None. Stacks the paired rows
    and forms the full joint covariance ``H_H P H_Hᵀ + R_H``. Used as the reference in the
    tests and for the final value of a hypothesis.
    """
    nu = np.asarray(nu, dtype=float)
    H = np.asarray(H, dtype=float)
    R = np.asarray(R, dtype=float)
    pairs = [(i, j) for i, j in enumerate(pairing) if j is not None]
    if not pairs:
        return 0.0, 0
    m = nu.shape[-1]
    if dof is None:
        dof = np.full(nu.shape[:2], m, dtype=int)
    v = np.concatenate([nu[i, j] for i, j in pairs])
    Hs = np.vstack([H[i, j] for i, j in pairs])
    Rs = np.zeros((m * len(pairs), m * len(pairs)))
    for k, (i, _) in enumerate(pairs):
        Rs[k * m : (k + 1) * m, k * m : (k + 1) * m] = R[i]
    S = Hs @ np.asarray(P, dtype=float) @ Hs.T + Rs
    S = 0.5 * (S + S.T)
    return float(v @ np.linalg.solve(S, v)), int(sum(int(dof[i, j]) for i, j in pairs))


# --------------------------------------------------------------------------- nearest neighbour


def gated_nearest_neighbour(d2, gate) -> list[int | None]:
    """Gated nearest neighbour with the conflict rule of the module docstring.

    ``d2`` (n, M) squared distances; ``gate`` a scalar or an array broadcastable to
    ``d2`` (per-pair thresholds, e.g. for different dof). Returns, per observation, the
    landmark index it is paired with, or None (no landmark in its gate, or it lost a
    conflict).
    """
    d2 = np.asarray(d2, dtype=float)
    n = d2.shape[0]
    if n == 0 or d2.shape[1] == 0:
        return [None] * n
    inside = d2 <= np.broadcast_to(np.asarray(gate, dtype=float), d2.shape)
    masked = np.where(inside, d2, np.inf)
    choice = np.argmin(masked, axis=1)
    best = masked[np.arange(n), choice]
    result: list[int | None] = [None] * n
    owner: dict[int, int] = {}
    for i in range(n):
        if not np.isfinite(best[i]):
            continue
        j = int(choice[i])
        k = owner.get(j)
        if k is None or best[i] < best[k]:  # strict: ties keep the lower index
            owner[j] = i
    for j, i in owner.items():
        result[i] = j
    return result


def free_candidates(candidate, pairing) -> np.ndarray:
    """Which observations have a candidate landmark that no observation of the step is paired with.

    ``candidate`` (n, M) says which landmarks each observation could be at all (inside the
    new-landmark gate); ``pairing[i]`` is the landmark index observation i was paired with
    (None: unpaired). One frame sees a landmark at most once, so a landmark another
    observation of the same step is paired with is excluded: an unpaired observation whose
    every candidate is taken is a landmark not in the map (a new one).
    """
    free = np.array(candidate, dtype=bool, ndmin=2)
    taken = [j for j in pairing if j is not None]
    if taken:
        free[:, taken] = False
    return free.any(axis=1)


def ambiguous_pairs(d2, pairing, margin: float = DEFAULT_AMBIGUITY_MARGIN) -> np.ndarray:
    """Which paired observations have another landmark almost as likely as the one chosen.

    ``d2`` (n, M) individual squared distances, ``pairing[i]`` observation i's landmark
    index or None. Observation i is ambiguous when a landmark no observation of the step is
    paired with has ``d²`` within ``margin`` of its chosen one's: the chosen landmark is
    then less than ``exp(margin / 2)`` times as likely as that one.
    """
    d2 = np.asarray(d2, dtype=float)
    out = np.zeros(d2.shape[0], dtype=bool)
    free = np.ones(d2.shape[1], dtype=bool)
    free[[j for j in pairing if j is not None]] = False
    for i, j in enumerate(pairing):
        if j is not None and free.any():
            out[i] = bool(d2[i, free].min() - d2[i, j] < margin)
    return out


def settle_pairing(candidate, d2, pairing, margin: float | None = DEFAULT_AMBIGUITY_MARGIN):
    """What becomes of a step's observations after JCBB chose ``pairing``: ``(pairing, near)``.

    ``near[i]`` (False for paired observations): some landmark not paired in the step is inside
    observation i's new-landmark gate (``candidate``, (n, M)), so it is rejected as
    ambiguous rather than made a new landmark (:func:`free_candidates`). A pair that is
    ambiguous (:func:`ambiguous_pairs`, ``margin``; None: no such test) is dropped and the
    observation rejected. Both rules matter only where landmarks stand closer together than
    the gates are wide (MRCLAM's cylinders, 0.18–0.36 m apart in clusters): there the first
    sighting of a landmark's neighbour comes in the same frame as the landmark, and a reading
    that fits two neighbours nearly equally, once paired with the wrong one, pulls pose and map
    towards it so that the next readings go wrong too (docs/estimators.md).
    """
    pairing = list(pairing)
    near = free_candidates(candidate, pairing) & np.array([j is None for j in pairing], dtype=bool)
    if margin is not None:
        for i in np.flatnonzero(ambiguous_pairs(d2, pairing, margin)):
            pairing[i], near[i] = None, True
    return pairing, near


# --------------------------------------------------------------------------- JCBB


@dataclass(frozen=True)
class JcbbResult:
    """The best hypothesis: ``pairing[i]`` = landmark index or None; its number of pairs,
    joint D² and Σ dof; how many nodes the search visited and whether the cap stopped it."""

    pairing: tuple[int | None, ...]
    pairs: int
    joint_d2: float
    dof: int
    nodes: int
    truncated: bool


class _Budget(Exception):
    pass


def jcbb(
    nu,
    H,
    P,
    R,
    *,
    dof=None,
    probability: float = DEFAULT_GATE_PROBABILITY,
    candidate_probability: float | None = None,
    joint_test: str = "final",
    max_nodes: int = DEFAULT_MAX_NODES,
) -> JcbbResult:
    """Joint compatibility branch and bound (see the module docstring).

    ``nu`` (n, M, m), ``H`` (n, M, m, d), ``P`` (d, d), ``R`` (n, m, m), ``dof`` (n, M)
    real rows per pair (default m). Observations are decided in the given order (a caller
    may sort them, e.g. fewest candidates first). The joint gate (per hypothesis) uses
    ``probability``; the individual gate that selects the candidate pairs uses
    ``candidate_probability`` (default: the same).

    ``joint_test``: ``"prefix"`` tests every partial hypothesis against χ² of its own dof,
    as in the paper (order-dependent; see the module docstring); ``"final"`` (default)
    tests only complete hypotheses and prunes a partial one when its D² already exceeds
    the threshold of the largest hypothesis it could grow into — exact for "the most pairs
    such that the whole hypothesis is jointly compatible, then the least D²".
    """
    if joint_test not in ("final", "prefix"):
        raise ValueError(f"joint_test must be 'final' or 'prefix', got {joint_test!r}")
    nu = np.asarray(nu, dtype=float)
    H = np.asarray(H, dtype=float)
    P = np.asarray(P, dtype=float)
    R = np.asarray(R, dtype=float)
    n = nu.shape[0]
    if n == 0 or nu.shape[1] == 0:
        return JcbbResult((None,) * n, 0, 0.0, 0, 0, False)
    M, m = nu.shape[1], nu.shape[2]
    dof = np.full((n, M), m, dtype=int) if dof is None else np.asarray(dof, dtype=int)
    S_ind = innovation_covariances(H, P, R)
    d2_ind = mahalanobis_squared(nu, S_ind)
    if candidate_probability is None:
        candidate_probability = probability
    compatible = d2_ind <= chi2_gate(dof, candidate_probability)
    joint_gate = _gate_table(float(probability), int(dof.max()) * n)

    # Candidates of each observation, nearest first; P Hᵀ for the compatible pairs only.
    candidates = [sorted(np.flatnonzero(compatible[i]).tolist(), key=lambda j, i=i: d2_ind[i, j]) for i in range(n)]
    final = joint_test == "final"

    if final and all(len(c) == 1 for c in candidates) and len({c[0] for c in candidates}) == n:
        # Fast path (the usual case): one candidate each, all different, so there is a
        # single hypothesis with n pairs; if it is jointly compatible it is the answer.
        pairing_all = [c[0] for c in candidates]
        D2, total_dof = joint_mahalanobis_squared(pairing_all, nu, H, P, R, dof)
        if D2 <= joint_gate[total_dof]:
            return JcbbResult(tuple(pairing_all), n, D2, total_dof, 1, False)

    return _JcbbSearch(nu, H, P, dof, S_ind, candidates, joint_gate, final, max_nodes).run()


class _JcbbSearch:
    """The branch and bound of :func:`jcbb` over its candidate pairs: one search's state (the
    hypothesis being grown, the best one so far, the nodes visited)."""

    def __init__(self, nu, H, P, dof, S_ind, candidates, joint_gate, final: bool, max_nodes: int):
        n, M, m = nu.shape
        self.nu, self.H, self.dof, self.S_ind, self.candidates = nu, H, dof, S_ind, candidates
        self.joint_gate, self.final, self.max_nodes = joint_gate, final, max_nodes
        self.n, self.m = n, m
        self.PHt = {(i, j): P @ H[i, j].T for i in range(n) for j in candidates[i]}
        # Largest dof the observations after level i can still add (for the "final" bound).
        most = [max((int(dof[i, j]) for j in candidates[i]), default=0) for i in range(n)]
        self.rest = np.concatenate([np.cumsum(most[::-1])[::-1], [0]]).astype(int).tolist()
        self.best = {"pairs": 0, "d2": np.inf, "pairing": [None] * n, "dof": 0}
        self.nodes = 0
        self.pairing: list[int | None] = [None] * n
        self.used = np.zeros(M, dtype=bool)

    def run(self) -> JcbbResult:
        """Search from the empty hypothesis; the best one found (so far, when the node cap stops it)."""
        truncated = False
        try:
            self.search(0, 0, 0.0, 0, None, None, None, None)
        except _Budget:
            truncated = True
            self.nodes = self.max_nodes
        best, nodes = self.best, self.nodes
        if best["pairs"] == 0:
            return JcbbResult((None,) * self.n, 0, 0.0, 0, nodes, truncated)
        return JcbbResult(tuple(best["pairing"]), int(best["pairs"]), float(best["d2"]), int(best["dof"]), nodes,
                          truncated)

    def search(self, i, k, d2, dof_sum, Hs, nus, Sinv, Sinv_nu) -> None:
        """Decide observation ``i`` given a hypothesis of ``k`` pairs (joint ``d2`` over
        ``dof_sum``; stacked ``Hs``, ``nus``, the inverse ``Sinv`` of its innovation
        covariance and ``Sinv @ nus``): each free candidate in turn, then unpaired."""
        self.nodes += 1
        if self.nodes > self.max_nodes:
            raise _Budget
        best = self.best
        reach = k + (self.n - i)
        if reach < best["pairs"] or (reach == best["pairs"] and d2 >= best["d2"]):
            return
        if i == self.n:
            if not self.final or d2 <= self.joint_gate[dof_sum]:
                best.update(pairs=k, d2=d2, pairing=list(self.pairing), dof=dof_sum)
            return
        for j in self.candidates[i]:
            if self.used[j]:
                continue
            extended = self._extend(i, j, k, d2, dof_sum, Hs, nus, Sinv, Sinv_nu)
            if extended is None:
                continue
            self.used[j] = True
            self.pairing[i] = j
            self.search(i + 1, k + 1, *extended)
            self.pairing[i] = None
            self.used[j] = False
        self.search(i + 1, k, d2, dof_sum, Hs, nus, Sinv, Sinv_nu)  # observation i unpaired

    def _extend(self, i, j, k, d2, dof_sum, Hs, nus, Sinv, Sinv_nu):
        """The hypothesis with pair (i, j) added: its ``(d2, dof_sum, Hs, nus, Sinv, Sinv_nu)``,
        or None when the pair makes the system singular or the joint gate prunes it."""
        nu, H = self.nu, self.H
        dof_new = dof_sum + int(self.dof[i, j])
        D = self.S_ind[i, j]
        if k == 0:
            Sigma, y, SinvC = D, nu[i, j], None
        else:
            C = Hs @ self.PHt[(i, j)]  # (mk)×m: covariance of the stacked innovation with the new one
            SinvC = Sinv @ C
            Sigma = D - C.T @ SinvC
            Sigma = 0.5 * (Sigma + Sigma.T)
            y = nu[i, j] - C.T @ Sinv_nu
        try:
            Sigma_inv = np.linalg.inv(Sigma)
        except np.linalg.LinAlgError:
            return None
        w = Sigma_inv @ y
        d2_new = d2 + float(y @ w)
        if d2_new > self.joint_gate[dof_new + self.rest[i + 1] if self.final else dof_new]:
            return None
        if k == 0:
            return d2_new, dof_new, H[i, j], nu[i, j], Sigma_inv, w
        # Block inverse of [[S_H, C], [Cᵀ, S_pp]] from S_H⁻¹ and the Schur complement Σ.
        km, m = Sinv.shape[0], self.m
        B = SinvC @ Sigma_inv
        Sinv_new = np.empty((km + m, km + m))
        Sinv_new[:km, :km] = Sinv + B @ SinvC.T
        Sinv_new[:km, km:] = -B
        Sinv_new[km:, :km] = -B.T
        Sinv_new[km:, km:] = Sigma_inv
        Sinv_nu_new = np.concatenate([Sinv_nu - SinvC @ w, w])
        return d2_new, dof_new, np.vstack([Hs, H[i, j]]), np.concatenate([nus, nu[i, j]]), Sinv_new, Sinv_nu_new
