"""Reference: the true wireframe given, the pose alone solved.

It uses the same projection factor, noise and robust loss as the factor graph,
starts from the true pose and holds the shape fixed, so its errors are what the
keypoint noise alone leaves: a lower bound for any method that must also find
the shape and the initial pose. Given a road plane, it holds the vehicle on it
with the same ground-plane factor, at the vehicle's true wheel radius.
"""

from __future__ import annotations

import dataclasses

import gtsam

from vfactor.factors.ground_plane import GroundPlane
from vfactor.graph import GraphConfig, add_observation_factor, ground_factor, insert_vehicle_values
from vfactor.factors.projection import KeypointObservations
from vfactor.keys import KeyScheme
from vfactor.label_swaps import relabel_swaps as _relabel_swaps
from vfactor.result import Status, VehicleResult
from vfactor.wireframe import Wireframe

__all__ = ["known_shape"]


def known_shape(
    obs: KeypointObservations,
    world_T_vehicle_true: gtsam.Pose3,
    wireframe_true: Wireframe,
    config: GraphConfig = GraphConfig(),
    vehicle_id: str = "vehicle",
    relabel_swaps: bool = True,
    ground_plane: GroundPlane | None = None,
    wheel_radius: float | None = None,
) -> VehicleResult:
    """Pose by Levenberg-Marquardt from the true pose with the true shape held fixed.

    With ``relabel_swaps`` (as the factor graph's solve does by default), the
    left/right pairs that the solution says are swapped are relabelled and the
    pose solved again (:func:`vfactor.label_swaps.relabel_swaps`). With a
    ``ground_plane`` (world frame) the ground-plane factor holds the hubs
    ``wheel_radius`` metres above it (default: :func:`vfactor.graph.hub_height`'s).
    """
    keys = KeyScheme()
    values = gtsam.Values()
    insert_vehicle_values(values, keys, world_T_vehicle_true, wireframe_true)
    if ground_plane is not None and wheel_radius is not None and config.hub_height is None:
        config = dataclasses.replace(config, hub_height=float(wheel_radius))
    ground = None if ground_plane is None else ground_factor(keys.pose_key(), ground_plane, config)
    graph, estimate, iterations = _solve(obs, wireframe_true, values, keys, config, ground)
    if relabel_swaps:
        relabelled, swaps = _relabel_swaps(obs, estimate.atPose3(keys.pose_key()), wireframe_true.vehicle_p_keypoints,
                                           config.loss)
        if swaps:
            graph, estimate, more = _solve(relabelled, wireframe_true, estimate, keys, config, ground)
            iterations += more
    return VehicleResult(
        vehicle_id, Status.CONVERGED, world_T_vehicle=estimate.atPose3(keys.pose_key()), wireframe=wireframe_true,
        iterations=iterations, final_error=graph.error(estimate),
    )


def _solve(obs, wireframe_true, values, keys, config, ground=None):
    graph = gtsam.NonlinearFactorGraph()
    add_observation_factor(graph, keys, obs, config=config)
    if ground is not None:
        graph.add(ground)
    fixed = gtsam.noiseModel.Isotropic.Sigma(12, 1e-6)
    for key, vec in zip(keys.layer_keys(), wireframe_true.layer_vectors().values()):
        graph.add(gtsam.PriorFactorVector(key, vec, fixed))
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams())
    estimate = optimizer.optimize()
    return graph, estimate, optimizer.iterations()
