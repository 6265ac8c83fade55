"""A keypoint's sigma follows the vehicle's size in the image, not the box of the few keypoints a detector kept.

A detector keeps only the keypoints inside the image of a vehicle the image
border cuts; the box around them can be a small part of the vehicle (with one
keypoint, none at all: the 1 px floor), so those keypoints were weighed as if
several times more precise than they are. The tracker sizes them by the
vehicle where it takes the vehicle to be (its prediction), batch smoothing and
the one-frame solve by the vehicle their first solution puts in each image
(docs/factors.md, "Keypoint noise sized by the vehicle").
"""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from vfactor.evaluation import held_out_scene_model
from vfactor.graph import (MAX_SIZE_IN_IMAGES, RESIZE_SHARE, GraphConfig, observations_from_detections,
                           resized_observations, sigma_change, sized_observations, vehicle_image_sizes)
from vfactor.metrics import ray_nees
from vfactor.observations import Detection
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions, solve_observations, solve_vehicle
from vfactor.track import TrackOptions, smooth_scene, track_scene
from vfactor.wireframe import Wireframe


def _exact_detection(sim, frame: int, vehicle: str, camera: str) -> Detection:
    """The vehicle's 12 true projections in ``camera``, confidence 1."""
    uv, _ = sim.scene.cameras[camera].project(sim.truth[frame][vehicle].keypoints_world)
    return Detection(camera, vehicle, uv, np.ones(12))


def test_a_cut_detection_sized_by_the_vehicle_gets_the_sigma_of_the_whole_vehicle():
    sim = simulate(load_scenario("library_tracks_2cam"), seed=3)
    vid = sim.scene.frames[0].vehicle_ids()[0]
    camera = sim.scene.frames[0].detections_of(vid)[0].camera
    whole = _exact_detection(sim, 0, vid, camera)
    cut = dataclasses.replace(whole, confidence=np.where(np.arange(12) < 3, 1.0, 0.0))  # three keypoints kept
    config = GraphConfig()
    truth = sim.truth[0][vid]
    sizes = vehicle_image_sizes(sim.scene.cameras, truth.world_T_vehicle, truth.wireframe, [camera])
    assert sizes[camera] == np.linalg.norm(np.ptp(whole.keypoints, axis=0))  # all 12 in front of the camera

    def sigma(detection, vehicle_sizes=None):
        obs = observations_from_detections([detection], sim.scene.cameras, config, vehicle_sizes)
        return 1.0 / obs.sqrt_information[:, 0, 0]

    whole_sigma = config.relative_pixel_sigma * sizes[camera]
    assert np.allclose(sigma(whole), whole_sigma)
    assert np.all(sigma(cut) < 0.8 * whole_sigma)  # the box of the three kept: the vehicle's noise understated
    assert np.allclose(sigma(cut, sizes), whole_sigma)
    assert np.allclose(sigma(whole, {camera: 1.0}), whole_sigma)  # never smaller than the box of the seen keypoints
    roi = (0.0, 0.0, 30.0, 40.0)  # a detector's box is the detector's word for the vehicle's size
    assert np.allclose(sigma(dataclasses.replace(cut, roi=roi), sizes), config.relative_pixel_sigma * 50.0)
    world_T_camera = gtsam.Pose3(np.asarray(sim.scene.cameras[camera].world_T_camera))
    behind = world_T_camera.compose(gtsam.Pose3(gtsam.Rot3(), np.array([0.0, 0.0, -10.0])))
    assert camera not in vehicle_image_sizes(sim.scene.cameras, behind, truth.wireframe)  # no size behind it
    straddling = world_T_camera.compose(gtsam.Pose3(gtsam.Rot3(), np.array([0.0, 0.0, 0.5])))  # through its plane
    width, height = sim.scene.cameras[camera].image_size
    assert vehicle_image_sizes(sim.scene.cameras, straddling, truth.wireframe)[camera] == \
        MAX_SIZE_IN_IMAGES * np.hypot(width, height)


@pytest.mark.parametrize("method", ["isam2", "batch"])
def test_tracks_keep_one_camera_depths_within_their_covariance(method):
    """Vehicles entering or leaving a view, seen by one camera there (library_tracks_2cam seeds 101 and 105): sized
    by the box of their kept keypoints the cut views pulled the one-camera poses along the camera's ray, whitened
    squares 4.65 and 5.34 on average for the tracker's final estimates, 3.44 and 4.80 for batch smoothing
    (consistent: 1); sized by the vehicle 0.88 and 0.69, 1.12 and 0.57."""
    for seed in (101, 105):
        sim = simulate(load_scenario("library_tracks_2cam"), seed=seed)
        model = held_out_scene_model(sim)
        frames = (track_scene(sim.scene, TrackOptions(), prior=model).frames if method == "isam2"
                  else smooth_scene(sim.scene, TrackOptions(), prior=model))
        along = []
        for f, frame in enumerate(frames):
            for v in frame.vehicles:
                cameras = {d.camera for d in sim.scene.frames[f].detections if d.vehicle == v.id}
                if v.ok and len(cameras) == 1:
                    centre = sim.scene.cameras[cameras.pop()].center
                    along.append(ray_nees(v.world_T_vehicle, v.pose_covariance, sim.truth[f][v.id].world_T_vehicle,
                                          centre)[1])
        assert len(along) >= 5 and np.mean(along) < 2.0, (seed, np.mean(along), len(along))


def test_resized_observations_measure_the_change_without_stacking_and_stack_only_beyond_the_share():
    """resized_observations: the change is sigma_change's between the plain and the sized stacking, to the bit, on
    views cut by the image border and whole ones, with and without covariances of the keypoints' own (kept as
    they are); the sized observations come back only where the change is beyond the share."""
    sim = simulate(load_scenario("library_tracks_2cam"), seed=3, num_frames=12)
    config = GraphConfig()
    changes = []
    for f, frame in enumerate(sim.scene.frames):
        for vid in frame.vehicle_ids():
            truth = sim.truth[f][vid]
            wireframe = Wireframe(truth.world_T_vehicle.transformTo(np.asarray(truth.keypoints_world).T).T)
            detections = list(frame.detections_of(vid))
            own = [dataclasses.replace(d, covariance=np.where((np.arange(12)[:, None, None] % 3 == 0) | (i == 0),
                                                              4.0 * np.eye(2), np.nan))
                   for i, d in enumerate(detections)]  # the first detection's keypoints all have their own
            for dets in (detections, own):
                plain = observations_from_detections(dets, sim.scene.cameras, config)
                sized = sized_observations(dets, sim.scene.cameras, config, truth.world_T_vehicle, wireframe)
                expected = sigma_change(plain, sized)
                for share in (RESIZE_SHARE, 0.0):
                    got, change = resized_observations(dets, sim.scene.cameras, config, truth.world_T_vehicle,
                                                       wireframe, share)
                    assert change == expected
                    if expected > share:
                        np.testing.assert_array_equal(got.sqrt_information, sized.sqrt_information)
                    else:
                        assert got is None
                changes.append(expected)
    assert max(changes) > RESIZE_SHARE and min(changes) <= RESIZE_SHARE  # both ways seen


def test_a_one_frame_solve_sizes_a_cut_views_keypoints_by_the_vehicle_it_finds():
    """solve_vehicle refines at sigmas sized by its first solution where that moves them by more than
    RESIZE_SHARE (a camera seeing few keypoints of a vehicle entering its view), and only there: the one-frame
    evaluation's vehicles, all in view, are solved as before."""
    sim = simulate(load_scenario("library_tracks_2cam"), seed=3)
    resized = []
    for f, frame in enumerate(sim.scene.frames[:12]):
        for vid in frame.vehicle_ids():
            detections = frame.detections_of(vid)
            result = solve_vehicle(detections, sim.scene.cameras, SolveOptions(covariance=False))
            if "resized" in result.extras:
                assert result.extras["resized"] > RESIZE_SHARE
                kept = [int((d.confidence > 0).sum()) for d in detections]
                resized.append(min(kept))
    assert resized and min(resized) <= 6, resized  # views of a few keypoints among them
    sim = simulate(load_scenario("library_2cam"), seed=20, num_frames=3)
    for frame in sim.scene.frames:
        for vid in frame.vehicle_ids():
            detections = frame.detections_of(vid)
            result = solve_vehicle(detections, sim.scene.cameras, SolveOptions(covariance=False))
            plain = solve_observations(observations_from_detections(detections, sim.scene.cameras),
                                       SolveOptions(covariance=False), vid)
            assert "resized" not in result.extras
            assert result.world_T_vehicle.equals(plain.world_T_vehicle, 1e-9)
