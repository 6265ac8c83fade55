"""The chi-squared and F quantiles of vfactor.stats against SciPy's."""

from __future__ import annotations

import pytest
from scipy.special import chdtri, fdtri

from vfactor.stats import chi2_quantile, f_quantile

PROBABILITIES = (0.01, 0.05, 0.5, 0.9, 0.95, 0.99, 0.999)


@pytest.mark.parametrize("dof", [0.5, 1, 2, 3, 5, 6, 7, 12, 36, 100.5])
def test_chi2_quantile_matches_scipy(dof):
    for p in PROBABILITIES:
        assert chi2_quantile(dof, p) == pytest.approx(chdtri(dof, 1.0 - p), rel=1e-13)


@pytest.mark.parametrize("dfn", [1, 2, 3, 6, 7, 12, 36])
def test_f_quantile_matches_scipy(dfn):
    for dfd in (3.0, 3.1, 4.7, 10.0, 20.3, 100.0, 1234.5):
        for p in PROBABILITIES:
            assert f_quantile(dfn, dfd, p) == pytest.approx(fdtri(dfn, dfd, p), rel=1e-11)
    for p in PROBABILITIES:  # lgamma's cancellation at a million degrees of freedom
        assert f_quantile(dfn, 1e6, p) == pytest.approx(fdtri(dfn, 1e6, p), rel=1e-8)


def test_quantiles_reject_what_has_none():
    for bad in ((0.0, 0.5), (3.0, 0.0), (3.0, 1.0)):
        with pytest.raises(ValueError):
            chi2_quantile(*bad)
    with pytest.raises(ValueError):
        f_quantile(6, -1.0, 0.95)

