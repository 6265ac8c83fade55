"""The motion factors' kernels: Pose3 between, Logmap and their Jacobians (numba source, compiled ahead of time
into :mod:`vfactor._kernels`).

The non-holonomic and acceleration factors of :mod:`vfactor.factors.motion`
are linearised once per pose (twice for the acceleration factor's two steps)
per iSAM2 update. Written with GTSAM's Python ``Pose3.between`` and
``Pose3.Logmap`` and NumPy they cost 16-24 us a linearisation, 28 % of the
fixed-lag tracking time (docs/performance.md). These kernels compute the same
residuals and Jacobians in one compiled call that fills the factor's output
arrays (7-8 us a linearisation), so that mostly the ``CustomFactor`` call
itself remains, as for the projection factor
(:mod:`kernels.projection`).

The maths is GTSAM's (``Pose3::between``, ``Pose3::Logmap``,
``Pose3::LogmapDerivative``; docs/factors.md), with ``k(theta) = 1/theta^2 -
1 / (2 theta tan(theta / 2))``:

* ``between``: ``T12 = T1^-1 T2 = (R1^T R2, R1^T (t2 - t1))``, with the
  Jacobians (right perturbation ``T Exp(xi)``, rotation first)
  ``H1 = -Ad(T12^-1) = [[-R12^T, 0], [R12^T [t12]x, -R12^T]]`` and ``H2 = I``;
* ``Logmap``: ``w = Log(R12) = theta / (2 sin theta) vee(R12 - R12^T)`` (the
  Taylor series near the identity; near ``theta = pi`` the axis from the
  symmetric part of ``R12``), and ``rho = t12 - [w]x t12 / 2 + k [w]x^2 t12``;
* ``LogmapDerivative``: ``[[Jw, 0], [-Jw Q Jw, Jw]]`` with
  ``Jw = I + [w]x / 2 + k [w]x^2`` and ``Q`` Barfoot's (TRO 2014, eq. 102).

Below ``theta = 1e-2`` rad the coefficients are their Taylor series (the
closed forms cancel to noise there; GTSAM 4.3 agrees to 1e-11). Near
``theta = pi`` the kernel is exact where GTSAM 4.3's Logmap is off by up to
1e-7; consecutive poses of a car are never there.

Poses come in as 4x4 homogeneous matrices ``world_T_vehicle`` (``Pose3.matrix()``,
metres). The tests check the kernels against GTSAM's own ``between`` and
``Logmap`` with their Jacobians, and against numerical derivatives.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["step_twist_kernel", "nonholonomic_kernel", "acceleration_kernel"]

#: Below this rotation angle (rad) the coefficients of the Logmap and its derivative are their Taylor series
#: (to theta^4; the closed forms lose their digits to cancellation at small angles).
_TAYLOR_BELOW = 1e-2


@njit
def _skew_into(S, a0, a1, a2):
    """Fills the 3x3 ``S = [a]x``."""
    S[0, 0], S[0, 1], S[0, 2] = 0.0, -a2, a1
    S[1, 0], S[1, 1], S[1, 2] = a2, 0.0, -a0
    S[2, 0], S[2, 1], S[2, 2] = -a1, a0, 0.0


@njit
def _mul_into(A, B, C):
    """Fills the 3x3 ``C = A B`` (explicit loops: BLAS is slower for matrices this small)."""
    for i in range(3):
        for j in range(3):
            C[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@njit
def _so3_log(R):
    """``Log(R)`` (rad) of a 3x3 rotation matrix, as GTSAM's ``SO3::Logmap``.

    ``theta / (2 sin theta) vee(R - R^T)``, with GTSAM's Taylor series near the
    identity. Near ``theta = pi`` (trace below -1 + 1e-3), where ``vee(R - R^T)``
    vanishes, the axis ``n`` comes from the symmetric part
    ``(R + R^T) / 2 = cos theta I + (1 - cos theta) n n^T`` (its largest diagonal
    entry), its sign from ``vee(R - R^T) = 2 sin theta n``, and the angle from
    ``atan2``.
    """
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    v0, v1, v2 = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    if tr + 1.0 < 1e-3:  # theta near pi
        c = 0.5 * (tr - 1.0)
        theta = math.atan2(0.5 * math.sqrt(v0 * v0 + v1 * v1 + v2 * v2), c)
        k = 0
        if R[1, 1] > R[k, k]:
            k = 1
        if R[2, 2] > R[k, k]:
            k = 2
        n = np.empty(3)
        n[k] = math.sqrt(max(R[k, k] - c, 0.0) / (1.0 - c))
        for j in range(3):
            if j != k:
                n[j] = (R[j, k] + R[k, j]) / (2.0 * (1.0 - c) * n[k])
        if n[0] * v0 + n[1] * v1 + n[2] * v2 < 0.0:
            theta = -theta
        return theta * n[0], theta * n[1], theta * n[2]
    tr_3 = tr - 3.0
    if tr_3 < -1e-6:
        theta = math.acos((tr - 1.0) / 2.0)
        magnitude = theta / (2.0 * math.sin(theta))
    else:  # theta near 0: Taylor series
        magnitude = 0.5 - tr_3 / 12.0 + tr_3 * tr_3 / 60.0
    return magnitude * v0, magnitude * v1, magnitude * v2


@njit
def _inverse_jacobian_coefficient(theta2):
    """``k(theta) = 1/theta^2 - 1 / (2 theta tan(theta / 2))`` of ``Jl^-1(w) = I - [w]x / 2 + k [w]x^2``.

    The same ``k`` gives GTSAM's SO(3) ``LogmapDerivative`` (``I + [w]x / 2 + k [w]x^2``)
    and the translation of its ``Pose3::Logmap`` (``rho = Jl^-1(w) t``; GTSAM writes
    it ``t - theta/2 [n]x t + (1 - theta / (2 tan(theta / 2))) [n]x^2 t``, ``n = w / theta``).
    GTSAM's ``(1 + cos theta) / (2 theta sin theta)`` is the same ratio, written here
    without its 0/0 at ``theta = pi``.
    """
    if theta2 < _TAYLOR_BELOW * _TAYLOR_BELOW:
        return 1.0 / 12.0 + theta2 / 720.0 + theta2 * theta2 / 30240.0
    theta = math.sqrt(theta2)
    return 1.0 / theta2 - 1.0 / (2.0 * theta * math.tan(0.5 * theta))


@njit
def _pose_log(R, t0, t1, t2, xi):
    """Fills ``xi = Log((R, t))`` (rotation first: rad, then metres), as GTSAM's ``Pose3::Logmap``."""
    w0, w1, w2 = _so3_log(R)
    xi[0], xi[1], xi[2] = w0, w1, w2
    k = _inverse_jacobian_coefficient(w0 * w0 + w1 * w1 + w2 * w2)
    a0, a1, a2 = w1 * t2 - w2 * t1, w2 * t0 - w0 * t2, w0 * t1 - w1 * t0  # w x t
    b0, b1, b2 = w1 * a2 - w2 * a1, w2 * a0 - w0 * a2, w0 * a1 - w1 * a0  # w x (w x t)
    xi[3] = t0 - 0.5 * a0 + k * b0
    xi[4] = t1 - 0.5 * a1 + k * b1
    xi[5] = t2 - 0.5 * a2 + k * b2


#: 3x3 matrices of the scratch array of :func:`_log_derivative` and :func:`_step_twist`.
_W, _V, _WW, _WV, _VW, _WVW, _WWV, _VWW, _WVWW, _WWVW, _Q, _JQ, _Q2, _R12, _T, _P, _C = range(17)
_SCRATCH = 17


@njit
def _log_derivative(xi, D, S):
    """Fills the 6x6 ``D = d Log(T) / d T`` at ``xi = Log(T)``, as GTSAM's ``Pose3::LogmapDerivative``.

    ``S``: scratch, (``_SCRATCH``, 3, 3).
    """
    w0, w1, w2 = xi[0], xi[1], xi[2]
    W, V = S[_W], S[_V]
    _skew_into(W, w0, w1, w2)
    _skew_into(V, xi[3], xi[4], xi[5])
    WW = S[_WW]
    _mul_into(W, W, WW)
    theta2 = w0 * w0 + w1 * w1 + w2 * w2
    k = _inverse_jacobian_coefficient(theta2)
    # Jw = I + [w]x / 2 + k [w]x^2, in both diagonal blocks
    for i in range(3):
        for j in range(3):
            jw = (1.0 if i == j else 0.0) + 0.5 * W[i, j] + k * WW[i, j]
            D[i, j] = jw
            D[3 + i, 3 + j] = jw
            D[i, 3 + j] = 0.0
    # Q (Barfoot14tro eq. 102)
    WV, VW, WVW, WWV, VWW, WVWW, WWVW = S[_WV], S[_VW], S[_WVW], S[_WWV], S[_VWW], S[_WVWW], S[_WWVW]
    _mul_into(W, V, WV)
    _mul_into(V, W, VW)
    _mul_into(WV, W, WVW)
    _mul_into(W, WV, WWV)
    _mul_into(VW, W, VWW)
    _mul_into(WVW, W, WVWW)
    _mul_into(W, WVW, WWVW)
    phi = math.sqrt(theta2)
    if phi > _TAYLOR_BELOW:
        s, c = math.sin(phi), math.cos(phi)
        phi3 = theta2 * phi
        phi4 = phi3 * phi
        phi5 = phi4 * phi
        c1 = (phi - s) / phi3
        c2 = (1.0 - theta2 / 2.0 - c) / phi4
        c3 = -0.5 * (c2 - 3.0 * (phi - s - phi3 / 6.0) / phi5)
    else:  # the same coefficients' Taylor series: the closed forms cancel to noise at small angles
        c1 = 1.0 / 6.0 - theta2 / 120.0 + theta2 * theta2 / 5040.0
        c2 = -1.0 / 24.0 + theta2 / 720.0 - theta2 * theta2 / 40320.0
        c3 = 1.0 / 120.0 - theta2 / 2520.0 + theta2 * theta2 / 120960.0
    Q = S[_Q]
    for i in range(3):
        for j in range(3):
            Q[i, j] = (-0.5 * V[i, j] + c1 * (WV[i, j] + VW[i, j] - WVW[i, j])
                       + c2 * (WWV[i, j] + VWW[i, j] - 3.0 * WVW[i, j]) + c3 * (WVWW[i, j] + WWVW[i, j]))
    Jw, JQ, Q2 = D[:3, :3], S[_JQ], S[_Q2]
    _mul_into(Jw, Q, JQ)
    _mul_into(JQ, Jw, Q2)
    for i in range(3):
        for j in range(3):
            D[3 + i, j] = -Q2[i, j]


@njit
def _step_twist(M1, M2, want_jacobians, xi, J1, J2, S):
    """Fills ``xi = Log(T1^-1 T2)`` and, if asked, ``J1, J2 = d xi / d T1, d xi / d T2`` (6x6 each).

    ``S``: scratch, (``_SCRATCH``, 3, 3).
    """
    R12 = S[_R12]
    for i in range(3):
        for j in range(3):
            R12[i, j] = M1[0, i] * M2[0, j] + M1[1, i] * M2[1, j] + M1[2, i] * M2[2, j]
    d0, d1, d2 = M2[0, 3] - M1[0, 3], M2[1, 3] - M1[1, 3], M2[2, 3] - M1[2, 3]
    t0 = M1[0, 0] * d0 + M1[1, 0] * d1 + M1[2, 0] * d2
    t1 = M1[0, 1] * d0 + M1[1, 1] * d1 + M1[2, 1] * d2
    t2 = M1[0, 2] * d0 + M1[1, 2] * d1 + M1[2, 2] * d2
    _pose_log(R12, t0, t1, t2, xi)
    if not want_jacobians:
        return
    _log_derivative(xi, J2, S)  # d between / d T2 is the identity: J2 = D
    # J1 = D H1, D = [[Jw, 0], [A, Jw]], H1 = -Ad(T12^-1) = [[-R12^T, 0], [R12^T [t12]x, -R12^T]]:
    # J1 = [[-Jw R12^T, 0], [-A R12^T + Jw R12^T [t12]x, -Jw R12^T]]
    T, P, C = S[_T], S[_P], S[_C]
    _skew_into(T, t0, t1, t2)
    for i in range(3):
        for j in range(3):
            P[i, j] = J2[i, 0] * R12[j, 0] + J2[i, 1] * R12[j, 1] + J2[i, 2] * R12[j, 2]  # Jw R12^T
            C[i, j] = R12[0, i] * T[0, j] + R12[1, i] * T[1, j] + R12[2, i] * T[2, j]  # R12^T [t12]x
    for i in range(3):
        for j in range(3):
            J1[i, j] = -P[i, j]
            J1[i, 3 + j] = 0.0
            J1[3 + i, 3 + j] = -P[i, j]
            J1[3 + i, j] = (-(J2[3 + i, 0] * R12[j, 0] + J2[3 + i, 1] * R12[j, 1] + J2[3 + i, 2] * R12[j, 2])
                            + J2[i, 0] * C[0, j] + J2[i, 1] * C[1, j] + J2[i, 2] * C[2, j])


@njit
def step_twist_kernel(M1, M2, want_jacobians, xi, J1, J2):
    """``Log(T1^-1 T2)`` and, if asked, its Jacobians with respect to ``T1`` and ``T2``.

    Args:
        M1, M2: (4, 4) homogeneous matrices of the poses ``T1``, ``T2`` (world frame, metres).
        want_jacobians: whether to fill ``J1`` and ``J2``.
        xi: (6,) the twist, written: rotation first (rad, then metres, in the frame of ``T1``).
        J1, J2: (6, 6) ``d xi / d T1``, ``d xi / d T2`` (right perturbations, rotation first), written.
    """
    _step_twist(M1, M2, want_jacobians, xi, J1, J2, np.empty((_SCRATCH, 3, 3)))


@njit
def nonholonomic_kernel(M1, M2, params, want_jacobians, r, H1, H2):
    """Residual and Jacobians of the non-holonomic factor (:func:`vfactor.factors.motion.nonholonomic_factor`).

    Args:
        M1, M2: (4, 4) homogeneous matrices of the two poses (world frame, metres).
        params: ``[dt (s), sigma_lateral (m/s), sigma_vertical (m/s), sigma_tilt (rad/s),
            max_yaw_rate (rad/s), yaw_rate_sigma (rad/s)]``.
        want_jacobians: whether to fill ``H1`` and ``H2``.
        r: (5,) the whitened residual, written.
        H1, H2: (5, 6) ``d r / d T1``, ``d r / d T2``, written.
    """
    dt, sigma_lateral, sigma_vertical, sigma_tilt, max_yaw_rate, yaw_rate_sigma = (
        params[0], params[1], params[2], params[3], params[4], params[5])
    xi, J = np.empty(6), np.empty((2, 6, 6))
    _step_twist(M1, M2, want_jacobians, xi, J[0], J[1], np.empty((_SCRATCH, 3, 3)))
    yaw_rate = xi[2] / dt
    over = yaw_rate - min(max(yaw_rate, -max_yaw_rate), max_yaw_rate)
    r[0] = xi[4] / (sigma_lateral * dt)
    r[1] = xi[5] / (sigma_vertical * dt)
    r[2] = xi[0] / (sigma_tilt * dt)
    r[3] = xi[1] / (sigma_tilt * dt)
    r[4] = over / yaw_rate_sigma
    if want_jacobians:
        rows = (4, 5, 0, 1, 2)  # the twist component of each residual row
        scale = (1.0 / (sigma_lateral * dt), 1.0 / (sigma_vertical * dt), 1.0 / (sigma_tilt * dt),
                 1.0 / (sigma_tilt * dt), (1.0 if over != 0.0 else 0.0) / (dt * yaw_rate_sigma))
        for a in range(5):
            for j in range(6):
                H1[a, j] = scale[a] * J[0, rows[a], j]
                H2[a, j] = scale[a] * J[1, rows[a], j]


@njit
def acceleration_kernel(M0, M1, M2, params, want_jacobians, r, H0, H1, H2):
    """Residual and Jacobians of the acceleration factor (:func:`vfactor.factors.motion.acceleration_factor`).

    Args:
        M0, M1, M2: (4, 4) homogeneous matrices of the three poses (world frame, metres).
        params: ``[dt1 (s), dt2 (s), sigma_acceleration (m/s^2), sigma_yaw_acceleration (rad/s^2)]``.
        want_jacobians: whether to fill ``H0``, ``H1`` and ``H2``.
        r: (2,) the whitened residual, written.
        H0, H1, H2: (2, 6) ``d r / d T0``, ``d r / d T1``, ``d r / d T2``, written.
    """
    dt1, dt2, sigma_acceleration, sigma_yaw_acceleration = params[0], params[1], params[2], params[3]
    xi, J, S = np.empty((2, 6)), np.empty((4, 6, 6)), np.empty((_SCRATCH, 3, 3))
    _step_twist(M0, M1, want_jacobians, xi[0], J[0], J[1], S)  # step a
    _step_twist(M1, M2, want_jacobians, xi[1], J[2], J[3], S)  # step b
    mid = 0.5 * (dt1 + dt2)
    ca, cb = 1.0 / (sigma_acceleration * mid), 1.0 / (sigma_yaw_acceleration * mid)
    r[0] = ca * (xi[1, 3] / dt2 - xi[0, 3] / dt1)
    r[1] = cb * (xi[1, 2] / dt2 - xi[0, 2] / dt1)
    if want_jacobians:
        for j in range(6):
            H0[0, j] = -ca / dt1 * J[0, 3, j]
            H0[1, j] = -cb / dt1 * J[0, 2, j]
            H1[0, j] = -ca / dt1 * J[1, 3, j] + ca / dt2 * J[2, 3, j]
            H1[1, j] = -cb / dt1 * J[1, 2, j] + cb / dt2 * J[2, 2, j]
            H2[0, j] = ca / dt2 * J[3, 3, j]
            H2[1, j] = cb / dt2 * J[3, 2, j]
