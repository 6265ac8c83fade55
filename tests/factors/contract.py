"""Contract every vfactor factor must meet, as a mixin (SymForce style).

A test class supplies ``make_factor()``, ``make_values(rng)`` (a generic point)
and ``make_truth_values()`` (where the factor's error is zero) and inherits the
Jacobian, error-consistency, dimension and zero-at-truth checks.
"""

from __future__ import annotations

import numpy as np

from vfactor.testing import check_factor_jacobians, whitened_error

SEEDS = (0, 1, 2)


class FactorContract:
    rtol = 1e-5
    atol = 1e-6

    def make_factor(self):
        raise NotImplementedError

    def make_values(self, rng):
        raise NotImplementedError

    def make_truth_values(self):
        raise NotImplementedError

    def test_jacobians_match_numerical(self):
        factor = self.make_factor()
        for seed in SEEDS:
            check_factor_jacobians(factor, self.make_values(np.random.default_rng(seed)), rtol=self.rtol, atol=self.atol)

    def test_error_is_half_squared_whitened_residual(self):
        factor = self.make_factor()
        values = self.make_values(np.random.default_rng(7))
        e = whitened_error(factor, values)
        assert np.isclose(factor.error(values), 0.5 * e @ e, rtol=1e-9, atol=1e-12)
        assert factor.error(values) > 0

    def test_dimension(self):
        factor = self.make_factor()
        values = self.make_values(np.random.default_rng(3))
        assert len(whitened_error(factor, values)) == factor.dim()

    def test_zero_at_truth(self):
        factor = self.make_factor()
        assert factor.error(self.make_truth_values()) < 1e-12
