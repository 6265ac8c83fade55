"""Self-occlusion and occlusion by other vehicles."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.keypoints import KEYPOINT_NAMES
from vfactor.sim import VehicleBody, occluded_keypoints, pole_camera, road_pose, self_occluded
from vfactor.wireframe import PRESETS

LEFT_WHEELS, RIGHT_WHEELS = [0, 2], [1, 3]
ROOF = [8, 9, 10, 11]


def _camera_at(pose, vehicle_xy, height):
    """A pole camera at body-frame (x, y) of the vehicle, looking at it."""
    world = pose.transformFrom(np.array([vehicle_xy[0], vehicle_xy[1], 0.0]))
    return pole_camera("c", world[:2], height, target=pose.translation())


@pytest.mark.parametrize("name", ["lincoln_mkz", "toyota_prius", "bmw_x5", "van", "pickup"])
@pytest.mark.parametrize("yaw", [0.0, 1.0, 2.5, 4.0])
def test_a_camera_on_the_left_sees_the_left_wheels_not_the_right_ones(name, yaw):
    preset = PRESETS[name]
    w, r = preset.wireframe(), preset.wheel_radius
    pose = road_pose(2.0, -1.0, yaw, r)
    left = self_occluded(_camera_at(pose, (0.0, 15.0), 7.0), w, pose, r)
    assert not left[LEFT_WHEELS].any() and left[RIGHT_WHEELS].all()
    assert not left[ROOF].any()
    right = self_occluded(_camera_at(pose, (0.5, -15.0), 7.0), w, pose, r)
    assert right[LEFT_WHEELS].all() and not right[RIGHT_WHEELS].any()


def test_a_low_camera_in_front_does_not_see_the_back_lights():
    preset = PRESETS["lincoln_mkz"]
    w, r = preset.wireframe(), preset.wheel_radius
    pose = road_pose(0.0, 0.0, 0.3, r)
    hidden = self_occluded(_camera_at(pose, (15.0, 0.0), 2.0), w, pose, r)
    names = {KEYPOINT_NAMES[i] for i in np.flatnonzero(hidden)}
    assert {"left_back_light", "right_back_light", "left_back_wheel", "right_back_wheel"} <= names
    assert not hidden[[4, 5, 8, 9]].any()  # front lights and windshield top in view


def test_a_camera_high_above_sees_the_whole_roof_and_lights():
    preset = PRESETS["toyota_prius"]
    w, r = preset.wireframe(), preset.wheel_radius
    pose = road_pose(0.0, 0.0, 0.0, r)
    hidden = self_occluded(_camera_at(pose, (0.5, 0.3), 20.0), w, pose, r)
    assert not hidden[4:].any()


def test_another_vehicle_in_the_way_hides_keypoints():
    preset = PRESETS["toyota_prius"]
    w, r = preset.wireframe(), preset.wheel_radius
    far, near = road_pose(0.0, 0.0, 0.0, r), road_pose(0.0, 3.0, 0.0, r)
    camera = pole_camera("c", (0.0, 12.0), 2.5, target=far.translation())
    body_far = VehicleBody.from_vehicle(w, far, r)
    body_near = VehicleBody.from_vehicle(w, near, r)
    alone = occluded_keypoints(camera.center, body_far)
    with_other = occluded_keypoints(camera.center, body_far, [body_near])
    assert not alone[LEFT_WHEELS].any()
    assert with_other[LEFT_WHEELS].all() and with_other.sum() > alone.sum()
    assert np.all(with_other >= alone)


def test_segment_test_is_exact_against_a_box():
    w = PRESETS["toyota_prius"].wireframe()
    body = VehicleBody.from_vehicle(w, road_pose(0, 0, 0, 0.32), 0.32)
    centre = body.world_p_hull.mean(0)
    origin = centre + [0.0, 20.0, 0.0]
    targets = np.array([centre - [0.0, 20.0, 0.0], centre + [0.0, 0.0, 10.0], origin + [1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(body.blocks(origin, targets), [True, False, False])
