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

The hub height may be a variable (``hub_key``: a 1-vector, metres): a vehicle's
wheel radius is its own and the same in every frame of its track, so a track
gives it one variable (with :func:`hub_height_prior`) and each pose's factor
only the road's unevenness (``sigma_height`` then the per-pose part; the height
row's Jacobian on the variable is ``-1 / sigma_height``). Treated as independent
noise in every frame, the unknown radius averaged away over a track: a pickup's
hubs (0.39 m up) were held near the default 0.34 m by 30 frames' factors each
as sure as one.

Residual and Jacobian come from one compiled call per linearisation
(:func:`kernels.ground_plane.ground_plane_kernel`, in :mod:`vfactor._kernels`), as
for the motion factors.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from functools import partial

import gtsam
import numpy as np

from vfactor._kernels import ground_plane_kernel

__all__ = ["GroundPlane", "ground_plane_factor", "hub_height_prior"]


@dataclass(frozen=True)
class GroundPlane:
    """A road plane ``n . x = offset`` in the world frame. A normal of any length is made unit length and the
    offset divided by the same length, so that the plane stays the one given (``(0, 0, 4)`` and offset 1 is
    ``z = 0.25``).

    Attributes:
        normal: (3,) upward normal.
        offset: metres.
    """

    normal: tuple = (0.0, 0.0, 1.0)
    offset: float = 0.0

    def __post_init__(self):
        n = np.asarray(self.normal, dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
            raise ValueError(f"ground_plane.normal: expected a non-zero 3-vector, got {_shown(self.normal)}")
        length = np.linalg.norm(n)
        n = n / length
        if n[2] <= 0:
            raise ValueError(f"ground_plane.normal: must point up (positive z), got {_shown(self.normal)}")
        if not isinstance(self.offset, numbers.Real) or isinstance(self.offset, (bool, np.bool_)) or \
                not np.isfinite(self.offset):
            raise ValueError(f"ground_plane.offset: expected a finite number, got {self.offset!r}")
        object.__setattr__(self, "normal", tuple(float(v) for v in n))
        object.__setattr__(self, "offset", float(self.offset) / float(length))


def _shown(value) -> str:
    """A normal as the user wrote it, for a message: ``[0.0, 0.0, -1.0]``, not NumPy's reprs."""
    try:
        return "[" + ", ".join(repr(float(v)) for v in value) + "]"
    except (TypeError, ValueError):
        return repr(value)


def _error(key: int, params: np.ndarray, out: tuple, hub_key, this, values, H):
    # out: this factor's (r, J), reused: GTSAM copies H[0] and the returned r
    r, J = out
    want = H is not None
    if hub_key is not None:  # the hub height is a variable: params[4] takes its value
        params[4] = values.atVector(hub_key)[0]
    ground_plane_kernel(values.atPose3(key).matrix(), params, want, r, J)
    if want:
        H[0] = J
        if hub_key is not None:
            H[1] = np.array([[-1.0 / params[5]], [0.0], [0.0]])
    return r


def ground_plane_factor(pose_key: int, plane: GroundPlane = GroundPlane(), hub_height: float = 0.34,
                        sigma_height: float = 0.06, sigma_tilt: float = 0.03,
                        hub_key: int | None = None) -> gtsam.CustomFactor:
    """The vehicle pose ``pose_key`` on the road plane (3 whitened rows).

    Args:
        pose_key: key of the ``world_T_vehicle`` pose (origin at the wheel-hub centroid).
        plane: the road plane (world frame).
        hub_height: height of the hubs above the road, metres (not used with ``hub_key``).
        sigma_height: sigma of the height residual, metres.
        sigma_tilt: sigma of the body-frame road normal's x and y components (about rad).
        hub_key: key of the vehicle's hub height (a 1-vector, metres) where it is a variable, shared by the
            poses of a track (:func:`hub_height_prior`); None: ``hub_height`` is given.

    Returns:
        A unit-noise ``CustomFactor`` on ``[pose_key]`` (or ``[pose_key, hub_key]``): the hub height above the
        plane, and roll and pitch against the plane's.
    """
    params = np.array([*plane.normal, plane.offset, hub_height, sigma_height, sigma_tilt], dtype=float)
    out = (np.empty(3), np.zeros((3, 6)))
    keys = [pose_key] if hub_key is None else [pose_key, hub_key]
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(3), keys, partial(_error, pose_key, params, out, hub_key))


def hub_height_prior(hub_key: int, hub_height: float, sigma: float) -> gtsam.NonlinearFactor:
    """The prior of a vehicle's hub height above the road (``hub_key``: a 1-vector, metres): ``hub_height``
    with ``sigma`` for the wheel radii of real vehicles (the ground-plane factors of its poses take the value
    through ``hub_key``)."""
    return gtsam.PriorFactorVector(hub_key, np.array([float(hub_height)]),
                                   gtsam.noiseModel.Isotropic.Sigma(1, float(sigma)))
