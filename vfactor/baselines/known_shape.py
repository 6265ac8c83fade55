"""Reference: the true wireframe given, the pose alone solved.

It uses the same projection factor, noise and robust loss as the factor graph,
starts from the true pose and holds the shape fixed, so its errors are what the
keypoint noise alone leaves: a lower bound for any method that must also find
the shape and the initial pose.
"""

from __future__ import annotations

import gtsam
import numpy as np

from vfactor.graph import GraphConfig, add_observation_factor, insert_vehicle_values
from vfactor.factors.projection import KeypointObservations
from vfactor.keys import KeyScheme
from vfactor.result import Status, VehicleResult
from vfactor.wireframe import Wireframe

__all__ = ["known_shape"]


def known_shape(
    obs: KeypointObservations,
    world_T_vehicle_true: gtsam.Pose3,
    wireframe_true: Wireframe,
    config: GraphConfig = GraphConfig(),
    vehicle_id: str = "vehicle",
) -> VehicleResult:
    """Pose by Levenberg-Marquardt from the true pose with the true shape held fixed."""
    keys = KeyScheme()
    graph = gtsam.NonlinearFactorGraph()
    add_observation_factor(graph, keys, obs, config=config)
    fixed = gtsam.noiseModel.Isotropic.Sigma(12, 1e-6)
    for key, vec in zip(keys.layer_keys(), wireframe_true.layer_vectors().values()):
        graph.add(gtsam.PriorFactorVector(key, vec, fixed))
    values = gtsam.Values()
    insert_vehicle_values(values, keys, world_T_vehicle_true, wireframe_true)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams())
    estimate = optimizer.optimize()
    return VehicleResult(
        vehicle_id, Status.CONVERGED, world_T_vehicle=estimate.atPose3(keys.pose_key()), wireframe=wireframe_true,
        iterations=optimizer.iterations(), final_error=graph.error(estimate),
    )
