"""What a solved vehicle's observations say about its shape and their noise: the body-type choice and the pixel-noise scale.

After a first solve with the pooled prior (:class:`vfactor.shape_model.ShapeModel`),
the graph is linearised at the solution. Its dense Gauss-Newton Hessian gives

* the **noise scale** ``s``: the keypoints' pixel sigmas are the detector's
  (confidence- or covariance-derived) sigmas times ``s``, estimated from the
  whitened residuals with a robust (median) estimator corrected for the
  degrees of freedom the solution used (:func:`noise_scale`);
* the **information on the shape** with the pose marginalised out and the
  pooled prior removed (:func:`shape_information`), from which each body
  type's Laplace evidence follows (:meth:`ShapeModel.type_log_evidence`).

docs/factors.md gives the maths.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import gtsam
import numpy as np

from vfactor._kernels import fit_at_scale_kernel, symmetric_eigen_kernel
from vfactor.keys import KeyScheme
from vfactor.shape_model import ANY, ShapeModel, ShapePrior
from vfactor.stats import chi2_quantile, f_quantile

__all__ = ["Linearisation", "linearise", "median_scale", "noise_scale", "inlier_noise_scale", "camera_noise_factors",
           "covariance_inflation", "sandwich_covariance", "considered_covariance", "prior_misfit_covariance",
           "PRIOR_MISFIT_LEVEL",
           "covariance_upper_bound", "symmetric_eigen", "shape_information", "BodyTypeChoice", "choose_body_type",
           "TrackShape", "track_shape", "NOISE_SCALE_RANGE"]

#: The noise scale is kept within this range: down to 1e-4 of the detector's nominal sigma (scores far below the
#: keypoints' precision; the sigmas themselves stay above ``min_pixel_sigma``; 1/30 until 2026-12-07), up to four
#: times it (a noisier detector; beyond that, keypoints at odds with each other are outliers, not noise).
NOISE_SCALE_RANGE = (1e-4, 4.0)

_CHI2_2_MEDIAN = 2.0 * np.log(2.0)  # median of a chi-square with 2 degrees of freedom


def _median(q: np.ndarray) -> float:
    """``np.median(q)`` of a short vector, to the bit, without its generic machinery (a tenth of the time)."""
    q = np.asarray(q, dtype=float).ravel()
    if not len(q) or not np.isfinite(q).all():
        return float(np.median(q))
    q, half = np.sort(q), len(q) // 2
    return float(q[half]) if len(q) % 2 else float((q[half - 1] + q[half]) / 2)


def median_scale(squared: np.ndarray) -> float:
    """``sqrt(median(q) / median chi2(2))`` of squared 2-vector residuals ``q`` (whitened): how many times their
    sigmas they are, robustly (up to half of them outliers)."""
    return float(np.sqrt(_median(squared) / _CHI2_2_MEDIAN))


@dataclass(frozen=True)
class Linearisation:
    """Dense Gauss-Newton Hessians of a one-vehicle graph at a solution, variables ``[pose (6), wheel, light, roof (36)]``.

    Each Hessian ``H`` comes with its information vector ``eta`` (minus the
    cost's gradient): the quadratic model is ``1/2 dx^T H dx - eta^T dx``.

    Attributes:
        total, total_eta: the whole graph.
        projection, projection_eta: the keypoint projection factor alone.
        prior, prior_eta: the shape prior factor alone.
        shape: (36,) the shape at the linearisation point (keypoint-major, metres).
        jacobian, rhs: the projection factor's whitened system ``A dx ~ b`` (2n rows;
            ``b`` is minus its residuals), for predicting the residuals of a step.
    """

    total: np.ndarray
    total_eta: np.ndarray
    projection: np.ndarray
    projection_eta: np.ndarray
    prior: np.ndarray
    prior_eta: np.ndarray
    shape: np.ndarray
    jacobian: np.ndarray | None = None
    rhs: np.ndarray | None = None


def linearise(graph: gtsam.NonlinearFactorGraph, projection: gtsam.NonlinearFactor, prior: gtsam.NonlinearFactor | None,
              values: gtsam.Values, keys: KeyScheme = KeyScheme(), vehicle: int = 0, frame: int = 0) -> Linearisation:
    """The graph's, the projection factor's and the shape prior's dense Hessians at ``values``.

    Args:
        graph: the one-frame graph of one vehicle.
        projection: its keypoint projection factor.
        prior: its shape prior factor (or an identical one); None: ``prior`` and ``prior_eta`` are zero.
        values: the solution.
    """
    layer_keys = keys.layer_keys(vehicle)

    def hessian(linear: gtsam.GaussianFactorGraph, variables):
        ordering = gtsam.Ordering()
        for key in variables:
            ordering.push_back(key)
        H, eta = linear.hessian(ordering)
        return H, np.ravel(eta)

    def alone(factor: gtsam.GaussianFactor) -> gtsam.GaussianFactorGraph:
        linear = gtsam.GaussianFactorGraph()
        linear.push_back(factor)
        return linear

    variables = [keys.pose_key(vehicle, frame), *layer_keys]
    H, eta = hessian(graph.linearize(values), variables)
    projection_linear = projection.linearize(values)  # once: its Hessian and its whitened system
    Hp, eta_p = hessian(alone(projection_linear), variables)
    A, b = projection_linear.jacobian()  # keys [pose, wheel, light, roof], as ``variables``
    Hs, eta_s = np.zeros((42, 42)), np.zeros(42)
    if prior is not None:
        Hs[6:, 6:], eta_s[6:] = hessian(alone(prior.linearize(values)), layer_keys)
    shape = np.concatenate([values.atVector(k) for k in layer_keys])
    return Linearisation(H, eta, Hp, eta_p, Hs, eta_s, shape, np.asarray(A), np.ravel(b))


def noise_scale(whitened: np.ndarray, lin: Linearisation, iterations: int = 8,
                groups: np.ndarray | None = None) -> tuple[float, float, np.ndarray | None]:
    """Robust scale of the whitened keypoint residuals, studentised by the fit's leverages: the solve's noise scale.

    With ``e_i`` the 2-vector whitened residuals at the current sigmas and
    ``M_i = A_i H(s)^-1 A_i^T / s^2`` observation i's 2x2 block of the hat
    matrix, ``s^2 = median(e_i^T (I - M_i)^-1 e_i) / median chi2(2)``: the
    studentised residuals are ``s^2 chi2(2)`` whatever each observation's
    leverage. ``p(s) = tr(H_proj(s) H(s)^-1) = sum tr(M_i)`` is the number of
    parameters the keypoints determine (6 for the pose plus the part of the
    shape the prior does not hold; ``H_proj(s) = H_proj / s^2``). The
    residuals are those of the solution the graph would reach with the
    sigmas times ``s``, predicted by one Gauss-Newton step from the
    linearisation (``e(s) = A dx(s) - b``, ``dx(s) = H(s)^-1 eta(s)``): a fit
    under the current sigmas, where the prior weighs more, overstates a small
    noise. ``s``, the leverages and the residuals are iterated to their fixed
    point. The median ignores outliers (up to half of the keypoints), and gross
    errors widen it, which keeps the solve's robust loss from locking onto
    one camera (the covariances use :func:`inlier_noise_scale`). Observations
    with a leverage above 0.95 are left out; without a Jacobian every
    observation takes the average share ``p / 2n`` (its residual divided by
    ``1 - p / 2n``). Clipped to :data:`NOISE_SCALE_RANGE`.

    Args:
        whitened: (n, 2) whitened residuals of the keypoints at the solution, current sigmas.
        lin: the linearisation at the solution (current sigmas).
        iterations: at most this many fixed-point iterations of ``s``, ``p`` and the
            residuals (they stop when ``s`` moves by less than 0.1 %).
        groups: (n,) each observation's camera: the cameras' noise is then compared too
            (:func:`camera_noise_factors`, from the last iteration's studentised residuals).

    Returns:
        (scale, p, factors): the noise scale (multiplies the sigmas), the effective
        number of parameters at that scale, and (n,) each observation's camera's own
        scale relative to it where the cameras' noise differs beyond chance (else None).

    Raises:
        numpy.linalg.LinAlgError: the residuals or the linearisation are not finite.
    """
    scale, p = 1.0, 0.0
    if not len(whitened):
        return scale, p, None
    fit = _ScaledFit(whitened, lin)
    for _ in range(iterations):
        previous = scale
        p, q, _ = fit.at(scale)
        if q is None:
            return scale, p, None
        scale = float(np.clip(np.sqrt(max(_median(q) / _CHI2_2_MEDIAN, 0.0)), *NOISE_SCALE_RANGE))
        if abs(scale - previous) <= 1e-3 * previous:
            break
    factors = None
    if groups is not None and fit.last is not None:  # the last fit's residuals, studentised at ``previous``
        factors = camera_noise_factors(*fit.last, groups, previous)
        factors = None if factors is None else factors * (previous / scale)
    return scale, p, factors


def inlier_noise_scale(whitened: np.ndarray, lin: Linearisation, iterations: int = 8) -> tuple[float, float, float]:
    """The inliers' noise scale, studentised by the fit's leverages, and its degrees of freedom: the covariances' scale.

    :func:`noise_scale` sets the balance of keypoints and prior for the
    solve: a median over every keypoint, which gross errors widen, and so a
    robust loss that does not lock onto one camera's keypoints. The
    covariances need the inliers' own noise, unbiased and with the number of
    degrees of freedom it rests on (:func:`covariance_inflation`): this. With ``e_i`` the 2-vector whitened residuals at the current sigmas and
    ``M_i = A_i H(s)^-1 A_i^T / s^2`` the observation's 2x2 block of the hat
    matrix (its leverage: how much of its own residual the fit absorbs;
    ``A`` the projection factor's whitened Jacobian without the robust loss,
    ``H(s) = H - H_proj + H_proj / s^2``), the studentised residuals
    ``q_i = e_i^T (I - M_i)^-1 e_i`` are ``s^2 chi2(2)`` for inliers whatever
    their leverage. The scale is then

    1. ``s0^2 = median(q) / median chi2(2)`` (ignores up to half of the keypoints as outliers),
    2. ``s^2 = mean(q_i : q_i < c s0^2) / E[chi2(2) | chi2(2) < c]``, ``c`` the 99 % point
       of chi2(2): the inliers' mean square, twice as efficient as the median,

    and its degrees of freedom ``nu = sum over those inliers of tr(I - M_i)``.
    The residuals are those of the solution the graph would reach with the
    sigmas times ``s``, predicted by one Gauss-Newton step from the
    linearisation (``e(s) = e + A dx(s)``, ``dx(s) = H(s)^-1 eta(s)``): a fit
    under the current sigmas, where the prior weighs more, overstates a small
    noise. ``s``, the leverages and the residuals are iterated to their fixed
    point. Observations the fit absorbs whole (leverage above 0.95) say
    nothing about the noise and are left out. Clipped to :data:`NOISE_SCALE_RANGE`.

    Args:
        whitened: (n, 2) whitened residuals of the keypoints at the solution, current sigmas,
            before the robust loss.
        lin: the linearisation at the solution (current sigmas) of the graph with its projection factor
            without the robust loss (least squares, as the covariances are; its ``jacobian`` and ``rhs``
            that factor's): a Hessian with the loss's down-weighting mispredicts the residuals at
            another scale.
        iterations: at most this many fixed-point iterations (they stop when ``s`` moves by
            less than 0.1 %).

    Returns:
        (scale, p, nu): the noise scale (multiplies the sigmas), the effective number of
        parameters at that scale (the hat matrix's trace, ``tr(H_proj(s) H(s)^-1)``) and
        the degrees of freedom of the scale's estimate (0 when nothing was left to estimate
        it from: the scale is then 1).

    Raises:
        numpy.linalg.LinAlgError: the residuals or the linearisation are not finite.
    """
    scale, p, nu = 1.0, 0.0, 0.0
    if not len(whitened):
        return scale, p, nu
    fit = _ScaledFit(whitened, lin)
    for _ in range(iterations):
        previous = scale
        p, q, freedom = fit.at(scale)
        if q is None:
            return 1.0, p, 0.0
        s0 = _median(q) / _CHI2_2_MEDIAN
        if not s0 > 0:
            return 1.0, p, 0.0
        inlier = q < _CHI2_2_99 * s0
        nu = float(freedom[inlier].sum())
        squared = float(np.mean(q[inlier])) / _CHI2_2_TRUNCATED_MEAN
        scale = float(np.clip(np.sqrt(squared), *NOISE_SCALE_RANGE))
        if abs(scale - previous) <= 1e-3 * previous:
            break
    return scale, p, nu


def camera_noise_factors(q: np.ndarray, freedom: np.ndarray, groups: np.ndarray, scale: float,
                         level: float = 0.999, min_ratio: float = 3.0,
                         min_freedom: float = 4.0) -> np.ndarray | None:
    """Each camera's noise scale relative to the pooled ``scale``, where the cameras' noise differs beyond chance;
    None where it does not (or cannot be told).

    A detector's confidences may be on another scale in one camera than in another (one camera's scores lower for
    keypoints as precise): one scale for all then weighs that camera too little and makes the other's keypoints
    too sharp (a user's audit, 2026-12-07: pose NEES 11-116 with one camera's scores at 0.1, where the same
    keypoints at full scores gave 1-18). With ``q_i`` the studentised squared residuals at ``scale``
    (:func:`noise_scale`'s), each camera ``c`` with inliers (``q_i`` below the 99 % point of its own median's
    ``s^2 chi2(2)``) has ``s_c^2 = mean(q_i) / E[chi2(2) | chi2(2) < 99 % point]`` on
    ``nu_c = sum tr(I - M_i)`` degrees of freedom; under one noise for all, ``s_c^2 / s_rest^2`` follows
    ``F(nu_c, nu_rest)``. Where some camera's ratio lies outside the two-sided ``level`` interval and its
    ``s_c / s_rest`` is beyond ``min_ratio`` (or below its inverse), every camera with at least ``min_freedom``
    degrees of freedom gets its own factor ``s_c / scale`` (the others 1). ``level`` and ``min_ratio`` were chosen
    on fresh ``library_2cam`` seeds 579-598 (the simulator's noise, the same in every camera): at 0.99 and no ratio
    the factors were applied to 1.5 % of the vehicles at paper-like noise and 6.3 % at hard noise (outliers that
    fall in one camera), which cost a little accuracy and consistency there (keypoints 15.11 -> 15.28 cm, pose
    under the chi2 bound 93.6 -> 92.7 %); at 0.999 and 2, 0.4 % and 2.3 %; at 0.999 and 3, 0.2 % and 1.4 %
    (15.15 cm, 93.4 %).

    Args:
        q, freedom: (n,) each observation's studentised squared residual at ``scale`` and its ``tr(I - M_i)``
            (NaN: not usable).
        groups: (n,) each observation's camera.
        scale: the pooled scale.

    Returns:
        (n,) each observation's camera's factor, or None.
    """
    q, freedom = np.asarray(q, float), np.asarray(freedom, float)
    cameras, group = np.unique(np.asarray(groups), return_inverse=True)
    if len(cameras) < 2:
        return None
    usable = np.isfinite(q) & np.isfinite(freedom)
    inlier = np.zeros(len(q), dtype=bool)
    for c in range(len(cameras)):  # each camera's inliers, by its own median
        rows = usable & (group == c)
        if rows.any():
            s0 = _median(q[rows]) / _CHI2_2_MEDIAN
            inlier |= rows & (q < _CHI2_2_99 * s0) if s0 > 0 else rows
    total = np.bincount(group[inlier], weights=q[inlier], minlength=len(cameras))
    count = np.bincount(group[inlier], minlength=len(cameras)).astype(float)
    nu = np.bincount(group[inlier], weights=freedom[inlier], minlength=len(cameras))
    seen = count > 0
    if seen.sum() < 2:
        return None
    differs = False
    for c in np.flatnonzero(seen):
        rest_total, rest_count, rest_nu = total.sum() - total[c], count.sum() - count[c], nu.sum() - nu[c]
        if min(nu[c], rest_nu) < min_freedom or not rest_total > 0:
            continue
        ratio = (total[c] / count[c]) / (rest_total / rest_count)
        if min_ratio ** -2 <= ratio <= min_ratio ** 2:
            continue  # within the factor: no F quantile needed (they cost 0.3 ms each in plain Python)
        high = max(f_quantile(nu[c], rest_nu, 0.5 + level / 2), min_ratio ** 2)
        low = min(1.0 / f_quantile(rest_nu, nu[c], 0.5 + level / 2), min_ratio ** -2)
        differs |= not low <= ratio <= high
    if not differs:
        return None
    own = np.flatnonzero(seen & (nu >= min_freedom) & (total > 0))
    if not len(own):
        return None
    factors = np.ones(len(q))
    for c in own:
        factors[group == c] = float(np.clip(np.sqrt(total[c] / count[c] / _CHI2_2_TRUNCATED_MEAN),
                                            *NOISE_SCALE_RANGE)) / scale
    return factors


#: Leverage (the larger eigenvalue of an observation's hat block) above which it says nothing about the noise.
_MAX_LEVERAGE = 0.95
_CHI2_2_99 = 2.0 * np.log(100.0)  # 99 % point of chi2(2)
_CHI2_2_TRUNCATED_MEAN = 2.0 - _CHI2_2_99 * 0.01 / 0.99  # E[chi2(2) | chi2(2) < its 99 % point]


def covariance_inflation(dof: float, dim: int = 6, level: float = 0.95) -> float:
    """What a covariance computed at an estimated noise scale is multiplied by, so that its confidence regions hold.

    With the scale estimated from ``nu`` degrees of freedom, a ``dim``-vector
    error's squared Mahalanobis norm at the estimated scale is ``dim F(dim, nu)``,
    not ``chi2(dim)``: heavier-tailed, most of all for few keypoints. The
    factor ``dim F_level(dim, nu) / chi2_level(dim)`` makes the covariance's
    ``chi2_level`` region the error's ``level`` region (by default the 95 %
    region of a pose); its mean squared norm is then ``nu / (nu - 2)`` times
    ``dim`` over that factor, about 0.9 ``dim`` (docs/factors.md). ``nu`` is
    taken as at least 3; 0 (no estimate) gives 1.
    """
    if not dof > 0:
        return 1.0
    return _f_over_chi2(dim, round(max(float(dof), 3.0), 1), level)


def sandwich_covariance(covariance: np.ndarray, jacobian: np.ndarray, rhs: np.ndarray,
                        min_freedom: float = 0.05) -> np.ndarray:
    """The robust (Huber-White) covariance of a least-squares solution: the spread its residuals say it has.

    With ``P = H^-1`` the graph's covariance (``H`` its Gauss-Newton
    Hessian), ``A_i`` the projection factor's whitened 2-row Jacobian block
    of observation ``i`` and ``e_i`` its whitened residual,

    ``C = P (H - A^T A + sum_i A_i^T r_i r_i^T A_i) P``,   ``r_i = (I - M_i)^-1/2 e_i``,   ``M_i = A_i P A_i^T``

    (the residuals corrected for the share of their own error the fit
    absorbs, "HC2"; the other factors, prior and bounds, enter by their
    model information). Where the residuals are as the sigmas say, ``C`` is
    ``P`` on average; where some keypoints are off by more than their
    sigmas (an accepted outlier, a detector whose errors are not of one
    size) it is wider in the directions they pull.

    Args:
        covariance: (m, m) ``H^-1``, the variables in the order of the Jacobian's columns.
        jacobian: (2n, m) the projection factor's whitened Jacobian (plain least squares), two rows per observation.
        rhs: (2n,) its right-hand side (minus the whitened residuals).
        min_freedom: ``I - M_i``'s eigenvalues are held above this (an observation the fit absorbs whole).

    Returns:
        (m, m) the sandwich covariance.
    """
    P = 0.5 * (covariance + covariance.T)
    A = np.asarray(jacobian, dtype=float).reshape(-1, 2, P.shape[0])
    e = -np.asarray(rhs, dtype=float).reshape(-1, 2)
    AP = A @ P  # (n, 2, m)
    M = AP @ A.transpose(0, 2, 1)
    w, V = np.linalg.eigh(np.eye(2) - M)
    r = np.einsum("nij,nj,nkj,nk->ni", V, np.maximum(w, min_freedom) ** -0.5, V, e)
    gP = np.einsum("nim,ni->nm", AP, r)  # (A_i^T r_i)^T P
    AP = AP.reshape(-1, P.shape[0])
    return P - AP.T @ AP + gP.T @ gP


def considered_covariance(covariance: np.ndarray, jacobian: np.ndarray, errors) -> np.ndarray:
    """The covariance a least-squares solution takes from errors it does not estimate ("consider" parameters).

    An error ``d`` (covariance ``V``) moves some of the whitened residuals by ``D d``; the solution moves by
    ``G d``, ``G = P A_d^T D`` (``P = H^-1`` the solution's covariance, ``A_d`` the whitened Jacobian's rows of
    those residuals), so that independent errors give

    ``C = sum_d G_d V_d G_d^T``.

    The one-frame solve's detector errors shaped like a change of shape and cameras' extrinsic errors
    (:func:`vfactor.solve.detector_shape_covariance`, :func:`vfactor.extrinsics.extrinsic_covariance`) and a
    track pose's cameras' errors and detector offsets (:func:`vfactor.extrinsics.extrinsic_pose_covariance`,
    ``vfactor.track._considered_offsets``) are this.

    Args:
        covariance: (m, m) ``P``, the variables in the order of the Jacobian's columns.
        jacobian: (r, m) the whitened Jacobian of the residuals the errors move.
        errors: (rows, derivative, variance) per error: a boolean mask of the Jacobian's rows it moves, their
            (k_rows, k) derivative ``D`` by it, and its (k,) variances or (k, k) covariance ``V``.

    Returns:
        (m, m) ``C``, symmetric.
    """
    A = np.asarray(jacobian, dtype=float)
    out = np.zeros((A.shape[1], A.shape[1]))
    for rows, derivative, variance in errors:
        G = covariance @ (A[rows].T @ derivative)
        out += G @ (np.diag(variance) if np.ndim(variance) == 1 else variance) @ G.T
    return 0.5 * (out + out.T)

#: A solved shape further from its prior than this quantile of chi2(p) (p: the shape parameters the keypoints
#: determine) is taken as one the prior does not describe (:func:`prior_misfit_covariance`).
PRIOR_MISFIT_LEVEL = 0.95


def prior_misfit_covariance(covariance: np.ndarray, prior, weight: float, vehicle_p_keypoints: np.ndarray,
                            shape_parameters: float, references=(),
                            level: float = PRIOR_MISFIT_LEVEL) -> tuple[np.ndarray, float]:
    """The covariance a solution takes from a shape prior that does not describe the vehicle, and the excess.

    The posterior covariance holds where the vehicle is drawn from the prior. A
    vehicle unlike those the prior was learnt from (a shape of another design,
    keypoints placed by another convention) is pulled towards the prior's mean
    by more than its covariance says: the prior's mean error, read as a
    consider parameter with covariance ``a^2 Sigma_prior``, moves the prior's
    whitened residuals by ``-R d`` and the solution by ``G d``,
    ``G = -P[:, shape] R^T R`` (:func:`considered_covariance`). ``a^2`` is read
    off the solution: with the vehicle drawn from a body type's prior, the
    solved shape's squared Mahalanobis distance ``d^2`` from that prior's mean
    is about ``chi2(p)`` (``p`` the shape parameters the keypoints determine,
    the hat matrix's trace less the pose's 6; the prior keeps the others at its
    mean), so ``a^2 = max(0, min_k d_k^2 / chi2_level(p) - 1)`` over the
    ``references`` (a shape model's body types; none given: the prior itself):
    nothing for a shape within some type's ``level`` region, the excess beyond
    the nearest one otherwise (docs/factors.md, "Covariances", item 8). The
    graph's prior, the types' priors moment-matched into one, is wider than
    any of them between types; a shape between two types is one the model
    describes.

    Args:
        covariance: (42, 42) ``P``, the solution's covariance of pose (6) and shape (36, the layers' keypoints in
            the keypoint order).
        prior: the :class:`~vfactor.shape_model.ShapePrior` of the graph, with ``weight`` multiplying its
            information: what pulls the solution.
        vehicle_p_keypoints: (12, 3) the solved shape, metres.
        shape_parameters: ``p``; below 1, 1.
        references: the priors whose regions describe the vehicles the model knows (each body type's own).
        level: the quantile of ``chi2(p)`` within which a prior is taken to describe the vehicle.

    Returns:
        ((42, 42) the covariance to add, zero within the region; ``a^2``).
    """
    shape = np.asarray(vehicle_p_keypoints, dtype=float).ravel()
    nearest = min(float(np.sum((reference.sqrt_information() @ (shape - np.asarray(reference.mean).ravel())) ** 2))
                  for reference in (references or (prior,)))
    excess = nearest / chi2_quantile(round(max(float(shape_parameters), 1.0), 1), level) - 1.0
    if not excess > 0:
        return np.zeros((42, 42)), 0.0
    R = prior.sqrt_information() * math.sqrt(weight)
    jacobian = np.zeros((36, 42))
    jacobian[:, 6:] = R
    every = np.ones(36, dtype=bool)
    sigma = np.asarray(prior.covariance, dtype=float) / weight  # the prior's covariance in the graph
    return considered_covariance(covariance, jacobian, [(every, -R, excess * sigma)]), excess


def covariance_upper_bound(model: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, float]:
    """A covariance at least as wide as both ``model`` and ``other`` (in the Loewner order), the least such in ``model``'s
    whitened frame.

    ``C = L W L^T`` with ``model = L L^T`` and ``W`` the eigen-decomposition of
    ``L^-1 other L^-T`` with its eigenvalues raised to at least 1: ``model``
    where ``other`` is narrower, ``other`` along the directions where it is wider.

    Returns:
        (C, widening): ``widening`` is the largest eigenvalue ratio of ``other`` to ``model`` (above 1: ``C``
        is wider than ``model``).

    Raises:
        numpy.linalg.LinAlgError: ``model`` is not positive definite.
    """
    L = np.linalg.cholesky(0.5 * (model + model.T))
    L_inv = np.linalg.inv(L)
    w, V = symmetric_eigen(L_inv @ (0.5 * (other + other.T)) @ L_inv.T)
    LV = L @ V
    return (LV * np.maximum(w, 1.0)) @ LV.T, float(w.max())


def symmetric_eigen(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``numpy.linalg.eigh`` of a symmetric matrix (its lower triangle), computed single-threaded
    (:func:`vfactor._kernels.symmetric_eigen_kernel`): on a machine whose cores are busy, the multi-threaded BLAS
    under NumPy's LAPACK made a 42 x 42 ``eigh`` several times slower than alone (docs/performance.md).

    Returns:
        (w, V): the eigenvalues ascending, and the orthonormal eigenvectors as columns.

    Raises:
        numpy.linalg.LinAlgError: the iteration did not converge (a matrix with NaN or infinite entries).
    """
    A = np.asarray(A, dtype=float)
    w, V = np.empty(A.shape[0]), np.empty(A.shape)
    if not np.all(np.isfinite(A)) or symmetric_eigen_kernel(A, w, V) != 0:
        raise np.linalg.LinAlgError("symmetric_eigen: the eigenvalues did not converge")
    return w, V


@lru_cache(maxsize=1024)
def _f_over_chi2(dim: int, nu: float, level: float) -> float:
    # vfactor.stats, not scipy.special (a 0.3 s import that a fresh process's first solve would pay)
    return dim * f_quantile(dim, nu, level) / chi2_quantile(dim, level)


class _ScaledFit:
    """What the fit would be with every sigma times ``s``: ``p`` and the studentised residuals of the usable observations.

    ``H(s) = H - H_proj + H_proj / s^2``; ``p = tr(H_proj(s) H(s)^-1)``; the
    residuals are predicted by one Gauss-Newton step, ``e(s) = A dx(s) - b``
    with ``dx(s) = H(s)^-1 eta(s)``, and the leverages are
    ``M_i = A_i H(s)^-1 A_i^T / s^2``; the studentised squared residuals are
    ``q_i = e_i^T (I - M_i)^-1 e_i``. Observations the fit absorbs whole
    (leverage, the larger eigenvalue of ``M_i``, above :data:`_MAX_LEVERAGE`) are
    left out. Without the whitened system (``lin.jacobian``) the residuals stay
    ``whitened`` and every observation takes an equal share ``p / 2n`` of the
    parameters. Each scale is one call of the compiled
    :func:`kernels.shape_evidence.fit_at_scale_kernel`; the inputs are
    checked and laid out once.

    Raises:
        numpy.linalg.LinAlgError: the residuals or the linearisation are not finite, or ``H(s)`` is not
            positive definite.
    """

    def __init__(self, whitened: np.ndarray, lin: Linearisation):
        if not (np.all(np.isfinite(whitened)) and np.all(np.isfinite(lin.total)) and np.all(np.isfinite(lin.projection))):
            raise np.linalg.LinAlgError("the residuals or the linearisation are not finite")
        self.whitened = np.asarray(whitened, dtype=float)
        self.last = None  # (q, tr(I - M_i)) of every observation at the last scale evaluated
        n = len(whitened)
        self.has_system = lin.jacobian is not None and lin.jacobian.shape[0] == 2 * n
        m = len(lin.total)
        self.arrays = tuple(np.ascontiguousarray(x, dtype=float) for x in (
            lin.total, lin.projection, lin.total_eta, lin.projection_eta,
            lin.jacobian if self.has_system else np.empty((0, m)), lin.rhs if self.has_system else np.empty(0)))

    def at(self, scale: float) -> tuple[float, np.ndarray | None, np.ndarray | None]:
        """(p, q (usable,), tr(I - M_i) (usable,)) with every sigma times ``scale``; q and the traces are None when
        no observation is usable."""
        n = len(self.whitened)
        q, freedom = np.empty(n), np.empty(n)
        p = fit_at_scale_kernel(*self.arrays, 1.0 / scale**2, _MAX_LEVERAGE, q, freedom)
        if not np.isfinite(p):
            raise np.linalg.LinAlgError("the Hessian at this noise scale is not positive definite")
        self.last = (q, freedom) if self.has_system else None  # every observation's (NaN: not usable), last scale
        if not self.has_system:  # an equal share of the parameters for every observation
            leverage = min(p / (2.0 * n), 0.95)
            if not leverage < _MAX_LEVERAGE:
                return p, None, None
            return p, np.sum(self.whitened**2, axis=1) / (1.0 - leverage), np.full(n, 2.0 * (1.0 - leverage))
        usable = np.isfinite(q)
        if not usable.any():
            return p, None, None
        return p, q[usable], freedom[usable]


def shape_information(lin: Linearisation, projection_factor: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The observations' Gaussian on the shape: pose marginalised out, the shape prior removed.

    The graph's quadratic model around the solution ``x0`` is
    ``1/2 dx^T H dx - eta^T dx``. The shape prior's part is removed, the
    projection factor's part scaled by ``projection_factor`` (``1 / s^2`` for a
    new noise scale), and the pose eliminated by its Schur complement. In the
    absolute shape coordinates ``x = x0 + dx`` the result is
    ``exp(-x^T Lambda x / 2 + (eta + Lambda x0)^T x)``.

    Returns:
        (Lambda (36, 36), information vector (36,)) for
        :meth:`ShapeModel.type_log_evidence`.
    """
    H = lin.total - lin.prior + (projection_factor - 1.0) * lin.projection
    eta = lin.total_eta - lin.prior_eta + (projection_factor - 1.0) * lin.projection_eta
    Hpp, Hps, Hss = H[:6, :6], H[:6, 6:], H[6:, 6:]
    K = np.linalg.solve(Hpp, Hps)
    Lam = Hss - Hps.T @ K
    Lam = 0.5 * (Lam + Lam.T)
    eta_s = eta[6:] - K.T @ eta[:6]
    return Lam, eta_s + Lam @ lin.shape


@dataclass(frozen=True)
class BodyTypeChoice:
    """The body type (and prior spread) a vehicle's observations choose.

    Attributes:
        body_type: the type of highest posterior probability.
        spread: the covariance multiplier of highest evidence for that type.
        probability: the type's posterior probability (over its spreads).
        posterior: body type -> posterior probability.
        prior: the prior to solve with: the moment-matched mixture of the
            components under their posterior probabilities (those above 0.1 %),
            which is ``model.prior(body_type, spread)`` itself for a clear choice.
        untyped: posterior probability of the pooled prior (the vehicle of none of the types).
    """

    body_type: str
    spread: float
    probability: float
    posterior: dict
    prior: ShapePrior
    untyped: float = 0.0


def choose_body_type(model: ShapeModel, information: np.ndarray, eta: np.ndarray, hints=()) -> BodyTypeChoice:
    """The body type of highest posterior probability, its prior spread, every type's probability, and the prior to use.

    ``p(c | z) ~ p(z | c) p(c | hints)`` over the model's components ``c``
    (:meth:`ShapeModel.components`: each type at each spread, and the pooled
    prior): the Laplace evidence of :meth:`ShapeModel.type_log_evidence`
    times the prior of :meth:`ShapeModel.log_prior`, split evenly over a type's
    spreads, with :attr:`ShapeModel.pooled_probability` on the pooled prior. A
    type's probability sums over its spreads and is reported among the types
    (conditional on the vehicle being of one); the prior to solve with is the
    moment-matched mixture of all components.

    Raises:
        numpy.linalg.LinAlgError: the evidence is not finite (the solver then keeps its first solve).
    """
    log_evidence = model.type_log_evidence(information, eta)
    if not all(np.isfinite(v) for v in log_evidence.values()):
        raise np.linalg.LinAlgError("the body types' evidence is not finite (the linearisation overflowed)")
    log_prior = model.log_prior(hints)
    share = np.log(1.0 - model.pooled_probability) - np.log(len(model.spreads))
    log_post = {key: value + (np.log(model.pooled_probability) if key[0] == ANY else log_prior[key[0]] + share)
                for key, value in log_evidence.items()}
    top = max(log_post.values())
    weights = {key: float(np.exp(v - top)) for key, v in log_post.items()}
    total = sum(weights.values())
    typed = sum(w for (t, _), w in weights.items() if t != ANY)
    posterior = {t: 0.0 for t in model.types}
    for (t, _), w in weights.items():
        if t != ANY:
            posterior[t] += w / typed
    body_type = max(posterior, key=posterior.get)
    spread = max((k for t, k in weights if t == body_type), key=lambda k: weights[(body_type, k)])
    return BodyTypeChoice(body_type, float(spread), posterior[body_type], posterior,
                          _moment_matched(model, {key: w / total for key, w in weights.items()}),
                          weights.get((ANY, 1.0), 0.0) / total)


def _moment_matched(model: ShapeModel, weights: dict, negligible: float = 1e-3) -> ShapePrior:
    """The Gaussian with the mean and covariance of the mixture of the (type, spread) priors under ``weights``.

    ``mu = sum w_k mu_k``, ``Sigma = sum w_k (Sigma_k + (mu_k - mu)(mu_k - mu)^T)``: when the
    observations leave the type uncertain the prior widens over the types they allow instead
    of committing to one; a clear choice gives that type's prior itself. Its hub height is the
    weighted mean of theirs (None where one has none).
    """
    kept = {key: w for key, w in weights.items() if w >= negligible}
    if len(kept) == 1:
        return model.prior(*next(iter(kept)))
    total = sum(kept.values())
    priors = {key: model.prior(*key) for key in kept}
    mean = sum(w * np.asarray(priors[key].mean).ravel() for key, w in kept.items()) / total
    cov = np.zeros((36, 36))
    for key, w in kept.items():
        d = np.asarray(priors[key].mean).ravel() - mean
        cov += w / total * (priors[key].covariance + np.outer(d, d))
    heights = [priors[key].hub_height for key in kept]  # the wheel radius: the mixture's mean where all give one
    hub_height = None if None in heights else sum(w * h for w, h in zip(kept.values(), heights)) / total
    return ShapePrior.trusted(mean, 0.5 * (cov + cov.T), hub_height)


def _kind_weights(results, model: ShapeModel | None) -> dict[bool, float]:
    """Of the one-frame solves ``results`` that chose a body type, per kind (True: a type far from the model's
    pooled prior, :meth:`~vfactor.shape_model.ShapeModel.far_from_pooled`, a bus; False: one near it) the sum of
    their choices' probabilities; only the kinds chosen are keys."""
    weights: dict[bool, float] = {}
    for r in results:
        if model is not None and r is not None and r.ok and r.body_type:
            far = model.far_from_pooled(r.body_type)
            weights[far] = weights.get(far, 0.0) + (r.body_type_probability or 0.0)
    return weights


def mixed_kinds(results, model: ShapeModel | None) -> bool:
    """Whether some of ``results`` (one-frame solves of one vehicle) chose a body type far from the model's pooled
    prior (a bus) and others a type near it."""
    return len(_kind_weights(results, model)) == 2


def heavier_kind(results, model: ShapeModel) -> bool:
    """Whether the one-frame solves of ``results`` that chose a type far from the model's pooled prior (a bus) have
    probabilities adding up to more than those of the ones that chose a type near it."""
    weights = _kind_weights(results, model)
    return weights.get(True, 0.0) > weights.get(False, 0.0)


@dataclass(frozen=True)
class TrackShape:
    """The shape prior and noise scale of a track (or of any vehicle seen in several frames).

    Attributes:
        prior: the shape prior for the track's shared shape.
        noise_scale: multiplies the detections' pixel sigmas in every frame.
        body_type: the chosen body type, or None (no model, or no frame solved).
        probability: its posterior probability, or None.
    """

    prior: ShapePrior
    noise_scale: float = 1.0
    body_type: str | None = None
    probability: float | None = None


def track_shape(results, model: ShapeModel | None, fallback: ShapePrior | None = None,
                far: bool | None = None, hints=()) -> TrackShape:
    """The prior and noise scale of a vehicle seen in several frames, from its one-frame solves.

    The frames share one shape, so the observations' Gaussians on it
    (``extras["shape_information"]`` of each result of
    :func:`vfactor.solve.solve_observations`) add up, and the body type is
    chosen from their sum; the noise scale is the median of the frames'.
    Where some frames' solves chose a type far from the model's pooled prior
    (:meth:`~vfactor.shape_model.ShapeModel.far_from_pooled`: a bus) and others
    a type near it, only the frames of the kind whose choices' probabilities add
    up to more count: each Gaussian is linearised at its own frame's solution,
    and a bus taken for a smaller vehicle along the cameras' rays, metres off,
    gives one of a car (``library_bus_tracks_2cam`` seeds 1-2: such frames
    outweighed the buses' and the tracks were reported vans; the tracker
    also solves a young track of both kinds as each, ``Tracker._solved_as``).
    :func:`vfactor.track.smooth_scene`, the tracker (over a young track's
    frames) and a graph of your own (examples/infrastructure_graph.py) use it.

    Args:
        results: one-frame results of the vehicle (unsolved ones are skipped), solved with
            ``SolveOptions(shape_information=True)``.
        model: the shape model, or None to keep ``fallback``.
        fallback: the prior without a model or without a solved frame
            (default: the model's pooled prior).
        far: where the frames are of both kinds (:func:`mixed_kinds`), count only those far from the pooled
            prior (True) or near it (False); None: the kind whose choices' probabilities add up to more.
        hints: the 2D detector's classes of the vehicle's detections (:func:`vfactor.observations.class_hints`),
            weighing the body types once for the whole track, as for one frame (:func:`choose_body_type`).
    """
    solved = [r for r in results if r is not None and r.ok]
    fallback = fallback if fallback is not None else (model.pooled if model is not None else None)
    if not solved:
        return TrackShape(fallback)
    if mixed_kinds(solved, model):  # frames of one kind: far from the pooled prior (a bus) or near it
        far = heavier_kind(solved, model) if far is None else far
        solved = [r for r in solved if model.far_from_pooled(r.body_type) == far]
    scale = float(np.median([r.extras.get("noise_scale", 1.0) for r in solved]))
    informations = [r.extras["shape_information"] for r in solved if "shape_information" in r.extras]
    if model is None or not informations:
        return TrackShape(fallback, scale)
    choice = choose_body_type(model, sum(a for a, _ in informations), sum(b for _, b in informations), hints)
    return TrackShape(choice.prior, scale, choice.body_type, choice.probability)
