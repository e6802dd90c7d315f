"""A factor graph linearised at a solution, as sparse arrays: what the noise verdict
(:mod:`fgslam.verdict`) and the noise fits without truth (:mod:`fgslam.self_calibration`,
:mod:`fgslam.self_calibration3d`) read."""

from __future__ import annotations

import gtsam
import numpy as np
import scipy.sparse as sp

__all__ = ["whitened_system"]


def whitened_system(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> tuple[sp.csr_matrix, np.ndarray]:
    """The whitened Jacobian A (rows in factor order) and the whitened residuals at ``values``."""
    triplets = graph.linearize(values).sparseJacobian_()
    rows, cols, vals = triplets[0].astype(int) - 1, triplets[1].astype(int) - 1, triplets[2]
    n = int(cols.max())  # the last column is the right-hand side b = −(whitened error)
    # every factor's rows, also trailing ones the triplets leave out (all zero at ``values``)
    m = max(int(rows.max()) + 1, sum(int(graph.at(i).dim()) for i in range(graph.size()) if graph.at(i) is not None))
    in_a = cols < n
    A = sp.csr_matrix((vals[in_a], (rows[in_a], cols[in_a])), shape=(m, n))
    b = np.zeros(m)
    b[rows[~in_a]] = vals[~in_a]
    return A, b
