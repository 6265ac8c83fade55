"""Quantiles of the chi-squared and F distributions, in plain Python (``math``).

:func:`vfactor.shape_evidence.covariance_inflation` needs ``F_level(dim, nu)``
and ``chi2_level(dim)``. SciPy has them (``scipy.special.fdtri``, ``chdtri``),
but importing ``scipy.special`` costs about 0.3 s, which a fresh process would
pay on its first solve (docs/performance.md, "Scale-out (issue 15)"). These
follow Numerical Recipes (3rd ed., 6.2 and 6.4): the regularised incomplete
gamma function by its series or continued fraction, the regularised
incomplete beta function by its continued fraction (modified Lentz), each
inverted by Newton's method kept inside a bisection bracket. They agree with
SciPy's to about 1e-12 relative up to a thousand degrees of freedom, about
1e-9 at a million (lgamma's cancellation; tests/test_stats.py).
"""

from __future__ import annotations

import math
from functools import lru_cache

__all__ = ["chi2_quantile", "f_quantile"]

_EPS = 1e-15
_TINY = 1e-300
_MAX_TERMS = 100_000


def _lower_gamma(a: float, x: float) -> float:
    """The regularised lower incomplete gamma function ``P(a, x)`` (``a > 0``, ``x >= 0``)."""
    if x <= 0.0:
        return 0.0
    log_prefactor = -x + a * math.log(x) - math.lgamma(a)
    if x < a + 1.0:  # series
        term = total = 1.0 / a
        for n in range(1, _MAX_TERMS):
            term *= x / (a + n)
            total += term
            if abs(term) < abs(total) * _EPS:
                break
        return total * math.exp(log_prefactor)
    # continued fraction for Q(a, x) = 1 - P(a, x)
    b = x + 1.0 - a
    c, d = 1.0 / _TINY, 1.0 / b
    h = d
    for i in range(1, _MAX_TERMS):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = _TINY if abs(d) < _TINY else d
        c = b + an / c
        c = _TINY if abs(c) < _TINY else c
        d = 1.0 / d
        step = d * c
        h *= step
        if abs(step - 1.0) < _EPS:
            break
    return 1.0 - math.exp(log_prefactor) * h


def _beta_fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of the incomplete beta function (modified Lentz)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (_TINY if abs(d) < _TINY else d)
    h = d
    for m in range(1, _MAX_TERMS):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (_TINY if abs(d) < _TINY else d)
        c = 1.0 + aa / c
        c = _TINY if abs(c) < _TINY else c
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (_TINY if abs(d) < _TINY else d)
        c = 1.0 + aa / c
        c = _TINY if abs(c) < _TINY else c
        step = d * c
        h *= step
        if abs(step - 1.0) < _EPS:
            break
    return h


def _log_beta_density_factor(a: float, b: float) -> float:
    return math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b)


def _regularised_beta(a: float, b: float, x: float, log_norm: float) -> float:
    """``I_x(a, b)``, ``log_norm = log(1 / B(a, b))``."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    front = math.exp(log_norm + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _beta_fraction(a, b, x) / a
    return 1.0 - front * _beta_fraction(b, a, 1.0 - x) / b


def _invert(cdf, log_density, p: float, lo: float, hi: float, start: float) -> float:
    """The ``x`` in ``(lo, hi)`` with ``cdf(x) = p``: Newton's method, bisection where a step leaves the bracket."""
    x = start
    for _ in range(200):
        f = cdf(x) - p
        if f == 0.0:
            return x
        if f < 0.0:
            lo = x
        else:
            hi = x
        step = f / math.exp(log_density(x))
        candidate = x - step
        if not lo < candidate < hi:
            candidate = 0.5 * (lo + hi)
        if abs(candidate - x) <= 4e-16 * abs(x):
            return candidate
        x = candidate
    return x


@lru_cache(maxsize=256)
def chi2_quantile(dof: float, p: float) -> float:
    """The ``p`` quantile of ``chi2(dof)`` (as ``scipy.special.chdtri(dof, 1 - p)``; cached: the solves ask for a few
    levels, each about 0.1 ms to invert).

    Args:
        dof: degrees of freedom, > 0.
        p: probability in (0, 1).
    """
    if not (dof > 0 and 0.0 < p < 1.0):
        raise ValueError(f"chi2_quantile: expected dof > 0 and 0 < p < 1, got {dof!r}, {p!r}")
    a = 0.5 * dof
    lgamma_a = math.lgamma(a)

    def log_density(y: float) -> float:  # of y = x / 2 ~ Gamma(a)
        return -y + (a - 1.0) * math.log(y) - lgamma_a

    hi = max(2.0 * a, 1.0)
    while _lower_gamma(a, hi) < p:
        hi *= 2.0
    y = _invert(lambda y: _lower_gamma(a, y), log_density, p, 0.0, hi, min(a, 0.5 * hi) if a > 0.5 else 0.5 * hi)
    return 2.0 * y


@lru_cache(maxsize=1024)
def f_quantile(dfn: float, dfd: float, p: float) -> float:
    """The ``p`` quantile of ``F(dfn, dfd)`` (as ``scipy.special.fdtri(dfn, dfd, p)``; cached).

    Through ``w ~ Beta(dfn / 2, dfd / 2)``: ``F = (dfd / dfn) w / (1 - w)``.

    Args:
        dfn, dfd: degrees of freedom of the numerator and the denominator, > 0.
        p: probability in (0, 1).
    """
    if not (dfn > 0 and dfd > 0 and 0.0 < p < 1.0):
        raise ValueError(f"f_quantile: expected dfn, dfd > 0 and 0 < p < 1, got {dfn!r}, {dfd!r}, {p!r}")
    a, b = 0.5 * dfn, 0.5 * dfd
    log_norm = _log_beta_density_factor(a, b)

    def log_density(w: float) -> float:
        return log_norm + (a - 1.0) * math.log(w) + (b - 1.0) * math.log1p(-w)

    w = _invert(lambda w: _regularised_beta(a, b, w, log_norm), log_density, p, 0.0, 1.0, a / (a + b))
    return (dfd / dfn) * w / (1.0 - w)

