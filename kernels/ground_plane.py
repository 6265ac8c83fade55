"""The ground-plane factor's residual and Jacobian (numba source, compiled ahead of time into
:mod:`vfactor._kernels`).

The factor and its maths: :mod:`vfactor.factors.ground_plane`.
"""

from __future__ import annotations

from numba import njit

__all__ = ["ground_plane_kernel"]


@njit
def ground_plane_kernel(M, params, want_jacobian, r, J):
    """Fills the residual and Jacobian of the ground-plane factor.

    Args:
        M: (4, 4) homogeneous matrix of ``world_T_vehicle`` (metres).
        params: ``[n_x, n_y, n_z, offset (m), hub_height (m), sigma_height (m), sigma_tilt (rad)]``,
            ``n`` the plane's unit upward normal (world frame).
        want_jacobian: whether to fill ``J``.
        r: (3,) the whitened residual, written.
        J: (3, 6) ``d r / d xi`` (right perturbation, rotation first), written (zero on entry).
    """
    n0, n1, n2 = params[0], params[1], params[2]
    offset, hub_height, sigma_height, sigma_tilt = params[3], params[4], params[5], params[6]
    # v = R^T n: the road normal in the body frame
    v0 = M[0, 0] * n0 + M[1, 0] * n1 + M[2, 0] * n2
    v1 = M[0, 1] * n0 + M[1, 1] * n1 + M[2, 1] * n2
    v2 = M[0, 2] * n0 + M[1, 2] * n1 + M[2, 2] * n2
    r[0] = (n0 * M[0, 3] + n1 * M[1, 3] + n2 * M[2, 3] - offset - hub_height) / sigma_height
    r[1] = v0 / sigma_tilt
    r[2] = v1 / sigma_tilt
    if want_jacobian:
        J[0, 3], J[0, 4], J[0, 5] = v0 / sigma_height, v1 / sigma_height, v2 / sigma_height  # n^T R
        # rows x and y of [v]x
        J[1, 1], J[1, 2] = -v2 / sigma_tilt, v1 / sigma_tilt
        J[2, 0], J[2, 2] = v2 / sigma_tilt, -v0 / sigma_tilt
