"""A factor graph linearised at a solution, as sparse arrays: what the noise verdict
(:mod:`fgslam.verdict`) and the noise fits without truth (:mod:`fgslam.self_calibration`,
:mod:`fgslam.self_calibration3d`) read."""

from __future__ import annotations

import gtsam
import numpy as np
import scipy.sparse as sp

__all__ = ["fill_reducing_columns", "whitened_system"]


def whitened_system(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> tuple[sp.csr_matrix, np.ndarray]:
    """The whitened Jacobian A (rows in factor order, columns in the fill-reducing order of
    :func:`fill_reducing_columns`) and the whitened residuals at ``values``.

    Everything read from A here — the hat matrix ``A (AᵀA)⁻¹ Aᵀ``, residuals of least squares —
    is the same whatever the order of its columns; factorise ``AᵀA`` in that order
    (``hat_traces(..., columns_ordered=True)``)."""
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


def fill_reducing_columns(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> np.ndarray:
    """The columns of ``graph``'s Jacobian (GTSAM's order: keys ascending, each key's block of
    its dimension) in the order of GTSAM's METIS nested dissection of the graph's variables.

    Minimum degree on AᵀA (SuperLU's orderings) fills in very differently from one graph to
    the next: on a long stereo drive 74 M entries (44 s), on Plaza1 COLAMD 41 M; factorised in
    this order 14 M (1.4 s) and 0.8 M (docs/performance.md). METIS is given only the factors
    that join two or more variables: GTSAM's METIS crashes (a segmentation fault) on a
    variable no such factor reaches, e.g. a landmark's height held by priors alone; those
    variables, which cause no fill, come last."""
    keys = sorted(graph.keyVector())
    zero = values.zeroVectors()
    dims = [len(zero.at(k)) for k in keys]
    first = dict(zip(keys, np.concatenate([[0], np.cumsum(dims)[:-1]]).astype(int)))
    dim = dict(zip(keys, dims))
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
    return np.concatenate([np.arange(first[k], first[k] + dim[k]) for k in keyed]).astype(int)


def _ordered_keys(order: gtsam.Ordering) -> list[int]:
    return [order.at(i) for i in range(order.size())]
