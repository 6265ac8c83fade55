"""Camera projection, its Jacobian, OpenCV agreement, validation and calibration files."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vfactor.camera import Camera
from vfactor.errors import CalibrationError

from .conftest import K, look_at

DIST = [-0.1, 0.03, 0.001, -0.002, 0.005]


def make_camera(**kw):
    args = dict(name="c", K=K, world_T_camera=look_at([10, 5, 6], [0, 0, 0]), dist=DIST, image_size=(1280, 720))
    args.update(kw)
    return Camera(**args)


def test_projection_matches_opencv():
    camera = make_camera()
    world = np.random.default_rng(0).uniform(-3, 3, (20, 3))
    uv, depth = camera.project(world)
    T = camera.camera_T_world
    expected, _ = cv2.projectPoints(world, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], camera.K, camera.dist)
    assert np.all(depth > 0)
    assert np.allclose(uv, expected.reshape(-1, 2), atol=1e-8)


@pytest.mark.parametrize("dist", [None, DIST])
def test_projection_jacobian_matches_numerical(dist):
    camera = make_camera(dist=dist)
    camera_p = np.random.default_rng(1).uniform([-2, -1, 5], [2, 1, 20], (10, 3))
    _, J = camera.project_camera_points(camera_p)
    h = 1e-6
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = h
        plus, _ = camera.project_camera_points(camera_p + step, jacobian=False)
        minus, _ = camera.project_camera_points(camera_p - step, jacobian=False)
        assert np.allclose(J[:, :, axis], (plus - minus) / (2 * h), rtol=1e-6, atol=1e-5)


def test_target_projects_to_principal_point():
    camera = make_camera(dist=None)
    uv, _ = camera.project(np.zeros((1, 3)))
    assert np.allclose(uv, [[640, 360]], atol=1e-9)


def test_undistort_inverts_projection():
    camera = make_camera()
    world = np.array([[1.0, 0.5, 0.2], [-1.0, 1.0, 0.0]])
    uv, _ = camera.project(world)
    xy = camera.undistort_pixels(uv)
    cam_p = camera.to_camera(world)
    assert np.allclose(xy, cam_p[:, :2] / cam_p[:, 2:], atol=1e-6)


@pytest.mark.parametrize(
    "kw, field, words",
    [
        (dict(K=[[0, 0, 640], [0, 800, 360], [0, 0, 1]]), "K", "singular"),
        (dict(K=[[800, 0], [0, 800]]), "K", "shape"),
        (dict(K=[[800, 0, np.nan], [0, 800, 360], [0, 0, 1]]), "K", "NaN"),
        (dict(dist=[0.1, 0.2]), "dist", "4, 5, 8, 12 or 14"),
        (dict(world_T_camera=np.diag([1.0, 1.0, -1.0, 1.0])), "world_T_camera", "not a rotation"),
        (dict(world_T_camera=np.eye(3)), "world_T_camera", "shape"),
        (dict(image_size=[1280]), "image_size", "width, height"),
        (dict(name=""), "name", "non-empty"),
    ],
)
def test_invalid_calibration_names_the_field(kw, field, words):
    with pytest.raises(CalibrationError, match=words) as info:
        make_camera(**kw)
    assert info.value.field == field
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize("suffix", [".yaml", ".xml"])
def test_opencv_file_round_trip(tmp_path, suffix):
    camera = make_camera()
    path = tmp_path / f"cam{suffix}"
    camera.to_opencv_file(path)
    loaded = Camera.from_opencv_file(path)
    assert loaded.name == "c"
    assert np.allclose(loaded.K, camera.K) and np.allclose(loaded.dist, camera.dist)
    assert np.allclose(loaded.world_T_camera, camera.world_T_camera)
    assert loaded.image_size == (1280, 720)


def test_opencv_file_with_rvec_tvec(tmp_path):
    camera = make_camera()
    path = tmp_path / "calib.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("camera_matrix", camera.K)
    fs.write("distortion_coefficients", camera.dist)
    T = camera.camera_T_world
    fs.write("rvec", cv2.Rodrigues(T[:3, :3])[0])
    fs.write("tvec", T[:3, 3].reshape(3, 1))
    fs.release()
    loaded = Camera.from_opencv_file(path, name="pole3")
    assert loaded.name == "pole3"
    assert np.allclose(loaded.world_T_camera, camera.world_T_camera, atol=1e-9)


def test_opencv_file_errors_name_file_and_node(tmp_path):
    path = tmp_path / "bad.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("distortion_coefficients", np.zeros(5))
    fs.release()
    with pytest.raises(CalibrationError, match="camera_matrix: missing"):
        Camera.from_opencv_file(path)
    with pytest.raises(CalibrationError, match="file not found"):
        Camera.from_opencv_file(tmp_path / "nope.yaml")
    junk = tmp_path / "junk.yaml"
    junk.write_text("this: [is not: opencv")
    with pytest.raises(CalibrationError):
        Camera.from_opencv_file(junk)
