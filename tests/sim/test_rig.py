"""Camera rigs: look_at, intrinsics from a field of view, pole cameras and intersection rigs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vfactor.sim import intersection_rig, intrinsics_from_hfov, look_at, pole_camera

SIZE = (1280, 720)
CENTRE = np.array([(SIZE[0] - 1) / 2, (SIZE[1] - 1) / 2])


@pytest.mark.parametrize(
    "eye, target",
    [([-14, -11, 7.5], [0, 0, 0]), ([13, 12, 7], [1.5, -0.5, 0.3]), ([0, -20, 9], [0, 0, 0]), ([5, 5, 6], [4, 6, 0])],
)
def test_pole_camera_projects_its_target_to_the_image_centre(eye, target):
    camera = pole_camera("c", eye[:2], eye[2], target=target, image_size=SIZE)
    uv, depth = camera.project(np.array([target], float))
    np.testing.assert_allclose(uv[0], CENTRE, atol=1e-9)
    assert depth[0] == pytest.approx(np.linalg.norm(np.subtract(target, eye)))


def test_look_at_is_a_rotation_with_a_level_horizon_and_up_upward():
    T = look_at([-14, -11, 7.5], [0, 0, 0])
    R = T[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert R[2, 0] == pytest.approx(0.0, abs=1e-12)  # image x axis is horizontal
    assert R[2, 1] < 0  # image y (down) points down in the world
    camera = pole_camera("c", (-14, -11), 7.5, image_size=SIZE)
    uv, _ = camera.project(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    assert uv[1, 1] < uv[0, 1]  # a point above the target appears higher in the image
    assert uv[1, 0] == pytest.approx(uv[0, 0], abs=1e-9)


def test_look_at_rejects_degenerate_directions():
    with pytest.raises(ValueError, match="parallel"):
        look_at([0, 0, 10], [0, 0, 0])
    with pytest.raises(ValueError, match="coincide"):
        look_at([1, 2, 3], [1, 2, 3])


def test_intrinsics_put_the_edge_of_the_field_of_view_at_the_image_border():
    K = intrinsics_from_hfov(60.0, SIZE)
    assert K[0, 0] == K[1, 1]
    x = math.tan(math.radians(30.0))
    assert K[0, 0] * x + K[0, 2] == pytest.approx(SIZE[0] - 0.5)
    assert -K[0, 0] * x + K[0, 2] == pytest.approx(-0.5)
    with pytest.raises(ValueError, match="hfov_deg"):
        intrinsics_from_hfov(180.0, SIZE)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_intersection_rig_places_poles_round_the_centre(n):
    cameras = intersection_rig(n, distance=18.0, height=7.5)
    assert list(cameras) == [f"cam{i}" for i in range(n)]
    for camera in cameras.values():
        c = camera.center
        assert np.hypot(c[0], c[1]) == pytest.approx(18.0)
        assert c[2] == pytest.approx(7.5)
        uv, _ = camera.project(np.zeros((1, 3)))
        np.testing.assert_allclose(uv[0], CENTRE, atol=1e-9)
    if n >= 2:  # the first two stand on opposite corners
        np.testing.assert_allclose(cameras["cam0"].center[:2], -cameras["cam1"].center[:2], atol=1e-9)
