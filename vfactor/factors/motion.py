"""Motion factors between consecutive poses of a vehicle: a planar, non-holonomic model.

A car moves along its heading: over a short step its body-frame motion is a
constant twist (a constant-curvature arc) with no sideways or vertical
velocity and no roll or pitch rate, and its speed and yaw rate change
smoothly. For two poses ``T1``, ``T2`` ``dt`` seconds apart let

    xi = Log(T1^-1 T2) = (w_x, w_y, w_z, rho_x, rho_y, rho_z)

(GTSAM's Pose3 tangent: rotation first; for a constant twist ``rho / dt`` is the
body velocity and ``w / dt`` the angular velocity). Then:

* :func:`nonholonomic_factor` (2 poses, 5 rows):
  ``rho_y / (sigma_lateral dt)``, ``rho_z / (sigma_vertical dt)``,
  ``w_x / (sigma_tilt dt)``, ``w_y / (sigma_tilt dt)`` and the yaw-rate bound
  ``hinge(w_z / dt, -max_yaw_rate, max_yaw_rate) / yaw_rate_sigma``;
* :func:`acceleration_factor` (3 poses, 2 rows): with ``v = rho_x / dt`` and
  ``omega = w_z / dt`` of the two steps,
  ``(v_b - v_a) / (sigma_acceleration dt_mid)`` and
  ``(omega_b - omega_a) / (sigma_yaw_acceleration dt_mid)``, ``dt_mid`` the mean step.

Jacobians are analytic: the chain ``dr/dxi * dLog * dbetween`` of GTSAM's
``Pose3.between`` and ``Pose3.Logmap`` Jacobians (docs/factors.md), computed
with the residual in one compiled call per factor (:mod:`kernels.motion`,
compiled ahead of time into :mod:`vfactor._kernels`); each factor is a
``gtsam.CustomFactor`` whose Python callback only reads the poses and calls
the kernel.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import gtsam
import numpy as np

from vfactor._kernels import acceleration_kernel, nonholonomic_kernel, step_twist_kernel
from vfactor.errors import check_numbers

__all__ = ["MotionModel", "nonholonomic_factor", "acceleration_factor", "step_twist"]


@dataclass(frozen=True)
class MotionModel:
    """Parameters of the vehicle motion model (SI units).

    Attributes:
        sigma_lateral: sideways velocity allowed (slip, modelling error), m/s.
        sigma_vertical: vertical velocity allowed, m/s.
        sigma_tilt: roll and pitch rates allowed, rad/s.
        max_yaw_rate: yaw rate bound (hinge), rad/s. Above any yaw rate a car
            reaches at an intersection: a left turn of radius 6.6 m at 11.6 m/s
            turns at 1.76 rad/s (tracks_3veh seed 2), and the former 1.0 rad/s
            bound left that turn's poses up to 65 cm and 15 degrees off.
        yaw_rate_sigma: softness of the yaw-rate bound beyond it, rad/s.
        sigma_acceleration: change of speed per second allowed, m/s^2.
        sigma_yaw_acceleration: change of yaw rate per second allowed, rad/s^2.
    """

    sigma_lateral: float = 0.1
    sigma_vertical: float = 0.1
    sigma_tilt: float = 0.05
    max_yaw_rate: float = 2.5
    yaw_rate_sigma: float = 0.05
    sigma_acceleration: float = 2.0
    sigma_yaw_acceleration: float = 1.0

    def __post_init__(self):
        check_numbers("MotionModel", self, self.__dataclass_fields__)


def step_twist(T1: gtsam.Pose3, T2: gtsam.Pose3, jacobians: bool = False):
    """The twist of the step from ``T1`` to ``T2`` and, if asked, its Jacobians.

    Args:
        T1, T2: ``world_T_vehicle`` at the start and the end of the step (metres).
        jacobians: whether to return the Jacobians.

    Returns:
        ``(xi, J1, J2)``: ``xi = Log(T1^-1 T2)`` (6,), rotation first (rad, then
        metres, in the frame of ``T1``), and ``d xi / d T1``, ``d xi / d T2``
        (6, 6; right perturbations, rotation first), or None for both when not asked.
    """
    xi, J1, J2 = np.empty(6), np.empty((6, 6)), np.empty((6, 6))
    step_twist_kernel(T1.matrix(), T2.matrix(), jacobians, xi, J1, J2)
    return (xi, J1, J2) if jacobians else (xi, None, None)


def _check_dt(dt: float) -> float:
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"motion factor: time step must be > 0 s, got {dt!r}")
    return float(dt)


def _nonholonomic_error(k1: int, k2: int, params: np.ndarray, out: tuple, this, values, H):
    # out: this factor's (r, H1, H2), reused: GTSAM copies H[i] and the returned r
    r, H1, H2 = out
    want = H is not None
    nonholonomic_kernel(values.atPose3(k1).matrix(), values.atPose3(k2).matrix(), params, want, r, H1, H2)
    if want:
        H[0], H[1] = H1, H2
    return r


def nonholonomic_factor(key1: int, key2: int, dt: float, model: MotionModel = MotionModel()) -> gtsam.CustomFactor:
    """Non-holonomic step between two poses of a vehicle (5 whitened rows).

    Args:
        key1, key2: keys of the ``world_T_vehicle`` poses at the start and the end of the step.
        dt: the step, seconds (> 0).
        model: the motion model's sigmas and yaw-rate bound.

    Returns:
        A unit-noise ``CustomFactor``: the lateral and vertical velocity, the roll and
        pitch rates, and the yaw rate beyond ``model.max_yaw_rate``, each over its sigma.

    Raises:
        ValueError: ``dt`` is not a positive finite number.
    """
    params = np.array([_check_dt(dt), model.sigma_lateral, model.sigma_vertical, model.sigma_tilt,
                       model.max_yaw_rate, model.yaw_rate_sigma], dtype=float)  # float64: the kernel's type
    out = (np.empty(5), np.zeros((5, 6)), np.zeros((5, 6)))
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(5), [key1, key2],
                              partial(_nonholonomic_error, key1, key2, params, out))


def _acceleration_error(k0: int, k1: int, k2: int, params: np.ndarray, out: tuple, this, values, H):
    # out: this factor's (r, H0, H1, H2), reused: GTSAM copies H[i] and the returned r
    r, H0, H1, H2 = out
    want = H is not None
    acceleration_kernel(values.atPose3(k0).matrix(), values.atPose3(k1).matrix(), values.atPose3(k2).matrix(),
                        params, want, r, H0, H1, H2)
    if want:
        H[0], H[1], H[2] = H0, H1, H2
    return r


def acceleration_factor(key0: int, key1: int, key2: int, dt1: float, dt2: float,
                        model: MotionModel = MotionModel()) -> gtsam.CustomFactor:
    """Smooth speed and yaw rate over three consecutive poses of a vehicle (2 whitened rows).

    Args:
        key0, key1, key2: keys of the ``world_T_vehicle`` poses, in time order.
        dt1, dt2: the steps ``key0 -> key1`` and ``key1 -> key2``, seconds (> 0).
        model: the motion model's acceleration sigmas.

    Returns:
        A unit-noise ``CustomFactor``: the change of speed and of yaw rate between the
        two steps, per mean step, each over its sigma.

    Raises:
        ValueError: a step is not a positive finite number.
    """
    params = np.array([_check_dt(dt1), _check_dt(dt2), model.sigma_acceleration, model.sigma_yaw_acceleration], dtype=float)
    out = (np.empty(2), np.zeros((2, 6)), np.zeros((2, 6)), np.zeros((2, 6)))
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(2), [key0, key1, key2],
                              partial(_acceleration_error, key0, key1, key2, params, out))
