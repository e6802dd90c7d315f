"""The χ² quantile of every gate and band (association gates, NEES/NIS bands, the noise
verdict, covariance ellipses), from ``scipy.special`` alone.

``scipy.stats`` builds all its distributions when it is imported: ~43 MB of resident
memory and ~1 s of every ``fgslam run`` (measured 2026-12-07, docs/performance.md), for
one function. :func:`chi2_ppf` is ``scipy.stats.chi2.ppf(probability, dof)``: the same
formula (``2·gammaincinv(dof/2, p)``, scipy's ``chi2_gen._ppf``) and the same values at the
edges (0 at p = 0, ∞ at p = 1, NaN for dof ≤ 0 or p outside [0, 1]), equal to it bit for
bit (tests/test_chi2.py checks it against scipy.stats).
"""

from __future__ import annotations

import numpy as np
from scipy.special import gammaincinv

__all__ = ["chi2_ppf"]


def chi2_ppf(probability, dof):
    """The ``probability`` quantile of a χ² distribution with ``dof`` degrees of freedom
    (scalars or arrays, broadcast; a numpy scalar for scalars, as ``scipy.stats.chi2.ppf``)."""
    p, k = np.broadcast_arrays(np.asarray(probability, dtype=float), np.asarray(dof, dtype=float))
    valid = (k > 0) & (p >= 0) & (p <= 1)
    out = np.full(p.shape, np.nan)
    out[valid] = 2 * gammaincinv(k[valid] / 2, p[valid])
    return out[()] if out.ndim == 0 else out
