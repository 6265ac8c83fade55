"""The keypoint projection factor's kernel (numba source, compiled ahead of time into :mod:`vfactor._kernels`).

The projection factor is the one factor of the default graph that runs in
Python; linearised per LM iteration, its NumPy form cost about 90 us for 24
observations, more than GTSAM's whole native iteration. This kernel computes
the same residuals and Jacobians in one compiled loop (a few microseconds), so
only the ~10 us of the ``CustomFactor`` call itself remain (docs/performance.md).

The maths is that of :mod:`vfactor.factors.projection` (docs/factors.md):
projection with every lens model as :func:`vfactor.camera.project_pinhole`
(the common lens, at most ``[k1, k2, p1, p2, k3]``, inline; the rational,
thin-prism, tilted and fisheye lenses in :func:`_full_lens` and
:func:`_fisheye_lens`),
whitening by ``L``, and the robust loss of :mod:`vfactor.factors.robust` as
``r = s(n) e``; the tests check it against those NumPy implementations and
against numerical derivatives.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from kernels.robust import robust_scale
from kernels.truncation import truncated_mean

__all__ = ["projection_kernel", "robust_cost_kernel"]

#: Lens codes of the ``lens`` table (:meth:`vfactor.camera.Camera.kernel_lens`).
_PLAIN, _FULL, _FISHEYE = 0, 1, 2
#: Below this squared normalised radius the fisheye scale is its limit 1 (as in vfactor.camera).
_FISHEYE_MIN_R2 = 1e-16


@njit
def _full_lens(d, x, y):
    """OpenCV's pinhole distortion with all 14 coefficients: ``(xd, yd, d00, d01, d10, d11)``.

    ``d00 .. d11``: ``d(xd, yd) / d(x, y)`` row by row (vfactor.camera._pinhole_lens).
    """
    k1, k2, p1, p2, k3, k4, k5, k6 = d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]
    s1, s2, s3, s4 = d[8], d[9], d[10], d[11]
    r2 = x * x + y * y
    numerator = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    denominator = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    radial = numerator / denominator
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + r2 * s2)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y + r2 * (s3 + r2 * s4)
    dradial = (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2) - radial * (k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2))) / denominator
    gx = 2.0 * (s1 + 2.0 * s2 * r2)
    gy = 2.0 * (s3 + 2.0 * s4 * r2)
    d00 = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x + gx * x
    d01 = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y + gx * y
    d10 = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y + gy * x
    d11 = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x + gy * y
    if d[12] == 0.0 and d[13] == 0.0:
        return xd, yd, d00, d01, d10, d11
    # tilted sensor (vfactor.camera.tilt_matrix): M = [[R22, 0, -R02], [0, R22, -R12], [0, 0, 1]] R
    cx, sx, cy, sy = math.cos(d[12]), math.sin(d[12]), math.cos(d[13]), math.sin(d[13])
    r02, r12, r22 = -sy * cx, sx, cy * cx
    m00, m01, m02 = r22 * cy - r02 * sy, r22 * sy * sx + r02 * cy * sx, -r22 * sy * cx - r02 * cy * cx
    m10, m11, m12 = -r12 * sy, r22 * cx + r12 * cy * sx, r22 * sx - r12 * cy * cx
    m20, m21, m22 = sy, -cy * sx, cy * cx
    w = m20 * xd + m21 * yd + m22
    xt = (m00 * xd + m01 * yd + m02) / w
    yt = (m10 * xd + m11 * yd + m12) / w
    t00, t01 = (m00 - xt * m20) / w, (m01 - xt * m21) / w
    t10, t11 = (m10 - yt * m20) / w, (m11 - yt * m21) / w
    return (xt, yt, t00 * d00 + t01 * d10, t00 * d01 + t01 * d11, t10 * d00 + t11 * d10, t10 * d01 + t11 * d11)


@njit
def _fisheye_lens(d, x, y):
    """OpenCV's equidistant fisheye model: ``(xd, yd, d00, d01, d10, d11)`` (vfactor.camera._fisheye_lens)."""
    k1, k2, k3, k4 = d[0], d[1], d[2], d[3]
    r2 = x * x + y * y
    if r2 < _FISHEYE_MIN_R2:
        h = 2.0 * (k1 - 1.0 / 3.0)
        return x, y, 1.0 + h * x * x, h * x * y, h * x * y, 1.0 + h * y * y
    r = math.sqrt(r2)
    theta = math.atan(r)
    t2 = theta * theta
    g = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) / r
    dtheta_d = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
    h = (dtheta_d / (1.0 + r2) - g) / r2
    return g * x, g * y, g + h * x * x, h * x * y, h * x * y, g + h * y * y


@njit
def projection_kernel(R, t, points, keypoint_index, R_cw, t_cw, intrinsics, lens, dist, uv, L, window, sigma, loss_id,
                      k, min_depth, want_jacobians, r_out, H_pose, H_shape):
    """Fills the robust whitened residuals and, if asked, the Jacobians of every observation.

    Args:
        R, t: rotation (3, 3) and translation (3,) of ``world_T_vehicle``.
        points: (12, 3) body-frame keypoints.
        keypoint_index: (n,) keypoint of each observation.
        R_cw, t_cw: (n, 3, 3), (n, 3) world -> camera of each observation's camera.
        intrinsics: (n, 5) ``fx, fy, skew, cx, cy``.
        lens: (n,) lens code of each observation's camera (0: at most ``k1, k2, p1, p2, k3``;
            1: all 14 pinhole coefficients; 2: fisheye), :meth:`vfactor.camera.Camera.kernel_lens`.
        dist: (n, 14) ``k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4, tauX, tauY``
            (fisheye: ``k1, k2, k3, k4``, then zeros).
        uv: (n, 2) measured pixels.
        L: (n, 2, 2) square-root information.
        window: (n, 4) ``[u_lo, v_lo, u_hi, v_hi]`` truncation window; NaN rows: none.
        sigma: (n, 2) marginal pixel sigmas (used with a window).
        loss_id, k: robust loss (:attr:`RobustLoss.id`) and its threshold.
        min_depth: depth clamp, metres.
        want_jacobians: whether to fill ``H_pose`` and ``H_shape``.
        r_out: (2n,) residuals, written.
        H_pose: (2n, 6) d r / d xi (right perturbation, rotation first), written.
        H_shape: (2n, 36) d r / d body points, written (must be zero on entry).
    """
    n = keypoint_index.shape[0]
    for i in range(n):
        kp = keypoint_index[i]
        p0, p1, p2 = points[kp, 0], points[kp, 1], points[kp, 2]
        # world point, then camera point
        w = np.empty(3)
        for a in range(3):
            w[a] = R[a, 0] * p0 + R[a, 1] * p1 + R[a, 2] * p2 + t[a]
        c = np.empty(3)
        for a in range(3):
            c[a] = R_cw[i, a, 0] * w[0] + R_cw[i, a, 1] * w[1] + R_cw[i, a, 2] * w[2] + t_cw[i, a]
        clamped = c[2] < min_depth
        Z = min_depth if clamped else c[2]
        inv_z = 1.0 / Z
        x, y = c[0] * inv_z, c[1] * inv_z
        fx, fy, skew, cx, cy = intrinsics[i, 0], intrinsics[i, 1], intrinsics[i, 2], intrinsics[i, 3], intrinsics[i, 4]
        code = lens[i]
        d00, d01, d10, d11 = 1.0, 0.0, 0.0, 1.0
        if code == _PLAIN:
            k1, k2, q1, q2, k3 = dist[i, 0], dist[i, 1], dist[i, 2], dist[i, 3], dist[i, 4]
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd = x * radial + 2.0 * q1 * x * y + q2 * (r2 + 2.0 * x * x)
            yd = y * radial + q1 * (r2 + 2.0 * y * y) + 2.0 * q2 * x * y
        elif code == _FULL:
            xd, yd, d00, d01, d10, d11 = _full_lens(dist[i], x, y)
        else:
            xd, yd, d00, d01, d10, d11 = _fisheye_lens(dist[i], x, y)
        mu_u = fx * xd + skew * yd + cx
        mu_v = fy * yd + cy
        slope_u, slope_v = 1.0, 1.0
        if not math.isnan(window[i, 0]):  # truncated at the window: compare with the kept measurements' mean
            mu_u, slope_u = truncated_mean(mu_u, sigma[i, 0], window[i, 0], window[i, 2])
            mu_v, slope_v = truncated_mean(mu_v, sigma[i, 1], window[i, 1], window[i, 3])
        du = mu_u - uv[i, 0]
        dv = mu_v - uv[i, 1]
        e0 = L[i, 0, 0] * du + L[i, 0, 1] * dv
        e1 = L[i, 1, 0] * du + L[i, 1, 1] * dv
        norm = math.sqrt(e0 * e0 + e1 * e1)
        s, ds = robust_scale(loss_id, k, norm)
        r_out[2 * i] = s * e0
        r_out[2 * i + 1] = s * e1
        if not want_jacobians:
            continue
        # d uv / d camera point
        if code == _PLAIN:
            dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
            d00 = radial + 2.0 * x * x * dradial + 2.0 * q1 * y + 6.0 * q2 * x
            d01 = 2.0 * x * y * dradial + 2.0 * q1 * x + 2.0 * q2 * y
            d10 = d01
            d11 = radial + 2.0 * y * y * dradial + 6.0 * q1 * y + 2.0 * q2 * x
        a00 = (fx * d00 + skew * d10) * slope_u
        a01 = (fx * d01 + skew * d11) * slope_u
        a10 = fy * d10 * slope_v
        a11 = fy * d11 * slope_v
        J = np.empty((2, 3))
        J[0, 0] = a00 * inv_z
        J[0, 1] = a01 * inv_z
        J[1, 0] = a10 * inv_z
        J[1, 1] = a11 * inv_z
        if clamped:
            J[0, 2] = 0.0
            J[1, 2] = 0.0
        else:
            J[0, 2] = -(a00 * x + a01 * y) * inv_z
            J[1, 2] = -(a10 * x + a11 * y) * inv_z
        # DL = s L + (s'/n) e (e^T L)
        eL0 = e0 * L[i, 0, 0] + e1 * L[i, 1, 0]
        eL1 = e0 * L[i, 0, 1] + e1 * L[i, 1, 1]
        DL = np.empty((2, 2))
        DL[0, 0] = s * L[i, 0, 0] + ds * e0 * eL0
        DL[0, 1] = s * L[i, 0, 1] + ds * e0 * eL1
        DL[1, 0] = s * L[i, 1, 0] + ds * e1 * eL0
        DL[1, 1] = s * L[i, 1, 1] + ds * e1 * eL1
        # M = R_cw R (camera <- body rotation); Jp = DL J M
        DJ = np.empty((2, 3))
        for a in range(2):
            for b in range(3):
                DJ[a, b] = DL[a, 0] * J[0, b] + DL[a, 1] * J[1, b]
        for a in range(2):
            row = 2 * i + a
            g = np.empty(3)  # DJ[a] @ R_cw
            for b in range(3):
                g[b] = DJ[a, 0] * R_cw[i, 0, b] + DJ[a, 1] * R_cw[i, 1, b] + DJ[a, 2] * R_cw[i, 2, b]
            jp = np.empty(3)  # g @ R: d r / d body point
            for b in range(3):
                jp[b] = g[0] * R[0, b] + g[1] * R[1, b] + g[2] * R[2, b]
            # d r / d xi = [p x jp, jp]
            H_pose[row, 0] = p1 * jp[2] - p2 * jp[1]
            H_pose[row, 1] = p2 * jp[0] - p0 * jp[2]
            H_pose[row, 2] = p0 * jp[1] - p1 * jp[0]
            H_pose[row, 3] = jp[0]
            H_pose[row, 4] = jp[1]
            H_pose[row, 5] = jp[2]
            for b in range(3):
                H_shape[row, 3 * kp + b] = jp[b]


@njit
def robust_cost_kernel(R, t, points, keypoint_index, R_cw, t_cw, intrinsics, lens, dist, uv, L, window, sigma, loss_id, k,
                       min_depth, costs):
    """Robust costs ``sum_i rho(|e_i|)`` of the observations at several poses and shapes, in one compiled pass.

    Each is ``1/2 |r|^2`` of :func:`projection_kernel`'s residuals (``r = s(n) e`` with
    ``1/2 s(n)^2 n^2 = rho(n)``), e.g. every initial candidate of a vehicle scored at once.

    Args:
        R, t: (K, 3, 3) rotations and (K, 3) translations of the ``world_T_vehicle`` to score.
        points: (K, 12, 3) body-frame keypoints of each, metres.
        keypoint_index .. min_depth: as for :func:`projection_kernel`.
        costs: (K,) the robust costs, written.
    """
    n = keypoint_index.shape[0]
    r = np.empty(2 * n)
    unused = np.empty((0, 0))
    for c in range(R.shape[0]):
        projection_kernel(R[c], t[c], points[c], keypoint_index, R_cw, t_cw, intrinsics, lens, dist, uv, L, window, sigma,
                          loss_id, k, min_depth, False, r, unused, unused)
        total = 0.0
        for j in range(2 * n):
            total += r[j] * r[j]
        costs[c] = 0.5 * total
