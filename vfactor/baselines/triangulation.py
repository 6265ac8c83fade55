"""Baseline: triangulate every keypoint seen by two or more cameras.

The triangulated points (linear DLT, weighted by confidence) are the
wireframe; keypoints seen by fewer than two cameras take the mean shape's
position after a rigid alignment (Umeyama, with scale) of the mean wireframe to
the triangulated ones, which also gives the pose.
"""

from __future__ import annotations

import gtsam
import numpy as np

from vfactor.factors.projection import KeypointObservations
from vfactor.init import triangulate_keypoints, umeyama
from vfactor.result import Status, VehicleResult
from vfactor.shape_model import default_shape_prior
from vfactor.wireframe import Wireframe

__all__ = ["triangulation"]


def triangulation(obs: KeypointObservations, vehicle_id: str = "vehicle", mean: Wireframe | None = None) -> VehicleResult:
    """Pose and wireframe from triangulated keypoints.

    Args:
        obs: the vehicle's observations in all cameras.
        vehicle_id: id for the result.
        mean: the shape aligned to the triangulated points (default: the prior's mean).

    Returns:
        A result with ``final_error`` NaN; ``degenerate`` when fewer than three
        keypoints triangulate.
    """
    mean = mean or Wireframe(default_shape_prior().mean)
    finite = np.all(np.isfinite(obs.uv), axis=1)
    if not finite.all():
        obs = obs.subset(finite)
    idx, world = triangulate_keypoints(obs)
    if len(idx) < 3:
        return VehicleResult(vehicle_id, Status.DEGENERATE, message=f"only {len(idx)} keypoints seen by two cameras")
    R, t, s = umeyama(mean.vehicle_p_keypoints[idx], world, with_scale=True)
    world_T_vehicle = gtsam.Pose3(gtsam.Rot3(R), t)
    body = mean.vehicle_p_keypoints * s
    body[idx] = (world - t) @ R  # triangulated points in the aligned body frame
    return VehicleResult(vehicle_id, Status.CONVERGED, world_T_vehicle=world_T_vehicle, wireframe=Wireframe(body))
