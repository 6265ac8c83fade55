"""Body-frame factor: fixes the gauge of pose and shape.

Pose and shape together have six degrees of freedom too many (move every body
point by a rigid motion and the pose by its inverse). docs/conventions.md fixes the
body frame at the centroid of the four wheel hubs, x forward, z up; with the
symmetry factor (which fixes yaw and roll about x), the wheel layer residual

    ( (p_lf + p_rf + p_lb + p_rb) / 4,  (z_lf + z_rf - z_lb - z_rb) / 2 ) / sigma

fixes the origin (3 rows) and the pitch (1 row). Linear, so native.

These factors fix the gauge up to one discrete choice: turned by half a turn
about body z (every body point ``(x, y, z) -> (-x, -y, z)``, every pose of
the vehicle composed with ``Rz(pi)``) the shape is still symmetric, its hubs
still level about the origin, and every keypoint lands on the same world point,
so every pixel is the same. Only the shape prior (and HWC) tell the front from
the back, and a heavy-tailed prior (the tracks' Cauchy loss) barely does: a
track started that way stayed turned for its whole length. The convention
(x points from the back axle to the front axle) is restored by
:func:`canonical_gauge`, which the solvers apply to every solution.
"""

from __future__ import annotations

import gtsam
import numpy as np

from vfactor.factors.linear import linear_vector_factor

__all__ = ["body_frame_factor", "BODY_FRAME_MATRIX", "turned_front_to_back", "upright", "canonical_gauge"]

#: (4, 12) residual matrix on the wheel layer.
BODY_FRAME_MATRIX = np.zeros((4, 12))
for _i in range(4):
    BODY_FRAME_MATRIX[:3, 3 * _i : 3 * _i + 3] = 0.25 * np.eye(3)
BODY_FRAME_MATRIX[3, [2, 5]] = 0.5
BODY_FRAME_MATRIX[3, [8, 11]] = -0.5
BODY_FRAME_MATRIX.setflags(write=False)


def body_frame_factor(wheel_key: int, sigma: float = 1e-3):
    """Gauge factor on the wheel layer (origin at the hub centroid, hubs level).

    Args:
        wheel_key: key of the wheel layer.
        sigma: standard deviation, metres (small: it is a definition, not a measurement).
    """
    return linear_vector_factor([wheel_key], [BODY_FRAME_MATRIX], np.zeros(4), sigma)


_HALF_TURN = gtsam.Pose3(gtsam.Rot3.Rz(np.pi), np.zeros(3))
_HALF_TURN_POINTS = np.tile([-1.0, -1.0, 1.0], 4)  # a layer 12-vector's (x, y, z) -> (-x, -y, z)


def turned_front_to_back(wheel_layer: np.ndarray) -> bool:
    """Whether a wheel layer (12-vector, body frame) has its front hubs behind its back hubs: the body frame is
    turned by half a turn about z against the convention (x forward)."""
    p = np.asarray(wheel_layer, dtype=float).reshape(4, 3)
    return bool(p[0, 0] + p[1, 0] < p[2, 0] + p[3, 0])


def upright(world_R_vehicle) -> np.ndarray | bool:
    """Whether a vehicle's body z axis (up) lies within 90 degrees of the world's, which is up (docs/conventions.md):
    no vehicle in traffic is upside down. ``world_R_vehicle``: a (3, 3) rotation or (n, 3, 3) / (n, 4, 4) stacked
    poses (then one answer each)."""
    R = np.asarray(world_R_vehicle, dtype=float)
    return bool(R[2, 2] > 0.0) if R.ndim == 2 else R[:, 2, 2] > 0.0


def canonical_gauge(values: gtsam.Values, pose_keys, layer_keys, offset_keys=()) -> gtsam.Values | None:
    """``values`` in the body frame of the convention when their body frame is turned front to back, else None.

    Every layer's body points become ``(-x, -y, z)`` and every pose ``world_T_vehicle Rz(pi)``: each keypoint keeps
    its label and its world point, so every factor but the shape prior's (and HWC's layer offsets) is unchanged, and
    those cost less. Keys not in ``values`` are skipped.

    Args:
        values: a solution.
        pose_keys: the vehicle's pose keys (one per frame).
        layer_keys: its (wheel, light, roof) layer keys.
        offset_keys: its detector pose offsets' keys (``vehicle_T_seen``, ``gtsam.Pose3``), put in the turned body
            frame (``Rz(pi)^-1 vehicle_T_seen Rz(pi)``).
    """
    layer_keys = list(layer_keys)
    if not values.exists(layer_keys[0]) or not turned_front_to_back(values.atVector(layer_keys[0])):
        return None
    out = gtsam.Values(values)
    for key in layer_keys:
        if out.exists(key):
            out.update(key, _HALF_TURN_POINTS * out.atVector(key))
    for key in offset_keys:
        if out.exists(key):
            out.update(key, _HALF_TURN.between(out.atPose3(key)).compose(_HALF_TURN))
    for key in pose_keys:
        if out.exists(key):
            out.update(key, out.atPose3(key).compose(_HALF_TURN))
    return out
