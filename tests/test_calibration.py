"""Calibration files (vfactor.calibration): each format as real tools write it, errors, and scenes by file."""

from __future__ import annotations

import json
import zlib
import textwrap

import cv2
import numpy as np
import pytest

from vfactor.calibration import decompose_projection_matrix, detect_format, load_calibration, read_calibration
from vfactor.camera import Camera
from vfactor.errors import CalibrationError, SceneError
from vfactor.scene import load_scene, save_scene, scene_to_dict
from vfactor.sim import simulate
from vfactor.solve import solve_scene

from .conftest import look_at

WORLD_T_CAMERA = look_at([12.0, -9.0, 6.5], [0.0, 0.0, 0.5])


def num(value) -> str:
    """A number as a tool writes it: the shortest text that reads back to the same float."""
    return repr(float(value))

# ----------------------------------------------------------------------------- fixtures, as the tools write them
#: cv2.FileStorage of a fisheye calibration (cv2.fisheye.calibrate), with the pose as camera_T_world.
OPENCV_FISHEYE = """%YAML:1.0
---
camera_name: "lobby"
image_width: 1920
image_height: 1080
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 7.1234500000000003e+02, 0., 9.6012000000000000e+02, 0.,
       7.1098000000000002e+02, 5.4007000000000005e+02, 0., 0., 1. ]
distortion_model: fisheye
distortion_coefficients: !!opencv-matrix
   rows: 4
   cols: 1
   dt: d
   data: [ 4.1200000000000001e-02, -1.1900000000000001e-02,
       2.8999999999999998e-03, -7.9999999999999993e-04 ]
"""

#: The same file format in XML, 14 coefficients (cv2.calibrateCamera with CALIB_RATIONAL_MODEL |
#: CALIB_THIN_PRISM_MODEL | CALIB_TILTED_MODEL), pose as world_T_camera.
D14 = [-0.21, 0.05, 0.0012, -0.0021, 0.011, 0.09, -0.018, 0.004, 0.0011, -0.0006, 0.0019, 0.0004, 0.021, -0.016]
OPENCV_XML_14 = """<?xml version="1.0"?>
<opencv_storage>
<image_width>1280</image_width>
<image_height>720</image_height>
<camera_matrix type_id="opencv-matrix">
  <rows>3</rows>
  <cols>3</cols>
  <dt>d</dt>
  <data>
    900. 0. 640. 0. 905. 360. 0. 0. 1.</data></camera_matrix>
<distortion_coefficients type_id="opencv-matrix">
  <rows>1</rows>
  <cols>14</cols>
  <dt>d</dt>
  <data>
    """ + " ".join(num(v) for v in D14) + """</data></distortion_coefficients>
<world_T_camera type_id="opencv-matrix">
  <rows>4</rows>
  <cols>4</cols>
  <dt>d</dt>
  <data>
    """ + " ".join(num(v) for v in WORLD_T_CAMERA.ravel()) + """</data></world_T_camera>
</opencv_storage>
"""

#: ROS camera_calibration's ost.yaml (sensor_msgs/CameraInfo), rational_polynomial.
ROS_RATIONAL = """image_width: 1280
image_height: 720
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [898.765432, 0.000000, 641.234567, 0.000000, 899.123456, 359.876543, 0.000000, 0.000000, 1.000000]
distortion_model: rational_polynomial
distortion_coefficients:
  rows: 1
  cols: 8
  data: [-0.210000, 0.050000, 0.001200, -0.002100, 0.011000, 0.090000, -0.018000, 1e-05]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.000000, 0.000000, 0.000000, 0.000000, 1.000000, 0.000000, 0.000000, 0.000000, 1.000000]
projection_matrix:
  rows: 3
  cols: 4
  data: [812.345678, 0.000000, 640.123456, 0.000000, 0.000000, 850.987654, 360.456789, 0.000000, 0.000000, 0.000000, 1.000000, 0.000000]
"""

#: Kalibr's camchain.yaml of two cameras (a pinhole-radtan and a pinhole-equidistant one).
KALIBR_CHAIN = """cam0:
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
  - [0.9999972564779, 0.002312067192424, 0.000376008102415, -0.110073808127187]
  - [-0.002317135723281, 0.999898048506644, 0.014089835846683, 0.000399121547014]
  - [-0.000343393120525, -0.014090668452714, 0.999900662637729, -0.000853702503357]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [-0.0125, 0.0031, -0.0004, 0.0001]
  distortion_model: equidistant
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
  rostopic: /cam1/image_raw
"""


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text) if not text.startswith("%") else text)
    return path


# ----------------------------------------------------------------------------- each reader
def test_opencv_fisheye_with_camera_T_world(tmp_path):
    camera_T_world = np.linalg.inv(WORLD_T_CAMERA)
    text = OPENCV_FISHEYE + "camera_T_world: !!opencv-matrix\n   rows: 4\n   cols: 4\n   dt: d\n   data: [ " + \
        ", ".join(num(v) for v in camera_T_world.ravel()) + " ]\n"
    path = write(tmp_path, "lobby.yaml", text)
    assert detect_format(path) == "opencv"
    camera = load_calibration(path, "pole7")
    assert camera.name == "pole7"  # the caller's, not the file's camera_name nor its stem
    assert camera.model == "fisheye" and camera.image_size == (1920, 1080)
    assert np.allclose(camera.K, [[712.345, 0, 960.12], [0, 710.98, 540.07], [0, 0, 1]])
    assert np.allclose(camera.dist, [0.0412, -0.0119, 0.0029, -0.0008])
    assert np.allclose(camera.world_T_camera, WORLD_T_CAMERA, atol=1e-12)
    # the legacy reader keeps its default name (camera_name), through the same implementation
    assert Camera.from_opencv_file(path).name == "lobby"


def test_opencv_xml_with_14_coefficients_round_trips(tmp_path):
    path = write(tmp_path, "cam.xml", OPENCV_XML_14)
    camera = load_calibration(path, "c")
    assert camera.dist.tolist() == D14 and camera.model == "pinhole"
    assert np.array_equal(camera.world_T_camera, WORLD_T_CAMERA)
    camera.to_opencv_file(tmp_path / "again.yaml")
    again = load_calibration(tmp_path / "again.yaml", "c")
    assert again.dist.tolist() == D14 and np.array_equal(again.K, camera.K)
    fisheye = Camera("f", camera.K, WORLD_T_CAMERA, dist=[0.01, 0.0, 0.0, 0.0], model="fisheye")
    fisheye.to_opencv_file(tmp_path / "f.yaml")
    assert load_calibration(tmp_path / "f.yaml", "f").model == "fisheye"


def test_ros_camera_info(tmp_path):
    path = write(tmp_path, "ost.yaml", ROS_RATIONAL)
    assert detect_format(path) == "ros"
    calibration = read_calibration(path)
    assert calibration.world_T_camera is None and calibration.file_camera_name == "narrow_stereo"
    camera = load_calibration(path, "east", world_T_camera=WORLD_T_CAMERA)
    assert camera.name == "east" and camera.image_size == (1280, 720) and camera.model == "pinhole"
    assert np.allclose(camera.K, [[898.765432, 0, 641.234567], [0, 899.123456, 359.876543], [0, 0, 1]])
    assert camera.dist.tolist() == [-0.21, 0.05, 0.0012, -0.0021, 0.011, 0.09, -0.018, 1e-05]
    # the raw image's K, not the rectified projection_matrix
    with pytest.raises(CalibrationError, match="missing extrinsic.*ROS|missing extrinsic") as info:
        load_calibration(path, "east")
    assert info.value.field == f"{path}:world_T_camera"
    equidistant = ROS_RATIONAL.replace("rational_polynomial", "equidistant").replace("cols: 8", "cols: 4").replace(
        ", 0.011000, 0.090000, -0.018000, 1e-05", "")
    camera = load_calibration(write(tmp_path, "fish.yaml", equidistant), "f", world_T_camera=WORLD_T_CAMERA)
    assert camera.model == "fisheye" and camera.dist.tolist() == [-0.21, 0.05, 0.0012, -0.0021]


def test_kalibr_camchain(tmp_path):
    path = write(tmp_path, "camchain.yaml", KALIBR_CHAIN)
    assert detect_format(path) == "kalibr"
    cam1 = load_calibration(path, "west", world_T_camera=WORLD_T_CAMERA, chain_camera="cam1")
    assert cam1.name == "west" and cam1.model == "fisheye" and cam1.image_size == (752, 480)
    assert np.allclose(cam1.K, [[457.587, 0, 379.999], [0, 456.134, 255.238], [0, 0, 1]])
    assert cam1.dist.tolist() == [-0.0125, 0.0031, -0.0004, 0.0001]
    cam0 = load_calibration(path, "cam0", world_T_camera=WORLD_T_CAMERA, chain_camera="cam0")
    assert cam0.model == "pinhole" and cam0.dist.tolist() == [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0]
    with pytest.raises(CalibrationError, match=r"holds 2 cameras \(cam0, cam1\)"):
        load_calibration(path, "cam0", world_T_camera=WORLD_T_CAMERA)  # never guessed from the name
    with pytest.raises(CalibrationError, match="it holds cam0, cam1") as info:
        load_calibration(path, "x", world_T_camera=WORLD_T_CAMERA, chain_camera="cam7")
    assert info.value.field == f"{path}:cam7"


@pytest.mark.parametrize("how", ["text", "json", "npy"])
def test_projection_matrix_decomposes_and_reprojects(tmp_path, how):
    K = np.array([[1210.5, 1.7, 655.25], [0.0, 1195.0, 371.5], [0.0, 0.0, 1.0]])
    camera_T_world = np.linalg.inv(WORLD_T_CAMERA)
    P = -2.5 * K @ camera_T_world[:3]  # any scale, either sign
    if how == "text":
        path = tmp_path / "P.txt"
        path.write_text("# P = K [R | t], world -> pixels\n" + "\n".join(" ".join(num(v) for v in row) for row in P))
    elif how == "json":
        path = tmp_path / "P.json"
        path.write_text(json.dumps({"P": P.tolist(), "image_size": [1280, 720]}))
    else:
        path = tmp_path / "P.npy"
        np.save(path, P)
    assert detect_format(path) == "projection"
    camera = load_calibration(path, "dlt")
    assert np.allclose(camera.K, K, rtol=1e-12, atol=1e-9) and camera.K[1, 0] == 0
    assert np.allclose(camera.world_T_camera, WORLD_T_CAMERA, atol=1e-9)
    assert camera.image_size == ((1280, 720) if how == "json" else None)
    world = np.random.default_rng(0).uniform(-5, 5, (30, 3))
    uv, depth = camera.project(world)
    h = np.column_stack([world, np.ones(30)]) @ P.T
    assert np.all(depth > 0) and np.allclose(uv, h[:, :2] / h[:, 2:], atol=1e-8)


def test_decomposition_agrees_with_opencv():
    rng = np.random.default_rng(1)
    for _ in range(5):
        K = np.array([[rng.uniform(300, 3000), rng.uniform(-5, 5), rng.uniform(100, 900)],
                      [0.0, rng.uniform(300, 3000), rng.uniform(100, 900)], [0.0, 0.0, 1.0]])
        R = cv2.Rodrigues(rng.normal(0, 1.5, 3))[0]
        P = rng.uniform(0.1, 10) * K @ np.column_stack([R, rng.normal(0, 10, 3)])
        ours, camera_T_world = decompose_projection_matrix(P)
        theirs, R_cv, C = cv2.decomposeProjectionMatrix(P)[:3]
        assert np.allclose(ours, theirs / theirs[2, 2], rtol=1e-9)
        assert np.allclose(camera_T_world[:3, :3], R, atol=1e-9)
        assert np.allclose(-camera_T_world[:3, :3].T @ camera_T_world[:3, 3], C[:3, 0] / C[3, 0], atol=1e-7)


# ----------------------------------------------------------------------------- errors name file and node
@pytest.mark.parametrize(
    "name, text, fmt, node, words",
    [
        ("ros_as_opencv", ROS_RATIONAL, "opencv", "camera_matrix", "ROS camera_info"),
        ("kalibr_as_opencv", KALIBR_CHAIN, "opencv", "", "Kalibr camchain"),
        ("opencv_no_K", "%YAML:1.0\n---\nimage_width: 10\nimage_height: 10\n", None, "camera_matrix", "missing"),
        ("opencv_model", OPENCV_FISHEYE.replace("fisheye", "omni"), None, "distortion_model", "got the string 'omni'"),
        ("opencv_dist_5_fisheye", OPENCV_FISHEYE.replace("rows: 4\n   cols: 1", "rows: 1\n   cols: 5").replace(
            "-7.9999999999999993e-04 ]", "-7.9999999999999993e-04, 0. ]"), None, "distortion_coefficients",
         "4 numbers [k1, k2, k3, k4] (fisheye model), got 5 entries"),
        ("ros_rows", ROS_RATIONAL.replace("rows: 3\n  cols: 3", "rows: 100000\n  cols: 3", 1), None, "camera_matrix",
         "rows: expected an integer from 1 to 16"),
        ("ros_data", ROS_RATIONAL.replace("0.000000, 0.000000, 1.000000]", "1.000000]", 1), None, "camera_matrix",
         "3 x 3 = 9 numbers, got a list of 7"),
        ("ros_string", ROS_RATIONAL.replace("898.765432", "'wide'"), None, "camera_matrix", "the string 'wide' at [0]"),
        ("ros_nan", ROS_RATIONAL.replace("898.765432", ".nan"), None, "camera_matrix", "got nan at [0]"),
        ("ros_model", ROS_RATIONAL.replace("rational_polynomial", "kannala_brandt"), None, "distortion_model",
         "plumb_bob, rational_polynomial, equidistant, fisheye"),
        ("ros_count", ROS_RATIONAL.replace("rational_polynomial", "plumb_bob"), None, "distortion_coefficients",
         "4 or 5 coefficients for distortion_model plumb_bob, got 8"),
        ("ros_width", ROS_RATIONAL.replace("image_width: 1280", "image_width: -3"), None, "image_width", "got -3"),
        ("ros_K", ROS_RATIONAL.replace("898.765432", "0.0"), None, "camera_matrix", "focal lengths must be > 0"),
        ("ros_yaml", ROS_RATIONAL.replace("rows: 1\n", "rows: [1\n"), "ros", "", "not valid YAML"),
        ("kalibr_intrinsics", KALIBR_CHAIN.replace("[458.654, 457.296, 367.215, 248.375]", "[458.654, 457.296]"), None,
         "cam0.intrinsics", "expected [fu, fv, pu, pv]"),
        ("kalibr_model", KALIBR_CHAIN.replace("camera_model: pinhole", "camera_model: omni", 1), None,
         "cam0.camera_model", "got the string 'omni'"),
        ("kalibr_dist", KALIBR_CHAIN.replace("distortion_model: radtan", "distortion_model: fov"), None,
         "cam0.distortion_model", "radtan, none, equidistant"),
        ("projection_short", "1 0 0 0\n0 1 0 0\n0 0 1\n", "projection", "P", "3 lines of 4 numbers"),
        ("projection_singular", "1 0 0 0\n0 1 0 0\n0 0 0 1\n", None, "P", "singular"),
        ("projection_json", '{"P": [[1, 0, 0, 0], [0, 1, 0, 0]], "fx": 3}', None, "fx", "unknown key"),
        ("unknown", "hello: world\n", None, "", "unknown calibration format"),
        ("binary", "\udcff", None, "", None),
    ],
)
def test_bad_files_raise_a_calibration_error_naming_file_and_node(tmp_path, name, text, fmt, node, words):
    path = tmp_path / f"{name}.yaml"
    if text == "\udcff":
        path.write_bytes(b"\xff\xfe\x00 not text")
    else:
        path.write_text(text)
    chain = "cam0" if "kalibr" in name and fmt is None else None
    with pytest.raises(CalibrationError) as info:
        load_calibration(path, "c", format=fmt, world_T_camera=None if "opencv" in name else WORLD_T_CAMERA,
                         chain_camera=chain)
    error = info.value
    assert error.field == (f"{path}:{node}" if node else str(path)), str(error)
    if words:
        assert words in error.problem, str(error)
    assert "\n" not in str(error) and type(error) is CalibrationError


def test_kalibr_relative_pose_is_checked(tmp_path):
    path = write(tmp_path, "chain.yaml", KALIBR_CHAIN.replace("- [0.0, 0.0, 0.0, 1.0]", "- [0.0, 0.0, 0.0]"))
    with pytest.raises(CalibrationError, match="4x4 matrix") as info:
        load_calibration(path, "c", world_T_camera=WORLD_T_CAMERA, chain_camera="cam1")
    assert info.value.field == f"{path}:cam1.T_cn_cnm1"


def test_the_name_comes_from_the_caller_and_the_extrinsic_once(tmp_path):
    path = write(tmp_path, "cam0.yaml", OPENCV_FISHEYE)
    with pytest.raises(CalibrationError, match="non-empty string") as info:
        load_calibration(path, None, world_T_camera=WORLD_T_CAMERA)
    assert info.value.field == "name"
    xml = write(tmp_path, "cam.xml", OPENCV_XML_14)
    with pytest.raises(CalibrationError, match="give it once") as info:
        load_calibration(xml, "c", world_T_camera=WORLD_T_CAMERA)
    assert info.value.field == f"{xml}:world_T_camera"
    with pytest.raises(CalibrationError, match="only a Kalibr camchain"):
        load_calibration(xml, "c", chain_camera="cam0")
    with pytest.raises(CalibrationError, match="file not found"):
        load_calibration(tmp_path / "nope.yaml", "c")
    big = tmp_path / "big.yaml"
    big.write_bytes(b"#" * ((1 << 20) + 1))
    with pytest.raises(CalibrationError, match="too large"):
        load_calibration(big, "c")


# ----------------------------------------------------------------------------- scenes by file
def _camera_files(camera: Camera, folder, stem: str) -> dict[str, dict]:
    """Scene entries giving ``camera`` by a file of each format (written as the tools write them)."""
    K, d = camera.K, camera.dist
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    w, h = camera.image_size
    camera.to_opencv_file(folder / f"{stem}.yaml")
    ros = textwrap.dedent(f"""\
        image_width: {w}
        image_height: {h}
        camera_name: {stem}_ros
        camera_matrix:
          rows: 3
          cols: 3
          data: [{num(fx)}, 0.0, {num(cx)}, 0.0, {num(fy)}, {num(cy)}, 0.0, 0.0, 1.0]
        distortion_model: plumb_bob
        distortion_coefficients:
          rows: 1
          cols: 5
          data: [{", ".join(num(v) for v in d)}]
        rectification_matrix:
          rows: 3
          cols: 3
          data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        projection_matrix:
          rows: 3
          cols: 4
          data: [{num(fx)}, 0.0, {num(cx)}, 0.0, 0.0, {num(fy)}, {num(cy)}, 0.0, 0.0, 0.0, 1.0, 0.0]
        """)
    (folder / f"{stem}_ros.yaml").write_text(ros)
    kalibr = textwrap.dedent(f"""\
        cam0:
          camera_model: pinhole
          distortion_coeffs: [{", ".join(num(v) for v in d[:4])}]
          distortion_model: radtan
          intrinsics: [{num(fx)}, {num(fy)}, {num(cx)}, {num(cy)}]
          resolution: [{w}, {h}]
          rostopic: /{stem}/image_raw
        """)
    (folder / f"{stem}_kalibr.yaml").write_text(kalibr)
    P = K @ camera.camera_T_world[:3]
    (folder / f"{stem}_P.txt").write_text("\n".join(" ".join(num(v) for v in row) for row in P) + "\n")
    pose = camera.world_T_camera.tolist()
    return {
        "opencv": {"name": camera.name, "calibration": f"{stem}.yaml"},
        "ros": {"name": camera.name, "calibration": f"{stem}_ros.yaml", "world_T_camera": pose},
        "kalibr": {"name": camera.name, "calibration": f"{stem}_kalibr.yaml", "calibration_format": "kalibr",
                   "world_T_camera": pose},
        "projection": {"name": camera.name, "calibration": f"{stem}_P.txt", "image_size": [w, h]},
    }


@pytest.fixture(scope="module")
def inline_scene():
    return simulate("intersection_2cam", seed=3, num_frames=1).scene


@pytest.fixture(scope="module")
def inline_poses(inline_scene):
    return [v.world_T_vehicle.matrix() for f in solve_scene(inline_scene) for v in f.vehicles]


def _cameras_equal(a: Camera, b: Camera, exact: bool):
    assert (a.name, a.model, a.image_size) == (b.name, b.model, b.image_size)
    for attr in ("K", "dist", "world_T_camera"):
        x, y = getattr(a, attr), getattr(b, attr)
        assert np.array_equal(x, y) if exact else np.allclose(x, y, rtol=1e-10, atol=1e-9), attr


@pytest.mark.parametrize("fmt", ["opencv", "ros", "kalibr", "projection"])
def test_scene_by_calibration_files_loads_and_solves_as_inline(tmp_path, inline_scene, inline_poses, fmt):
    data = scene_to_dict(inline_scene, base_dir=tmp_path)
    data["cameras"] = [_camera_files(c, tmp_path, c.name)[fmt] for c in inline_scene.cameras.values()]
    (tmp_path / "scene.json").write_text(json.dumps(data))
    scene = load_scene(tmp_path / "scene.json")
    for name, camera in inline_scene.cameras.items():
        _cameras_equal(scene.cameras[name], camera, exact=fmt != "projection")
    poses = [v.world_T_vehicle.matrix() for f in solve_scene(scene) for v in f.vehicles]
    assert len(poses) == len(inline_poses) > 0
    for ours, theirs in zip(poses, inline_poses, strict=True):
        assert np.abs(ours[:3, 3] - theirs[:3, 3]).max() < 1e-6
        assert np.abs(ours[:3, :3] - theirs[:3, :3]).max() < 1e-6
    # written back inline (with the model), to the same cameras
    save_scene(scene, tmp_path / "inline.json")
    written = json.loads((tmp_path / "inline.json").read_text())["cameras"]
    assert all("calibration" not in c and c["model"] == "pinhole" for c in written)
    again = load_scene(tmp_path / "inline.json")
    for name, camera in scene.cameras.items():
        _cameras_equal(again.cameras[name], camera, exact=True)


def _scene_with(tmp_path, camera_entry, extra_files=()):
    data = {"cameras": [camera_entry], "frames": []}
    for name, text in extra_files:
        (tmp_path / name).write_text(text)
    (tmp_path / "scene.json").write_text(json.dumps(data))
    return tmp_path / "scene.json"


POSE = WORLD_T_CAMERA.tolist()


@pytest.mark.parametrize(
    "entry, field, words",
    [
        ({"calibration": "ost.yaml"}, "cameras[0].world_T_camera", "has no extrinsic"),
        ({"calibration": "ost.yaml", "world_T_camera": POSE, "K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}, "cameras[0].K",
         "given beside 'calibration'"),
        ({"calibration": "ost.yaml", "world_T_camera": POSE, "model": "fisheye"}, "cameras[0].model", "beside"),
        ({"calibration": "ost.yaml", "world_T_camera": POSE, "image_size": [640, 480]}, "cameras[0].image_size",
         "ost.yaml:image_width"),
        ({"calibration": "cam.xml", "world_T_camera": POSE}, "cameras[0].world_T_camera", "cam.xml:world_T_camera"),
        ({"calibration": "ost.yaml", "world_T_camera": POSE, "calibration_format": "matlab"},
         "cameras[0].calibration_format", "opencv, ros, kalibr, projection"),
        ({"calibration": "ost.yaml", "world_T_camera": POSE, "calibration_format": "opencv"},
         "cameras[0].calibration", "ost.yaml:camera_matrix: expected an OpenCV matrix"),
        ({"calibration": "bad.yaml", "world_T_camera": POSE}, "cameras[0].calibration",
         "bad.yaml:camera_matrix: rows: expected an integer from 1 to 16"),
        ({"calibration": "missing.yaml", "world_T_camera": POSE}, "cameras[0].calibration", "file not found"),
        ({"calibration": "../outside.yaml", "world_T_camera": POSE}, "cameras[0].calibration", "outside the scene"),
        ({"calibration": "chain.yaml", "world_T_camera": POSE}, "cameras[0].calibration",
         "chain.yaml: the camchain holds 2 cameras"),
        ({"calibration": "chain.yaml", "world_T_camera": POSE, "chain_camera": 3}, "cameras[0].chain_camera",
         "non-empty string"),
        ({"K": [[900, 0, 640], [0, 900, 360], [0, 0, 1]], "world_T_camera": POSE, "chain_camera": "cam0"},
         "cameras[0].chain_camera", "without 'calibration'"),
        ({"K": [[900, 0, 640], [0, 900, 360], [0, 0, 1]], "world_T_camera": POSE, "model": "fisheye",
          "dist": [0, 0, 0, 0, 0]}, "cameras[0].dist", "4 numbers [k1, k2, k3, k4] (fisheye model)"),
        ({"K": [[900, 0, 640], [0, 900, 360], [0, 0, 1]], "world_T_camera": POSE, "model": "omni"},
         "cameras[0].model", "pinhole, fisheye"),
        ({"world_T_camera": POSE}, "cameras[0].K", "missing"),
    ],
)
def test_scene_camera_entries_by_file_are_checked(tmp_path, entry, field, words):
    folder = tmp_path / "scene"
    folder.mkdir()
    files = [("ost.yaml", ROS_RATIONAL), ("cam.xml", OPENCV_XML_14), ("chain.yaml", KALIBR_CHAIN),
             ("bad.yaml", ROS_RATIONAL.replace("rows: 3", "rows: 100000", 1))]
    (tmp_path / "outside.yaml").write_text(ROS_RATIONAL)
    path = _scene_with(folder, {"name": "c", **entry}, files)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert info.value.field == field and words in info.value.problem, str(info.value)
    assert "\n" not in str(info.value)


def test_scene_camera_by_file_outside_the_folder_when_allowed(tmp_path):
    folder = tmp_path / "scene"
    folder.mkdir()
    (tmp_path / "chain.yaml").write_text(KALIBR_CHAIN)
    path = _scene_with(folder, {"name": "gate", "calibration": "../chain.yaml", "chain_camera": "cam1",
                                "world_T_camera": POSE})
    camera = load_scene(path, allow_outside_paths=True).cameras["gate"]
    assert camera.name == "gate" and camera.model == "fisheye" and camera.image_size == (752, 480)


def test_camera_files_replace_the_scene_s_calibration(tmp_path, inline_scene):
    data = scene_to_dict(inline_scene, base_dir=tmp_path)
    (tmp_path / "scene.json").write_text(json.dumps(data))
    cam0, cam1 = inline_scene.cameras.values()
    ros = tmp_path / "ros.yaml"
    ros.write_text(ROS_RATIONAL)
    opencv = tmp_path / "opencv.xml"
    opencv.write_text(OPENCV_XML_14)
    scene = load_scene(tmp_path / "scene.json", camera_files={cam0.name: ros, cam1.name: str(opencv)})
    a, b = scene.cameras[cam0.name], scene.cameras[cam1.name]
    # ROS: intrinsics from the file, the scene's extrinsic kept
    assert a.name == cam0.name and np.array_equal(a.world_T_camera, cam0.world_T_camera)
    assert a.K[0, 0] == 898.765432 and a.dist.size == 8 and a.image_size == (1280, 720)
    # OpenCV with an extrinsic: the file's pose replaces the scene's
    assert np.array_equal(b.world_T_camera, WORLD_T_CAMERA) and b.dist.tolist() == D14
    chain = tmp_path / "chain.yaml"
    chain.write_text(KALIBR_CHAIN.replace("cam1:", f"{cam1.name}:"))  # several cameras: the entry named like it
    scene = load_scene(tmp_path / "scene.json", camera_files={cam1.name: chain})
    assert scene.cameras[cam1.name].model == "fisheye"
    assert np.array_equal(scene.cameras[cam1.name].world_T_camera, cam1.world_T_camera)
    with pytest.raises(SceneError, match="unknown camera 'cam9'") as info:
        load_scene(tmp_path / "scene.json", camera_files={"cam9": ros})
    assert info.value.field == "camera_files.cam9"
    bad = tmp_path / "bad.yaml"
    bad.write_text(ROS_RATIONAL.replace("898.765432", "'wide'"))
    with pytest.raises(SceneError) as info:
        load_scene(tmp_path / "scene.json", camera_files={cam0.name: bad})
    assert info.value.field == f"camera_files.{cam0.name}"
    assert info.value.problem.startswith(f"{bad}:camera_matrix: ")


def test_fisheye_scene_round_trips_and_solves(tmp_path, inline_scene):
    """A fisheye camera given inline (model, 4 coefficients) saves, loads and solves to the truth of its pixels."""
    import dataclasses

    from vfactor.observations import Frame, Scene

    sim = simulate("intersection_2cam_noiseless", seed=3, num_frames=1)
    cameras = {name: dataclasses.replace(c, model="fisheye", dist=[0.03, -0.01, 0.002, 0.0])
               for name, c in sim.scene.cameras.items()}
    frame = sim.scene.frames[0]
    detections = []
    for det in frame.detections:
        camera, original = cameras[det.camera], sim.scene.cameras[det.camera]
        # the same rays seen through the fisheye lens
        xy = original.undistort_pixels(det.keypoints)
        uv, _ = camera.project_camera_points(np.column_stack([xy, np.ones(len(xy))]), jacobian=False)
        detections.append(dataclasses.replace(det, keypoints=np.where(np.isfinite(det.keypoints), uv, np.nan)))
    scene = Scene(cameras=cameras, frames=[Frame(t=frame.t, detections=detections)], base_dir=tmp_path)
    save_scene(scene, tmp_path / "fish.json")
    loaded = load_scene(tmp_path / "fish.json")
    for name in cameras:
        _cameras_equal(loaded.cameras[name], cameras[name], exact=True)
    fish = [v.world_T_vehicle.matrix() for f in solve_scene(loaded) for v in f.vehicles]
    plain = [v.world_T_vehicle.matrix() for f in solve_scene(sim.scene) for v in f.vehicles]
    assert len(fish) == len(plain) > 0
    for ours, theirs in zip(fish, plain, strict=True):
        assert np.abs(ours[:3, 3] - theirs[:3, 3]).max() < 1e-4


# ----------------------------------------------------------------------------- mutated files: CalibrationError or a camera
TOKENS = ["", "-", "[", "]", "{", "}", ":", ",", "'", '"', "!!binary", "&a", "*a", ".nan", ".inf", "1e400", "-1",
          "0", "100000", "yes", "null", "~", "\t", "rows: 3", "data: []", "cam0:", "  - [1, 2]", "%YAML:1.0", "<a>",
          "\\x00", "0x7fffffffffffffff", "?", "|", ">", "#"]


@pytest.mark.parametrize("fmt, text", [("opencv", OPENCV_FISHEYE), ("opencv", OPENCV_XML_14), ("ros", ROS_RATIONAL),
                                       ("kalibr", KALIBR_CHAIN), ("projection", "1 0 0 0\n0 1 0 0\n0 0 1 5\n"),
                                       ("projection", '{"P": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5]]}')],
                         ids=["opencv_yaml", "opencv_xml", "ros", "kalibr", "projection_text", "projection_json"])
def test_mutated_files_give_a_calibration_error_or_a_valid_camera(tmp_path, fmt, text):
    """Lines replaced, cut, duplicated or spliced with tokens: never a raw cv2 / YAML / JSON error, KeyError, ..."""
    rng = np.random.default_rng(zlib.crc32(text.encode()))
    path = tmp_path / "mutated.yaml"
    outcomes = {"loaded": 0, "error": 0}
    for _ in range(60):
        lines = text.splitlines()
        for _ in range(int(rng.integers(1, 4))):
            i = int(rng.integers(len(lines)))
            op = rng.integers(4)
            token = TOKENS[int(rng.integers(len(TOKENS)))]
            if op == 0:
                lines[i] = token
            elif op == 1:
                cut = int(rng.integers(len(lines[i]) + 1))
                lines[i] = lines[i][:cut] + token + lines[i][cut:]
            elif op == 2:
                lines.insert(i, lines[i])
            else:
                lines[i] = lines[i][: int(rng.integers(len(lines[i]) + 1))]
        path.write_text("\n".join(lines) + "\n")
        for given in (fmt, None):
            try:
                camera = load_calibration(path, "c", format=given, world_T_camera=None if fmt in ("opencv", "projection")
                                          else WORLD_T_CAMERA, chain_camera="cam0" if fmt == "kalibr" and given else None)
            except CalibrationError as exc:
                assert "\n" not in str(exc) and exc.field.startswith(str(path)) or exc.field == "world_T_camera", exc
                outcomes["error"] += 1
            else:
                assert np.all(np.isfinite(camera.K)) and camera.K[0, 0] > 0
                outcomes["loaded"] += 1
    assert outcomes["error"] > 0
