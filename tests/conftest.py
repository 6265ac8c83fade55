"""Shared fixtures: a two-camera rig with small overlap and a vehicle on the road."""

from __future__ import annotations

import os

import gtsam
import numpy as np
import pytest

from vfactor.camera import Camera
from vfactor.wireframe import PRESETS


def look_at(eye, target) -> np.ndarray:
    """4x4 world_T_camera of an OpenCV camera at ``eye`` looking at ``target`` (world z up)."""
    eye = np.asarray(eye, float)
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye
    return T


K = [[900.0, 0.0, 640.0], [0.0, 900.0, 360.0], [0.0, 0.0, 1.0]]


def opencv_pixels(camera: Camera, world: np.ndarray) -> np.ndarray:
    """(N, 2) pixels of world points by OpenCV's own projection of the camera's lens model (the reference)."""
    import cv2

    T = camera.camera_T_world
    rvec, tvec = cv2.Rodrigues(T[:3, :3])[0], T[:3, 3].copy()
    if camera.model == "fisheye":
        uv, _ = cv2.fisheye.projectPoints(np.asarray(world, float).reshape(-1, 1, 3), rvec, tvec, camera.K, camera.dist)
    else:
        uv, _ = cv2.projectPoints(np.asarray(world, float), rvec, tvec, camera.K, camera.dist)
    return uv.reshape(-1, 2)


def assert_projection_jacobian(camera: Camera, camera_p: np.ndarray, h: float = 1e-6) -> None:
    """``Camera.project_camera_points``' Jacobian against central differences at camera points (N, 3)."""
    _, J = camera.project_camera_points(camera_p)
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = h
        plus, _ = camera.project_camera_points(camera_p + step, jacobian=False)
        minus, _ = camera.project_camera_points(camera_p - step, jacobian=False)
        assert np.allclose(J[:, :, axis], (plus - minus) / (2 * h), rtol=1e-6, atol=1e-5)


@pytest.fixture
def cameras() -> dict[str, Camera]:
    """Two pole cameras (7-8 m) on opposite corners, each seeing its own side of the vehicle."""
    return {
        "cam0": Camera("cam0", K, look_at([18, 12, 7], [0, 0, 0]), image_size=(1280, 720)),
        "cam1": Camera("cam1", K, look_at([-18, -12, 8], [0, 0, 0]), dist=[-0.05, 0.01, 0.001, -0.001, 0.0], image_size=(1280, 720)),
    }


@pytest.fixture
def prius():
    return PRESETS["toyota_prius"].wireframe()


@pytest.fixture
def world_T_vehicle():
    return gtsam.Pose3(gtsam.Rot3.Yaw(0.7), np.array([1.0, -0.5, 0.32]))


# ----------------------------------------------------------------------------- fuzzing profiles (tests/test_fuzz.py)
def pytest_addoption(parser):
    parser.addoption("--fuzz-long", action="store_true", default=False,
                     help="run the long fuzzing profile (over 5,000 cases; also VFACTOR_FUZZ=long)")
    parser.addoption("--slow", action="store_true", default=False,
                     help="also run the tests marked slow (statistical checks of several seconds each whose code "
                          "paths quicker tests also run; also VFACTOR_SLOW=1)")


def pytest_configure(config):
    from tests import fuzzing

    fuzzing.configure(long=config.getoption("--fuzz-long"))
    config.addinivalue_line("markers",
                            "slow: a statistical check of several seconds, run with --slow or VFACTOR_SLOW=1")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--slow") or os.environ.get("VFACTOR_SLOW", "") not in ("", "0"):
        return
    skip = pytest.mark.skip(reason="slow: run with --slow (or VFACTOR_SLOW=1)")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
