"""A factor graph linearised at a solution, as sparse arrays: what the noise verdict
(:mod:`fgslam.verdict`) and the noise fits without truth (:mod:`fgslam.self_calibration`,
:mod:`fgslam.self_calibration3d`) read."""

from __future__ import annotations

import gtsam
import numpy as np
import scipy.sparse as sp

from slamio.noise.errors import NoiseModelError
from slamio.noise.fit_self import CholeskyFactor

__all__ = ["fill_reducing_columns", "fill_reducing_keys", "normal_cholesky", "whitened_system"]


def whitened_system(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> tuple[sp.csr_matrix, np.ndarray]:
    """The whitened Jacobian A (rows in factor order, columns in the fill-reducing order of
    :func:`fill_reducing_columns`) and the whitened residuals at ``values``.

    Everything read from A here — the hat matrix ``A (AᵀA)⁻¹ Aᵀ``, residuals of least squares —
    is the same whatever the order of its columns; factorise ``AᵀA`` in that order
    (``hat_traces(..., columns_ordered=True)``, or :func:`normal_cholesky`)."""
    triplets = graph.linearize(values).sparseJacobian_()
    rows, cols, vals = triplets[0].astype(int) - 1, triplets[1].astype(int) - 1, triplets[2]
    n = int(cols.max())  # the last column is the right-hand side b = −(whitened error)
    # every factor's rows, also trailing ones the triplets leave out (all zero at ``values``)
    m = max(int(rows.max()) + 1, sum(int(graph.at(i).dim()) for i in range(graph.size()) if graph.at(i) is not None))
    in_a = cols < n
    A = sp.csr_matrix((vals[in_a], (rows[in_a], cols[in_a])), shape=(m, n))
    b = np.zeros(m)
    b[rows[~in_a]] = vals[~in_a]
    return A[:, fill_reducing_columns(graph, values)], b


def normal_cholesky(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> CholeskyFactor:
    """``AᵀA = Rᵀ R`` of the whitened Jacobian A of :func:`whitened_system` (same columns,
    same order), from GTSAM's sequential elimination of ``graph`` linearised at ``values`` in
    that order: what :func:`slamio.noise.fit_self.hat_traces` solves with (``factor=``).

    Why not SuperLU (``scipy.sparse.linalg.splu`` of AᵀA, what ``hat_traces`` does without a
    factor): it keeps L and U and grows its work space by doubling; on the long dense stereo
    drive of ``scripts/bench_vio.py`` (11 505 unknowns) its factor held 14.4 M entries and
    added 310 MB of resident memory, where R holds 3.0 M (+~40 MB) and is made 2–3× faster.
    Raises :class:`~slamio.noise.errors.NoiseModelError` when the system is singular (a pose
    or landmark no measurement fixes)."""
    keys, dims = fill_reducing_keys(graph, values)
    ordering = gtsam.Ordering()
    for key in keys:
        ordering.push_back(key)
    try:
        bayes_net = graph.linearize(values).eliminateSequential(ordering)
    except RuntimeError as exc:  # gtsam.IndeterminantLinearSystemException
        raise NoiseModelError(f"the smoothing problem is singular ({str(exc).splitlines()[0]}): a pose or "
                              "landmark no measurement fixes") from None
    first = dict(zip(keys, np.concatenate([[0], np.cumsum([dims[k] for k in keys])[:-1]]).astype(int)))
    return _upper_rows(bayes_net, first, dims, sum(dims.values()))


def _upper_rows(bayes_net, first: dict[int, int], dims: dict[int, int], n: int) -> CholeskyFactor:
    """The :class:`CholeskyFactor` of a Gaussian Bayes net of one frontal variable per
    conditional (unit noise: Cholesky), whose rows of R start at ``first[key]``: R row by row
    (CSR), each conditional's ``[R S]`` block's upper part, columns ascending."""
    blocks = [bayes_net.at(i) for i in range(bayes_net.size())]
    counts = np.zeros(n + 1, dtype=np.int64)
    for conditional in blocks:
        keys = list(conditional.keys())
        d, width = dims[keys[0]], sum(dims[k] for k in keys)
        counts[first[keys[0]] + 1:first[keys[0]] + d + 1] = width - np.arange(d)
    indptr = np.cumsum(counts)
    indices, data = np.empty(indptr[-1], dtype=np.int32), np.empty(indptr[-1])
    for conditional in blocks:
        keys = list(conditional.keys())
        if conditional.get_model() is not None:  # a constrained or non-unit model: not R of AᵀA = RᵀR
            raise NoiseModelError("a conditional with a noise model: the graph is not a plain least-squares problem")
        columns = np.concatenate([np.arange(first[k], first[k] + dims[k]) for k in keys])
        block = np.hstack([conditional.R(), conditional.S()])
        order = np.argsort(columns[dims[keys[0]]:], kind="stable") + dims[keys[0]]
        for r in range(dims[keys[0]]):
            row = first[keys[0]] + r
            cols = np.concatenate([np.arange(r, dims[keys[0]]), order])
            indices[indptr[row]:indptr[row + 1]] = columns[cols]
            data[indptr[row]:indptr[row + 1]] = block[r, cols]
    return CholeskyFactor(sp.csr_matrix((data, indices, indptr), shape=(n, n)))


def fill_reducing_keys(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> tuple[list[int], dict[int, int]]:
    """``(keys, dims)``: ``graph``'s variables in the order of GTSAM's METIS nested dissection
    (:func:`fill_reducing_columns`) and each one's dimension."""
    keys = sorted(graph.keyVector())
    zero = values.zeroVectors()
    dim = {k: len(zero.at(k)) for k in keys}
    joining = gtsam.NonlinearFactorGraph()
    for i in range(graph.size()):
        factor = graph.at(i)
        if factor is not None and len(set(factor.keys())) >= 2:
            joining.push_back(factor)
    keyed = []
    if joining.size():
        keyed = _ordered_keys(gtsam.Ordering.MetisNonlinearFactorGraph(joining))
        if sorted(keyed) != sorted(joining.keyVector()):  # METIS failed (it says so on stderr)
            keyed = _ordered_keys(gtsam.Ordering.ColamdNonlinearFactorGraph(joining))
    placed = set(keyed)
    keyed += [k for k in keys if k not in placed]
    return keyed, dim


def fill_reducing_columns(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> np.ndarray:
    """The columns of ``graph``'s Jacobian (GTSAM's order: keys ascending, each key's block of
    its dimension) in the order of GTSAM's METIS nested dissection of the graph's variables.

    Minimum degree on AᵀA (SuperLU's orderings) fills in very differently from one graph to
    the next: on a long stereo drive 74 M entries (44 s), on Plaza1 COLAMD 41 M; factorised in
    this order 14 M (1.4 s) and 0.8 M (docs/performance.md). METIS is given only the factors
    that join two or more variables: GTSAM's METIS crashes (a segmentation fault) on a
    variable no such factor reaches, e.g. a landmark's height held by priors alone; those
    variables, which cause no fill, come last."""
    keyed, dim = fill_reducing_keys(graph, values)
    keys = sorted(dim)
    first = dict(zip(keys, np.concatenate([[0], np.cumsum([dim[k] for k in keys])[:-1]]).astype(int)))
    return np.concatenate([np.arange(first[k], first[k] + dim[k]) for k in keyed]).astype(int)


def _ordered_keys(order: gtsam.Ordering) -> list[int]:
    return [order.at(i) for i in range(order.size())]
