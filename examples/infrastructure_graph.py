"""vfactor's vehicle variables inside a larger graph of your own.

A roadside unit (RSU) with its own pose variable measures the tracked vehicle
with a range sensor (a relative pose, ``BetweenFactorPose3``), while two fixed
cameras see the vehicle's keypoints. vfactor's factors are added to the same
``gtsam.NonlinearFactorGraph`` under a key scheme chosen not to collide with
the RSU's keys, and everything is solved together.

Run: ``python examples/infrastructure_graph.py``. The tests import
:func:`build_graph` and :func:`solve` and check the estimate against vfactor's
standalone batch smoother.
"""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np

import vfactor
from vfactor.factors.motion import MotionModel, acceleration_factor, nonholonomic_factor
from vfactor.sim import simulate

#: vfactor's variables use v (poses) and a, b, c (shape layers); the RSU uses u.
KEYS = vfactor.KeyScheme(pose="v", wheel="a", light="b", roof="c")
RSU = gtsam.symbol("u", 0)
RSU_POSE = gtsam.Pose3(gtsam.Rot3.Yaw(np.pi / 2), np.array([8.0, -6.0, 1.5]))


def build_graph(scenario: str = "intersection_2cam_track", seed: int = 2, frames: int = 12,
                range_sigma: float = 0.3, angle_sigma: float = 0.02, vehicle: str = "v1"):
    """The joint graph: RSU prior, RSU-to-vehicle relative poses, and vfactor's factors.

    Args:
        range_sigma: the RSU's position noise along its x and y (metres; a third of it vertically).
        angle_sigma: its yaw noise (radians; half of it for roll and pitch).

    Returns:
        (graph, initial values, the simulation, pose keys of the vehicle by frame).
    """
    sim = simulate(scenario, seed=seed, num_frames=frames)
    rng = np.random.default_rng(seed)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()

    # Your own part of the graph: the RSU, surveyed to a few millimetres.
    graph.add(gtsam.PriorFactorPose3(RSU, RSU_POSE, gtsam.noiseModel.Isotropic.Sigma(6, 0.005)))
    values.insert(RSU, RSU_POSE)

    # vfactor's part: one shape per vehicle, one pose per frame, with the tracker's settings. Each frame is
    # solved alone first: the solves give the initial values, and together the body type (the shape prior)
    # and the noise scale of the keypoints (vfactor.track_shape, as vfactor's batch smoother does).
    options = vfactor.TrackOptions().solve
    config = options.graph
    model = vfactor.default_shape_model()
    frames = [(f, frame) for f, frame in enumerate(sim.scene.frames) if frame.detections_of(vehicle)]
    observations = {f: vfactor.observations_from_detections(frame.detections_of(vehicle), sim.scene.cameras, config)
                    for f, frame in frames}
    hints = vfactor.class_hints(d for _, frame in frames for d in frame.detections_of(vehicle))  # a 2D detector's
    firsts = {f: vfactor.solve_observations(obs, dataclasses.replace(options, covariance=False, shape_information=True),
                                            prior=model, hints=hints)  # classes, where the detections carry them
              for f, obs in observations.items()}
    shape = vfactor.track_shape(list(firsts.values()), model, hints=hints)
    vfactor.add_shape_factors(graph, KEYS, vehicle=0, config=config, prior=shape.prior)
    motion = MotionModel()
    pose_keys = {}
    previous = []
    for f, frame in frames:
        obs = observations[f].scaled(shape.noise_scale)
        key = KEYS.pose_key(0, f)
        vfactor.add_observation_factor(graph, KEYS, obs, vehicle=0, frame=f, config=config)
        if previous:
            graph.add(nonholonomic_factor(previous[-1][1], key, frame.t - previous[-1][0], motion))
        if len(previous) >= 2:
            (t0, k0), (t1, k1) = previous[-2:]
            graph.add(acceleration_factor(k0, k1, key, t1 - t0, frame.t - t1, motion))
        # The RSU's range sensor: the vehicle's pose relative to the RSU, with noise.
        truth = sim.truth[f][vehicle].world_T_vehicle
        sigmas = np.array([angle_sigma / 2, angle_sigma / 2, angle_sigma, range_sigma, range_sigma, range_sigma / 3])
        measured = RSU_POSE.between(truth).retract(rng.normal(0, sigmas))
        noise = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        graph.add(gtsam.BetweenFactorPose3(RSU, key, measured, noise))
        # Initial values from vfactor's one-frame solve (the shape of the frame with the most keypoints).
        first = firsts[f]
        values.insert(key, first.world_T_vehicle if first.ok else RSU_POSE.compose(measured))
        if first.ok and len(obs) >= max((len(observations[g]) for g in firsts if firsts[g].ok), default=0):
            vfactor.insert_vehicle_values(values, KEYS, None, first.wireframe, vehicle=0)
        pose_keys[f] = key
        previous.append((frame.t, key))
    return graph, values, sim, pose_keys


def solve(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> gtsam.Values:
    """Levenberg-Marquardt over the joint graph."""
    return gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()


def main() -> None:
    graph, values, sim, pose_keys = build_graph()
    estimate = solve(graph, values)
    alone = vfactor.smooth_scene(sim.scene, vfactor.TrackOptions())
    print(f"{'frame':>5} {'joint vs truth cm':>18} {'standalone vs truth cm':>23} {'joint vs standalone cm':>23}")
    for f, key in pose_keys.items():
        joint = estimate.atPose3(key).translation()
        standalone = alone[f].vehicles[0].world_T_vehicle.translation()
        truth = sim.truth[f]["v1"].world_T_vehicle.translation()
        print(f"{f:>5} {100 * np.linalg.norm(joint - truth):>18.1f} {100 * np.linalg.norm(standalone - truth):>23.1f} "
              f"{100 * np.linalg.norm(joint - standalone):>23.1f}")


if __name__ == "__main__":
    main()
