"""The body frame's half-turn ambiguity: a solution turned front to back is brought back to the convention.

The symmetry and body-frame factors fix the gauge of pose and shape up to half a
turn about body z (vfactor.factors.body_frame). With the tracks' heavy-tailed
shape prior a track of association_3cam (hard noise, seed 0) started that way
and stayed 179 deg off for all its 50 frames, every pose reported converged.
"""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from vfactor.evaluation import NOISE_LEVELS, noise_variant
from vfactor.factors.body_frame import canonical_gauge, turned_front_to_back
from vfactor.factors.robust import RobustLoss
from vfactor.graph import GraphConfig, build_vehicle_graph, insert_vehicle_values, observations_from_detections
from vfactor.keys import KeyScheme
from vfactor.result import Status, VehicleResult
from vfactor.sanity import check_estimate
from vfactor.shape_model import default_shape_prior
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions, solve_observations
from vfactor.track import TrackOptions, track_scene
from vfactor.wireframe import PRESETS, Wireframe

HALF_TURN = gtsam.Pose3(gtsam.Rot3.Rz(np.pi), np.zeros(3))


def turned(world_T_vehicle: gtsam.Pose3, wireframe: Wireframe) -> tuple[gtsam.Pose3, Wireframe]:
    """The same vehicle with its body frame turned by half a turn about z: the same world keypoints."""
    return world_T_vehicle.compose(HALF_TURN), Wireframe(wireframe.vehicle_p_keypoints * np.array([-1.0, -1.0, 1.0]))


def rotation_deg(a: gtsam.Pose3, b: gtsam.Pose3) -> float:
    return float(np.degrees(np.linalg.norm(a.rotation().logmap(b.rotation()))))


def test_canonical_gauge_keeps_every_world_point_and_lowers_the_prior_cost():
    keys = KeyScheme()
    shape = PRESETS["toyota_prius"].wireframe()
    world_T_vehicle = gtsam.Pose3(gtsam.Rot3.Ypr(0.7, 0.02, -0.01), np.array([3.0, -4.0, 0.33]))
    values = gtsam.Values()
    insert_vehicle_values(values, keys, world_T_vehicle, shape)
    assert not turned_front_to_back(values.atVector(keys.layer_keys(0)[0]))
    assert canonical_gauge(values, [keys.pose_key()], keys.layer_keys(0)) is None  # already the convention's

    bad = gtsam.Values()
    insert_vehicle_values(bad, keys, *turned(world_T_vehicle, shape))
    assert turned_front_to_back(bad.atVector(keys.layer_keys(0)[0]))
    fixed = canonical_gauge(bad, [keys.pose_key()], keys.layer_keys(0))
    assert fixed is not None and not turned_front_to_back(fixed.atVector(keys.layer_keys(0)[0]))
    np.testing.assert_allclose(fixed.atPose3(keys.pose_key()).matrix(), world_T_vehicle.matrix(), atol=1e-12)
    for key in keys.layer_keys(0):
        np.testing.assert_allclose(fixed.atVector(key), values.atVector(key), atol=1e-12)
    # the same pixels either way: only the shape prior tells front from back
    sim = simulate("intersection_2cam", seed=1, num_frames=1)
    vid = sim.scene.frames[0].vehicle_ids()[0]
    obs = observations_from_detections(sim.scene.frames[0].detections_of(vid), sim.scene.cameras)
    truth = sim.truth[0][vid]
    at_truth, at_turned = gtsam.Values(), gtsam.Values()
    insert_vehicle_values(at_truth, keys, truth.world_T_vehicle, truth.wireframe)
    insert_vehicle_values(at_turned, keys, *turned(truth.world_T_vehicle, truth.wireframe))
    graph = build_vehicle_graph(obs, keys, prior=default_shape_prior())
    projection = graph.at(0)
    assert projection.error(at_turned) == pytest.approx(projection.error(at_truth), rel=1e-9)
    assert graph.error(at_turned) > graph.error(at_truth) + 100.0


def test_canonical_gauge_keeps_what_a_detector_pose_offset_sees():
    """A track's detector pose offsets are put in the turned body frame: the same pixels, the same prior cost."""
    from vfactor.factors.projection import projection_factor
    from vfactor.graph import detector_offset_prior

    keys = KeyScheme()
    sim = simulate("intersection_2cam", seed=1, num_frames=1)
    vid = sim.scene.frames[0].vehicle_ids()[0]
    obs = observations_from_detections(sim.scene.frames[0].detections_of(vid), sim.scene.cameras)
    truth = sim.truth[0][vid]
    offset_key = keys.offset_key(0, 0)
    factor = projection_factor(keys.pose_key(), keys.layer_keys(0), obs, RobustLoss("none"), offset_key=offset_key)
    prior = detector_offset_prior(offset_key, 0.04, truth.wireframe.vehicle_p_keypoints)
    bad = gtsam.Values()
    insert_vehicle_values(bad, keys, *turned(truth.world_T_vehicle, truth.wireframe))
    bad.insert(offset_key, gtsam.Pose3.Expmap(np.array([0.01, -0.02, 0.015, 0.03, 0.02, -0.01])))
    fixed = canonical_gauge(bad, [keys.pose_key()], keys.layer_keys(0), [offset_key])
    assert fixed is not None
    assert factor.error(bad) > 1.0
    assert factor.error(fixed) == pytest.approx(factor.error(bad), rel=1e-9)
    assert prior.error(fixed) == pytest.approx(prior.error(bad), rel=1e-9)


@pytest.mark.parametrize("loss", [RobustLoss("cauchy", 6.0), RobustLoss("none")])
def test_a_solve_started_turned_front_to_back_ends_in_the_convention(loss):
    sim = simulate("intersection_2cam", seed=3, num_frames=1)
    vid = sim.scene.frames[0].vehicle_ids()[0]
    truth = sim.truth[0][vid]
    options = SolveOptions(graph=GraphConfig(shape_prior_loss=loss))
    obs = observations_from_detections(sim.scene.frames[0].detections_of(vid), sim.scene.cameras, options.graph)
    own = solve_observations(obs, options, vid)
    started_turned = solve_observations(obs, options, vid, initial=turned(truth.world_T_vehicle, truth.wireframe))
    assert own.status == started_turned.status == Status.CONVERGED
    assert not turned_front_to_back(started_turned.wireframe.layer_vectors()["wheel"])
    assert rotation_deg(started_turned.world_T_vehicle, truth.world_T_vehicle) < 15.0  # was 179 deg (Cauchy prior)
    if loss.name == "cauchy":  # the heavy-tailed prior: LM goes on from the turned-back point to the same minimum
        assert rotation_deg(started_turned.world_T_vehicle, own.world_T_vehicle) < 0.05
        assert started_turned.final_error == pytest.approx(own.final_error, rel=1e-3)


def test_a_track_whose_first_frame_came_out_turned_is_tracked_the_right_way_round():
    sim = simulate(noise_variant(load_scenario("association_3cam"), **NOISE_LEVELS["hard"]), seed=0)
    scene = dataclasses.replace(sim.scene, frames=[
        dataclasses.replace(f, detections=[d for d in f.detections if d.vehicle == "v1"]) for f in sim.scene.frames[:4]])
    run = track_scene(scene, TrackOptions(covariance=False))
    for f, frame in enumerate(run.frames):
        (vehicle,) = frame.vehicles
        assert vehicle.status == Status.CONVERGED
        assert rotation_deg(vehicle.world_T_vehicle, sim.truth[f]["v1"].world_T_vehicle) < 5.0  # was 178.7-179.9


def test_a_shape_turned_front_to_back_is_not_called_converged(cameras, prius, world_T_vehicle):
    good = VehicleResult("v", Status.CONVERGED, world_T_vehicle=world_T_vehicle, wireframe=prius)
    assert check_estimate(good, cameras.values())[0] == Status.CONVERGED
    pose, shape = turned(world_T_vehicle, prius)
    status, message = check_estimate(dataclasses.replace(good, world_T_vehicle=pose, wireframe=shape), cameras.values())
    assert status == Status.FAILED and "turned front to back" in message
