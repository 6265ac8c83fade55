"""Ground-plane factor: the vehicle stands on the road.

For a road plane ``{x : n . x = d}`` (unit normal ``n`` pointing up, world frame)
and a pose ``T = (R, t)`` whose origin is the wheel-hub centroid:

* height: ``(n . t - d - hub_height) / sigma_height``, the hubs at the wheel
  radius above the road (``sigma_height`` covers the unknown radius);
* tilt: the x and y components of ``v = R^T n`` (the road normal in the body
  frame, ``(0, 0, 1)`` when the car sits flat) over ``sigma_tilt``: roll and
  pitch near the plane's.

Jacobians (right perturbation ``T Exp(xi)``): ``d(n . t)/d rho = n^T R``;
``d v / d w = [v]x`` (``R Exp(w)`` gives ``Exp(-w) v ~ v + v x w``).

Residual and Jacobian come from one compiled (numba) call per linearisation,
:func:`_ground_plane_kernel`, as for the motion factors
(:mod:`vfactor.factors.motion_kernel`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import gtsam
import numpy as np
from numba import njit

__all__ = ["GroundPlane", "ground_plane_factor"]


@dataclass(frozen=True)
class GroundPlane:
    """A road plane ``n . x = offset`` in the world frame (``normal`` is made unit length).

    Attributes:
        normal: (3,) upward normal.
        offset: metres.
    """

    normal: tuple = (0.0, 0.0, 1.0)
    offset: float = 0.0

    def __post_init__(self):
        n = np.asarray(self.normal, dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
            raise ValueError(f"ground_plane.normal: expected a non-zero 3-vector, got {self.normal!r}")
        n = n / np.linalg.norm(n)
        if n[2] <= 0:
            raise ValueError(f"ground_plane.normal: must point up (positive z), got {self.normal!r}")
        if not np.isfinite(self.offset):
            raise ValueError(f"ground_plane.offset: expected a finite number, got {self.offset!r}")
        object.__setattr__(self, "normal", tuple(float(v) for v in n))
        object.__setattr__(self, "offset", float(self.offset))


@njit(cache=True)
def _ground_plane_kernel(M, params, want_jacobian, r, J):
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


def _error(key: int, params: np.ndarray, out: tuple, this, values, H):
    # out: this factor's (r, J), reused: GTSAM copies H[0] and the returned r
    r, J = out
    want = H is not None
    _ground_plane_kernel(values.atPose3(key).matrix(), params, want, r, J)
    if want:
        H[0] = J
    return r


def ground_plane_factor(pose_key: int, plane: GroundPlane = GroundPlane(), hub_height: float = 0.34,
                        sigma_height: float = 0.05, sigma_tilt: float = 0.03) -> gtsam.CustomFactor:
    """The vehicle pose ``pose_key`` on the road plane (3 whitened rows).

    Args:
        pose_key: key of the ``world_T_vehicle`` pose (origin at the wheel-hub centroid).
        plane: the road plane (world frame).
        hub_height: height of the hubs above the road, metres.
        sigma_height: sigma of the height residual, metres.
        sigma_tilt: sigma of the body-frame road normal's x and y components (about rad).

    Returns:
        A unit-noise ``CustomFactor``: the hub height above the plane, and roll and pitch
        against the plane's.
    """
    params = np.array([*plane.normal, plane.offset, hub_height, sigma_height, sigma_tilt], dtype=float)
    out = (np.empty(3), np.zeros((3, 6)))
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(3), [pose_key], partial(_error, pose_key, params, out))
