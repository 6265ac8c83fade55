"""Camera projection, its Jacobian, OpenCV agreement, validation and calibration files."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vfactor.camera import Camera
from vfactor.errors import CalibrationError

from .conftest import K, assert_projection_jacobian, look_at, opencv_pixels

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
    assert_projection_jacobian(camera, np.random.default_rng(1).uniform([-2, -1, 5], [2, 1, 20], (10, 3)))


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


# ----------------------------------------------------------------------------- lens models
#: Coefficients of every OpenCV pinhole length, and a fisheye lens (moderately strong, realistic signs).
D14 = [-0.21, 0.05, 0.0012, -0.0021, 0.011, 0.09, -0.018, 0.004, 0.0011, -0.0006, 0.0019, 0.0004, 0.021, -0.016]
LENSES = [
    ("pinhole", D14[:4]),
    ("pinhole", D14[:5]),
    ("pinhole", D14[:8]),
    ("pinhole", D14[:12]),
    ("pinhole", D14),
    ("fisheye", [0.04, -0.012, 0.003, -0.0008]),
    ("fisheye", [0.0, 0.0, 0.0, 0.0]),
]
LENS_IDS = [f"{m}{len(d)}" + ("_zero" if not any(d) else "") for m, d in LENSES]


@pytest.mark.parametrize("model, dist", LENSES, ids=LENS_IDS)
def test_every_lens_model_matches_opencv(model, dist):
    camera = make_camera(model=model, dist=dist)
    world = np.random.default_rng(2).uniform(-4, 4, (40, 3))
    uv, depth = camera.project(world)
    assert np.all(depth > 0)
    assert np.allclose(uv, opencv_pixels(camera, world), atol=1e-8)


@pytest.mark.parametrize("model, dist", LENSES, ids=LENS_IDS)
def test_every_lens_model_jacobian_matches_numerical(model, dist):
    camera = make_camera(model=model, dist=dist, K=[[900.0, 2.5, 640.0], [0.0, 880.0, 360.0], [0.0, 0.0, 1.0]])
    camera_p = np.random.default_rng(3).uniform([-3, -2, 3], [3, 2, 12], (20, 3))
    camera_p[0] = [0.0, 0.0, 5.0]  # on the optical axis (the fisheye scale's limit)
    camera_p[1] = [1e-9, -2e-9, 4.0]
    assert_projection_jacobian(camera, camera_p)


@pytest.mark.parametrize("model, dist", LENSES, ids=LENS_IDS)
def test_undistort_inverts_every_lens_model(model, dist):
    camera = make_camera(model=model, dist=dist, K=[[900.0, 3.0, 640.0], [0.0, 900.0, 360.0], [0.0, 0.0, 1.0]])
    camera_p = np.random.default_rng(4).uniform([-2, -1.2, 4], [2, 1.2, 9], (30, 3))
    uv, _ = camera.project_camera_points(camera_p, jacobian=False)
    assert np.allclose(camera.undistort_pixels(uv), camera_p[:, :2] / camera_p[:, 2:], atol=1e-9)


def test_tilt_matrix_is_opencv_s():
    """cv2.projectPoints with only tauX, tauY against tilt_matrix applied by hand (an independent route)."""
    from vfactor.camera import tilt_matrix

    d = np.zeros(14)
    d[12:] = [0.03, -0.02]
    camera_p = np.random.default_rng(5).uniform([-1, -1, 4], [1, 1, 8], (10, 3))
    expected, _ = cv2.projectPoints(camera_p, np.zeros(3), np.zeros(3), np.array(K), d)
    h = np.column_stack([camera_p[:, :2] / camera_p[:, 2:], np.ones(10)]) @ tilt_matrix(0.03, -0.02).T
    xy = h[:, :2] / h[:, 2:]
    assert np.allclose(xy * 900.0 + [640.0, 360.0], expected.reshape(-1, 2), atol=1e-9)


def test_lens_model_and_distortion_lengths_are_checked():
    with pytest.raises(CalibrationError, match="pinhole, fisheye") as info:
        make_camera(model="omni")
    assert info.value.field == "model"
    with pytest.raises(CalibrationError, match="4 numbers \\[k1, k2, k3, k4\\] \\(fisheye") as info:
        make_camera(model="fisheye", dist=DIST)
    assert info.value.field == "dist"
    for n in (6, 7, 9, 13, 15):
        with pytest.raises(CalibrationError, match=f"got {n} entries"):
            make_camera(dist=np.zeros(n))
    assert make_camera(model="fisheye", dist=None).dist.tolist() == [0.0] * 4
    assert make_camera(dist=DIST[:4]).dist.tolist() == DIST[:4] + [0.0]
    assert make_camera(model="fisheye", dist=[0, 0, 0, 0]).has_distortion  # equidistant is not the pinhole


def test_to_dict_writes_the_model_and_pnp_inputs_follow_it():
    fisheye = make_camera(model="fisheye", dist=[0.04, -0.01, 0.0, 0.0])
    assert fisheye.to_dict()["model"] == "fisheye" and len(fisheye.to_dict()["dist"]) == 4
    assert make_camera().to_dict()["model"] == "pinhole"
    world = np.random.default_rng(6).uniform(-2, 2, (8, 3))
    uv, _ = fisheye.project(world)
    points, K_pnp, dist, scale = fisheye.pnp_inputs(uv)
    assert np.allclose(K_pnp, np.eye(3)) and dist is None and scale == 900.0
    cam_p = fisheye.to_camera(world)
    assert np.allclose(points, cam_p[:, :2] / cam_p[:, 2:], atol=1e-9)
    pinhole = make_camera()
    points, K_pnp, dist, scale = pinhole.pnp_inputs(uv)
    assert np.array_equal(points, uv) and np.array_equal(K_pnp, pinhole.K) and scale == 1.0


@pytest.mark.parametrize("model, dist", [LENSES[4], LENSES[5]], ids=[LENS_IDS[4], LENS_IDS[5]])
def test_pnp_recovers_the_pose_through_every_lens(model, dist):
    from vfactor.baselines.pnp import camera_pnp
    from vfactor.factors.projection import KeypointObservations
    from vfactor.wireframe import PRESETS

    import gtsam

    camera = make_camera(model=model, dist=dist)
    shape = PRESETS["hatchback"].wireframe()
    pose = gtsam.Pose3(gtsam.Rot3.Yaw(0.4), np.array([0.5, -0.3, 0.3]))
    uv, _ = camera.project(shape.in_world(pose))
    obs = KeypointObservations((camera,), np.zeros(12, int), np.arange(12), uv, np.tile(np.eye(2), (12, 1, 1)))
    found = camera_pnp(obs, 0, shape.vehicle_p_keypoints)
    assert found is not None
    assert np.allclose(found.matrix(), pose.matrix(), atol=1e-6)


def test_crop_camera_keeps_the_lens():
    from vfactor.render.dataset import crop_camera

    camera = make_camera(model="fisheye", dist=[0.04, -0.01, 0.002, 0.0])
    crop = crop_camera(camera, (300, 200, 556, 456), 64)
    world = np.array([[0.3, -0.2, 0.5]])
    uv, _ = camera.project(world)
    uv_crop, _ = crop.project(world)
    assert crop.model == "fisheye"
    assert np.allclose(uv_crop, 0.25 * (uv + 0.5 - [300, 200]) - 0.5, atol=1e-9)
