"""Simulation: placement, detections, determinism, several vehicles, moving vehicles."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vfactor.errors import ScenarioError
from vfactor.keypoints import LAYERS
from vfactor.observations import Scene
from vfactor.sim import (
    Motion,
    NoiseModel,
    footprint,
    footprints_overlap,
    load_scenario,
    redraw_noise,
    simulate,
)

HUBS = list(LAYERS["wheel"])


def _arrays(sim):
    """Everything random in a simulation, as a list of arrays."""
    out = []
    for frame, truth in zip(sim.scene.frames, sim.truth):
        out.append(np.array([frame.t]))
        for d in frame.detections:
            out += [np.array([hash((d.camera, d.vehicle))]), d.keypoints, d.confidence]
        for vid, v in truth.items():
            out += [np.array([hash((vid, v.preset))]), v.world_T_vehicle.matrix(), v.wireframe.vehicle_p_keypoints]
    return out


def _same(a, b) -> bool:
    return len(a) == len(b) and all(x.shape == y.shape and np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b))


@pytest.fixture(scope="module")
def sim2():
    return simulate(load_scenario("intersection_2cam"), seed=5, num_frames=12)


def test_simulation_is_deterministic_and_depends_on_the_seed(sim2):
    scenario = load_scenario("intersection_2cam")
    again = simulate(scenario, seed=5, num_frames=12)
    assert _same(_arrays(sim2), _arrays(again))
    assert not _same(_arrays(sim2), _arrays(simulate(scenario, seed=6, num_frames=12)))
    default = simulate("intersection_2cam")  # a packaged name works too; seed from the scenario
    assert default.seed == scenario.seed and len(default.scene.frames) == scenario.num_frames


def test_redraw_noise_keeps_the_truth_and_draws_new_detections(sim2):
    assert _same(_arrays(redraw_noise(sim2, sim2.seed)), _arrays(sim2))
    other = redraw_noise(sim2, 77)
    assert other.truth is sim2.truth and other.scene.cameras == sim2.scene.cameras
    assert [f.t for f in other.scene.frames] == [f.t for f in sim2.scene.frames]
    assert not _same(_arrays(other), _arrays(sim2))
    with pytest.raises(ValueError, match="noise_seed"):
        redraw_noise(sim2, -1)


def test_earlier_frames_do_not_depend_on_the_number_of_frames(sim2):
    short = simulate(load_scenario("intersection_2cam"), seed=5, num_frames=4)
    assert _same(_arrays(short), _arrays(dataclasses.replace(sim2, scene=Scene(sim2.scene.cameras,
                                                                                 sim2.scene.frames[:4]),
                                                               truth=sim2.truth[:4])))


def test_frames_times_ids_and_presets(sim2):
    scenario = sim2.scenario
    assert isinstance(sim2.scene, Scene) and list(sim2.scene.cameras) == ["cam0", "cam1"]
    assert [f.t for f in sim2.scene.frames] == pytest.approx([0.1 * f for f in range(12)])
    presets = [t["v1"].preset for t in sim2.truth]
    expected = [scenario.vehicles[f % len(scenario.vehicles)] for f in range(12)]  # "cycle" order
    for drawn, name in zip(presets, expected):  # a random car records the PASCAL3D+ model it was drawn from
        assert drawn == name or (name == "random" and drawn.startswith("pascal3d_")), (drawn, name)
    for truth in sim2.truth:
        assert list(truth) == ["v1"]


def test_vehicles_stand_on_the_road_inside_every_image(sim2):
    margin = sim2.scenario.margin_px
    (x0, x1), (y0, y1) = sim2.scenario.region
    for truth in sim2.truth:
        v = truth["v1"]
        T = v.world_T_vehicle
        rpy = T.rotation().rpy()
        assert abs(rpy[0]) < 1e-12 and abs(rpy[1]) < 1e-12
        assert x0 <= T.x() <= x1 and y0 <= T.y() <= y1
        assert T.z() == pytest.approx(v.wheel_radius)
        np.testing.assert_allclose(v.keypoints_world[HUBS].mean(0)[2], v.wheel_radius, atol=1e-9)
        for camera in sim2.scene.cameras.values():
            uv, depth = camera.project(v.keypoints_world)
            assert np.all(depth > 0) and np.all(camera.in_image(uv, margin=-margin))


def test_detections_hold_12_keypoints_nan_where_unseen(sim2):
    for f, frame in enumerate(sim2.scene.frames):
        assert len(frame.detections) == 2
        for d in frame.detections:
            assert d.keypoints.shape == (12, 2) and d.confidence.shape == (12,)
            unseen = d.confidence == 0
            assert np.all(np.isnan(d.keypoints[unseen])) and np.all(np.isfinite(d.keypoints[~unseen]))
            assert np.all((d.confidence[~unseen] >= 0.3) & (d.confidence[~unseen] <= 1.0))
            labels = sim2.detection_truth[f][(d.camera, d.vehicle)]
            np.testing.assert_array_equal(labels.missing, unseen)
            assert sim2.occluded(f, d.camera, d.vehicle) is labels.occluded


def test_the_two_cameras_see_the_vehicle_from_different_sides(sim2):
    # Over the frames, each camera hides some wheels the other one sees.
    differ = 0
    for labels in sim2.detection_truth:
        occ0, occ1 = labels[("cam0", "v1")].occluded, labels[("cam1", "v1")].occluded
        differ += np.any(occ0[HUBS] & ~occ1[HUBS]) and np.any(occ1[HUBS] & ~occ0[HUBS])
    assert differ >= len(sim2.detection_truth) // 2


def test_noiseless_detections_are_the_true_projections():
    sim = simulate(load_scenario("intersection_2cam_noiseless"), num_frames=3)
    for frame, truth in zip(sim.scene.frames, sim.truth):
        for d in frame.detections:
            uv, _ = sim.scene.cameras[d.camera].project(truth[d.vehicle].keypoints_world)
            np.testing.assert_allclose(d.keypoints, uv, atol=1e-9)


def test_several_vehicles_per_frame_do_not_overlap():
    scenario = load_scenario("intersection_multi")
    sim = simulate(scenario, num_frames=4)
    for frame, truth in zip(sim.scene.frames, sim.truth):
        assert list(truth) == ["v1", "v2", "v3"]
        assert frame.vehicle_ids() == ["v1", "v2", "v3"]
        prints = [footprint(v.wireframe, v.world_T_vehicle) for v in truth.values()]
        for i in range(3):
            for j in range(i + 1, 3):
                assert not footprints_overlap(prints[i], prints[j], scenario.min_gap)


def test_a_camera_that_sees_nothing_gives_no_detection():
    scenario = load_scenario("intersection_3cam")
    # Turn cam2 away from the road: it sees no keypoint, and is not required to.
    from vfactor.sim import pole_camera

    cameras = dict(scenario.cameras)
    cameras["cam2"] = pole_camera("cam2", (13.0, -13.0), 8.0, target=(60.0, -60.0, 0.0))
    scenario = dataclasses.replace(scenario, cameras=cameras, visible_in=("cam0", "cam1"))
    sim = simulate(scenario, num_frames=3)
    for frame in sim.scene.frames:
        assert sorted(d.camera for d in frame.detections) == ["cam0", "cam1"]


def test_an_impossible_region_raises_a_scenario_error():
    scenario = dataclasses.replace(load_scenario("intersection_2cam"), region=((80.0, 90.0), (80.0, 90.0)))
    with pytest.raises(ScenarioError) as info:
        simulate(scenario, num_frames=1)
    assert info.value.field == "region"


def test_moving_vehicles_keep_their_shape_and_drive_forward():
    scenario = dataclasses.replace(
        load_scenario("intersection_2cam"), vehicles=("random",), motion=Motion(speed=(4.0, 4.0), yaw_rate=(0.1, 0.1)),
        noise=NoiseModel.noiseless(), num_frames=10,
    )
    sim = simulate(scenario)
    shapes = {t["v1"].wireframe for t in sim.truth}
    assert len(shapes) == 1
    poses = [t["v1"].world_T_vehicle for t in sim.truth]
    for a, b in zip(poses, poses[1:]):
        step = a.between(b)  # in the body frame of a: mostly forward, small left turn
        assert step.translation()[0] == pytest.approx(0.4, abs=0.01)
        assert abs(step.translation()[1]) < 0.03 and step.rotation().yaw() == pytest.approx(0.01)
    assert simulate("intersection_2cam_track", num_frames=6).truth[0]["v1"].preset.startswith("pascal3d_")
