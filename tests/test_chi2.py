"""slamio.chi2.chi2_ppf against scipy.stats.chi2.ppf (the independent reference): equal bit for bit."""

import numpy as np
import pytest
from scipy.stats import chi2

from slamio.chi2 import chi2_ppf

PROBABILITIES = [0.0, 1e-12, 0.001, 0.01, 0.025, 0.05, 0.5, 0.95, 0.975, 0.99, 0.999, 1 - 1e-12, 1.0]


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 5, 7, 12, 30, 100, 250, 1000, 3 * 63107, 2.5])
def test_equals_scipy_stats_bit_for_bit(dof):
    for p in PROBABILITIES:
        ours, theirs = chi2_ppf(p, dof), chi2.ppf(p, dof)
        assert type(ours) is type(theirs)
        assert ours == theirs, (p, dof)


def test_arrays_broadcast_and_edges_as_scipy():
    dof = np.arange(0, 40)
    for p in (0.95, 0.999):
        np.testing.assert_array_equal(chi2_ppf(p, dof), chi2.ppf(p, dof))  # dof 0: NaN in both
    p = np.array([[-0.1, 0.0, 0.3], [0.7, 1.0, 1.1]])
    np.testing.assert_array_equal(chi2_ppf(p, 3), chi2.ppf(p, 3))
    np.testing.assert_array_equal(chi2_ppf(0.5, [-1, 0, 1]), chi2.ppf(0.5, [-1, 0, 1]))
    assert np.isnan(chi2_ppf(np.nan, 2)) and np.isnan(chi2.ppf(np.nan, 2))
    assert chi2_ppf(0.95, 2) == pytest.approx(5.991464547107979)  # the textbook 95 % ellipse
