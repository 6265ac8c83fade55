"""Tests of vfactor.scene: scene and result files, round trips and validation errors."""

from __future__ import annotations

import copy
import json
import math
import os
from pathlib import Path

import gtsam
import numpy as np
import pytest

from vfactor.errors import InputError, SceneError
from vfactor.heatmaps import image_to_heatmap, render_gaussian_heatmap
from vfactor.observations import DEFAULT_VEHICLE_ID, Scene
from vfactor.result import FrameResult, Status, VehicleResult
from vfactor.scene import (
    load_results,
    load_scene,
    results_to_dict,
    save_results,
    save_scene,
    scene_from_dict,
    scene_to_dict,
)
from vfactor.wireframe import preset

# Camera axes in the world (columns): x_cam -> -y, y_cam -> -z, z_cam -> +x.
R_LOOK_X = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
HEATMAP_SHAPE = (32, 24)  # (H, W)
ROI = (400.0, 300.0, 496.0, 428.0)  # sx = 96 / 24 = 4, sy = 128 / 32 = 4


def pose_matrix(R, t) -> list:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T.tolist()


def keypoint_rows(offset: float, unseen=(3, 7)) -> list:
    rows = []
    for k in range(12):
        if k in unseen:
            rows.append([None, None, 0])
        else:
            rows.append([100.0 + 10.5 * k + offset, 200.25 + 5.0 * k, round(0.5 + 0.04 * k, 2)])
    return rows


def heatmap_targets():
    """Image pixels, heatmap covariance and peak value of the 12 rendered keypoints."""
    uv = np.stack([np.linspace(410.3, 480.9, 12), np.linspace(320.6, 410.2, 12)], axis=1)
    S = np.array([[1.5, 0.4], [0.4, 1.0]])
    peaks = np.full(12, 0.9)
    peaks[4] = 0.0  # an empty heatmap: keypoint 4 not found
    return uv, S, peaks


def write_heatmaps(path: Path) -> None:
    uv, S, peaks = heatmap_targets()
    xy = image_to_heatmap(uv, ROI, HEATMAP_SHAPE)
    stack = np.stack([render_gaussian_heatmap(xy[k], S, HEATMAP_SHAPE, peak=peaks[k]) for k in range(12)])
    np.save(path, stack.astype(np.float32))


def base_scene(tmp_path: Path) -> dict:
    """A valid scene (dict) with files under tmp_path/data: heatmaps and an image."""
    data_dir = tmp_path / "data"
    data_dir.mkdir(exist_ok=True)
    write_heatmaps(data_dir / "hm.npy")
    (data_dir / "f0_cam0.png").write_bytes(b"\x89PNG not really")
    covariances = [None] * 12
    covariances[0] = [[4.0, 1.0], [1.0, 2.0]]
    covariances[5] = [[1.5, 0.0], [0.0, 1.5]]
    return {
        "cameras": [
            {
                "name": "cam0",
                "K": [[800.0, 0.0, 640.0], [0.0, 810.0, 360.0], [0.0, 0.0, 1.0]],
                "dist": [0.01, -0.002, 0.0, 0.0],
                "image_size": [1280, 720],
                "world_T_camera": pose_matrix(R_LOOK_X, [-10.0, 0.5, 1.5]),
            },
            {
                "name": "cam1",
                "K": [[700.0, 0.0, 320.0], [0.0, 700.0, 240.0], [0.0, 0.0, 1.0]],
                "world_T_camera": pose_matrix(R_LOOK_X, [-12.0, -3.0, 2.0]),
            },
        ],
        "frames": [
            {
                "t": 0.5,
                "detections": [
                    {"camera": "cam0", "vehicle": "v1", "keypoints": keypoint_rows(0.0)},
                    {
                        "camera": "cam1",
                        "vehicle": "v1",
                        "keypoints": keypoint_rows(3.0),
                        "keypoint_covariances": covariances,
                    },
                    {"camera": "cam0", "vehicle": "v2", "keypoints": keypoint_rows(-7.0), "roi": [80, 190, 260, 280]},
                ],
                "images": {"cam0": "data/f0_cam0.png"},
            },
            {
                "t": 0.0,  # frames need not be in time order
                "detections": [
                    {"camera": "cam0", "keypoints": keypoint_rows(1.0, unseen=())},
                    {"camera": "cam1", "heatmaps": "data/hm.npy", "roi": list(ROI)},
                ],
            },
            {"t": 1.0, "detections": []},
        ],
    }


# --------------------------------------------------------------------- helpers
def same_array(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


def assert_scenes_equal(a: Scene, b: Scene) -> None:
    assert list(a.cameras) == list(b.cameras)
    for name in a.cameras:
        ca, cb = a.cameras[name], b.cameras[name]
        assert ca.name == cb.name and ca.image_size == cb.image_size
        for attr in ("K", "world_T_camera", "dist"):
            assert same_array(getattr(ca, attr), getattr(cb, attr)), (name, attr)
    assert len(a.frames) == len(b.frames)
    for fa, fb in zip(a.frames, b.frames, strict=True):
        assert fa.t == fb.t and fa.images == fb.images
        assert len(fa.detections) == len(fb.detections)
        for da, db in zip(fa.detections, fb.detections, strict=True):
            assert (da.camera, da.vehicle, da.heatmaps, da.roi) == (db.camera, db.vehicle, db.heatmaps, db.roi)
            for attr in ("keypoints", "confidence", "covariance"):
                assert same_array(getattr(da, attr), getattr(db, attr)), attr


def write_json(path: Path, data) -> Path:
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def strict_json(text: str):
    def reject(constant):
        raise AssertionError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=reject)


# ------------------------------------------------------------------- scenes
def test_load_scene_contents(tmp_path):
    scene = load_scene(write_json(tmp_path / "scene.json", base_scene(tmp_path)))
    assert list(scene.cameras) == ["cam0", "cam1"]
    cam0 = scene.cameras["cam0"]
    np.testing.assert_array_equal(cam0.dist, [0.01, -0.002, 0.0, 0.0, 0.0])
    assert cam0.image_size == (1280, 720)
    assert scene.cameras["cam1"].image_size is None and not scene.cameras["cam1"].has_distortion
    assert [f.t for f in scene.frames] == [0.5, 0.0, 1.0]  # file order, not time order
    assert scene.base_dir == tmp_path

    d0, d1, d2 = scene.frames[0].detections
    assert (d0.camera, d0.vehicle) == ("cam0", "v1") and (d2.vehicle, d2.roi) == ("v2", (80.0, 190.0, 260.0, 280.0))
    assert d0.keypoints.shape == (12, 2) and d0.confidence.shape == (12,)
    np.testing.assert_array_equal(d0.keypoints[0], [100.0, 200.25])
    assert d0.confidence[3] == 0 and np.all(np.isnan(d0.keypoints[3]))
    assert d0.covariance is None
    assert d1.covariance.shape == (12, 2, 2)
    np.testing.assert_array_equal(d1.covariance[0], [[4.0, 1.0], [1.0, 2.0]])
    assert np.all(np.isnan(d1.covariance[1]))
    assert scene.frames[0].images == {"cam0": str(tmp_path / "data" / "f0_cam0.png")}
    assert scene.frames[0].vehicle_ids() == ["v1", "v2"]

    # 'vehicle' omitted by every detection of a frame: the default track id.
    assert [d.vehicle for d in scene.frames[1].detections] == [DEFAULT_VEHICLE_ID] * 2
    assert scene.frames[2].detections == []


def test_heatmap_detection_is_decoded(tmp_path):
    scene = load_scene(write_json(tmp_path / "scene.json", base_scene(tmp_path)))
    det = scene.frames[1].detections[1]
    assert det.heatmaps == str(tmp_path / "data" / "hm.npy") and det.roi == ROI
    uv, S, peaks = heatmap_targets()
    found = peaks > 0
    assert np.all(det.confidence[~found] == 0) and np.all(np.isnan(det.keypoints[~found]))
    assert np.all(np.linalg.norm(det.keypoints[found] - uv[found], axis=1) < 0.05 * 4)
    np.testing.assert_allclose(det.confidence[found], 0.9, atol=0.1)
    J = np.diag([4.0, 4.0])  # ROI pixels per heatmap pixel
    for k in np.flatnonzero(found):
        np.testing.assert_allclose(det.covariance[k], J @ S @ J.T, atol=0.1 * 16 * 1.5)


def test_heatmaps_with_keypoints_keep_keypoints_and_take_covariance(tmp_path):
    data = base_scene(tmp_path)
    data["frames"][1]["detections"][1]["keypoints"] = keypoint_rows(0.0)
    scene = scene_from_dict(data, base_dir=tmp_path)
    det = scene.frames[1].detections[1]
    np.testing.assert_array_equal(det.keypoints[0], [100.0, 200.25])
    _, S, _ = heatmap_targets()
    np.testing.assert_allclose(det.covariance[0], 16 * S, atol=0.1 * 16 * 1.5)
    # Explicit covariances win over the heatmaps'.
    data["frames"][1]["detections"][1]["keypoint_covariances"] = [[[2.0, 0.0], [0.0, 3.0]]] * 12
    det = scene_from_dict(data, base_dir=tmp_path).frames[1].detections[1]
    np.testing.assert_array_equal(det.covariance[0], [[2.0, 0.0], [0.0, 3.0]])


def test_scene_round_trip(tmp_path):
    original = load_scene(write_json(tmp_path / "scene.json", base_scene(tmp_path)))
    out = tmp_path / "elsewhere" / "deeper"
    out.mkdir(parents=True)
    save_scene(original, out / "copy.json")
    text = (out / "copy.json").read_text(encoding="utf-8")
    written = strict_json(text)
    assert written["frames"][0]["detections"][0]["keypoints"][3] == [None, None, 0]
    assert written["frames"][0]["images"] == {"cam0": "../../data/f0_cam0.png"}
    assert written["frames"][1]["detections"][1]["heatmaps"] == "../../data/hm.npy"
    reloaded = load_scene(out / "copy.json", allow_outside_paths=True)  # its paths lead back up
    assert_scenes_equal(original, reloaded)
    # And a second generation, to the same content.
    save_scene(reloaded, tmp_path / "again.json")
    assert_scenes_equal(original, load_scene(tmp_path / "again.json"))


def test_scene_to_dict_round_trip_in_memory(tmp_path):
    original = scene_from_dict(base_scene(tmp_path), base_dir=tmp_path)
    data = scene_to_dict(original)
    strict_json(json.dumps(data, allow_nan=False))
    assert data["frames"][1]["detections"][1]["heatmaps"] == "data/hm.npy"
    assert_scenes_equal(original, scene_from_dict(data, base_dir=tmp_path))


def test_save_scene_rejects_nan_pixels_of_seen_keypoints(tmp_path):
    scene = scene_from_dict(base_scene(tmp_path), base_dir=tmp_path)
    scene.frames[0].detections[2].keypoints[6] = np.nan
    with pytest.raises(SceneError) as info:
        save_scene(scene, tmp_path / "bad.json")
    assert info.value.field == "frames[0].detections[2].keypoints[6]"


# Each case: (name, edit of the base scene, expected field, text in the message).
def _set(path, value):
    def edit(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return edit


def _delete(path):
    def edit(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]

    return edit


def _kp(row, value, frame=0, det=0):
    return _set(["frames", frame, "detections", det, "keypoints", row], value)


def _duplicate_camera_name(data):
    data["cameras"][1]["name"] = "cam0"


def _all_unnamed_two_from_cam0(data):
    data["frames"][1]["detections"].append({"camera": "cam0", "keypoints": keypoint_rows(0.0)})


def _same_camera_vehicle_twice(data):
    data["frames"][0]["detections"].append({"camera": "cam1", "vehicle": "v1", "keypoints": keypoint_rows(0.0)})


D = "frames[0].detections[0]"
BAD_CASES = [
    ("top_empty", lambda d: d.clear(), "cameras", "missing"),
    ("cameras_missing", _delete(["cameras"]), "cameras", "missing"),
    ("cameras_empty", _set(["cameras"], []), "cameras", "non-empty list"),
    ("frames_not_list", _set(["frames"], {"t": 0}), "frames", "expected a list"),
    ("unknown_top_key", _set(["colour"], "red"), "colour", "unknown key; known keys: cameras, frames"),
    ("unknown_camera_key", _set(["cameras", 0, "fov"], 60), "cameras[0].fov", "unknown key"),
    ("camera_name_missing", _delete(["cameras", 0, "name"]), "cameras[0].name", "missing"),
    ("camera_name_not_string", _set(["cameras", 0, "name"], 3), "cameras[0].name", "non-empty string, got 3"),
    ("duplicate_camera_name", _duplicate_camera_name, "cameras[1].name", "duplicate camera name 'cam0'"),
    ("K_shape", _set(["cameras", 1, "K"], [[700, 0, 320], [0, 700, 240]]), "cameras[1].K", "3x3"),
    ("K_string", _set(["cameras", 1, "K", 0, 0], "700"), "cameras[1].K", "the string '700' at [0][0]"),
    ("K_nan", _set(["cameras", 1, "K", 1, 1], math.nan), "cameras[1].K", "NaN at [1][1]"),
    ("K_singular", _set(["cameras", 1, "K", 0, 0], 0.0), "cameras[1].K", "focal lengths must be > 0"),
    ("K_bottom_row", _set(["cameras", 1, "K", 2], [0, 1, 1]), "cameras[1].K", "expected [[fx, s, cx]"),
    (
        "pose_not_rigid",
        _set(["cameras", 0, "world_T_camera", 0, 0], 2.0),
        "cameras[0].world_T_camera",
        "not a rotation",
    ),
    ("pose_missing", _delete(["cameras", 0, "world_T_camera"]), "cameras[0].world_T_camera", "missing"),
    ("dist_three", _set(["cameras", 0, "dist"], [0.1, 0.0, 0.0]), "cameras[0].dist", "4, 5, 8, 12 or 14 numbers"),
    ("dist_inf", _set(["cameras", 0, "dist", 1], math.inf), "cameras[0].dist", "Infinity"),
    ("image_size_negative", _set(["cameras", 0, "image_size"], [1280, -720]), "cameras[0].image_size", "positive"),
    ("image_size_float", _set(["cameras", 0, "image_size"], [1280.5, 720]), "cameras[0].image_size", "integers"),
    ("frame_not_object", _set(["frames", 0], [1, 2]), "frames[0]", "expected an object"),
    ("t_missing", _delete(["frames", 0, "t"]), "frames[0].t", "missing"),
    ("t_inf", _set(["frames", 0, "t"], math.inf), "frames[0].t", "finite number of seconds, got Infinity"),
    ("t_string", _set(["frames", 0, "t"], "0.5"), "frames[0].t", "the string '0.5'"),
    ("t_bool", _set(["frames", 0, "t"], True), "frames[0].t", "got true"),
    ("detections_missing", _delete(["frames", 0, "detections"]), "frames[0].detections", "missing"),
    ("unknown_frame_key", _set(["frames", 0, "time"], 1), "frames[0].time", "unknown key"),
    ("detection_not_object", _set(["frames", 0, "detections", 0], "cam0"), D, "expected an object"),
    (
        "unknown_detection_key",
        _set(["frames", 0, "detections", 2, "colour"], "red"),
        "frames[0].detections[2].colour",
        "unknown key; known keys: camera, vehicle, track, keypoints",
    ),
    (
        "unknown_camera",
        _set(["frames", 0, "detections", 0, "camera"], "cam9"),
        f"{D}.camera",
        "unknown camera 'cam9'; known: cam0, cam1",
    ),
    ("camera_missing", _delete(["frames", 0, "detections", 0, "camera"]), f"{D}.camera", "missing"),
    (
        "vehicle_not_string",
        _set(["frames", 0, "detections", 0, "vehicle"], 7),
        f"{D}.vehicle",
        "non-empty string, got 7",
    ),
    ("vehicle_mixed", _delete(["frames", 0, "detections", 1, "vehicle"]), "frames[0].detections[1].vehicle", "missing"),
    (
        "vehicle_mixed_other_frame",
        _set(["frames", 1, "detections", 1, "vehicle"], "v1"),
        "frames[1].detections[0].vehicle",
        "missing",
    ),
    (
        "camera_vehicle_twice",
        _same_camera_vehicle_twice,
        "frames[0].detections[3]",
        "already has a detection of vehicle 'v1'",
    ),
    ("neither_keypoints_nor_heatmaps", _delete(["frames", 0, "detections", 0, "keypoints"]), D, "found none"),
    ("keypoints_not_list", _set(["frames", 0, "detections", 0, "keypoints"], "none"), f"{D}.keypoints", "12 rows"),
    ("keypoints_eleven", lambda d: d["frames"][0]["detections"][0]["keypoints"].pop(), f"{D}.keypoints", "got 11 rows"),
    ("keypoint_row_short", _kp(5, [100.0, 200.0]), f"{D}.keypoints[5]", "[u, v, confidence], got a list of 2"),
    ("keypoint_row_not_list", _kp(5, 3.0), f"{D}.keypoints[5]", "[u, v, confidence]"),
    (
        "confidence_above_one",
        _kp(5, [100.0, 200.0, 1.5]),
        f"{D}.keypoints[5]",
        "confidence: expected a number in [0, 1], got 1.5",
    ),
    ("confidence_negative", _kp(5, [100.0, 200.0, -0.1]), f"{D}.keypoints[5]", "confidence"),
    ("confidence_string", _kp(5, [100.0, 200.0, "high"]), f"{D}.keypoints[5]", "confidence"),
    ("confidence_null", _kp(5, [100.0, 200.0, None]), f"{D}.keypoints[5]", "got null"),
    ("confidence_nan", _kp(5, [100.0, 200.0, math.nan]), f"{D}.keypoints[5]", "got NaN"),
    ("u_null_but_seen", _kp(5, [None, 200.0, 0.8]), f"{D}.keypoints[5]", "u: expected a finite number"),
    ("v_inf", _kp(5, [100.0, math.inf, 0.8]), f"{D}.keypoints[5]", "v: expected a finite number"),
    ("u_nan_unseen", _kp(3, [math.nan, None, 0]), f"{D}.keypoints[3]", "u: expected a finite number or null, got NaN"),
    ("u_string_unseen", _kp(3, ["x", None, 0]), f"{D}.keypoints[3]", "u:"),
    (
        "roi_flipped",
        _set(["frames", 0, "detections", 2, "roi"], [260, 190, 80, 280]),
        "frames[0].detections[2].roi",
        "x1 > x0",
    ),
    (
        "roi_empty_height",
        _set(["frames", 0, "detections", 2, "roi"], [80, 190, 260, 190]),
        "frames[0].detections[2].roi",
        "y1 > y0",
    ),
    (
        "roi_three",
        _set(["frames", 0, "detections", 2, "roi"], [80, 190, 260]),
        "frames[0].detections[2].roi",
        "[x0, y0, x1, y1]",
    ),
    ("roi_nan", _set(["frames", 0, "detections", 2, "roi", 1], math.nan), "frames[0].detections[2].roi", "NaN"),
    (
        "heatmaps_missing_file",
        _set(["frames", 1, "detections", 1, "heatmaps"], "data/nope.npy"),
        "frames[1].detections[1].heatmaps",
        "file not found",
    ),
    (
        "heatmaps_not_string",
        _set(["frames", 1, "detections", 1, "heatmaps"], 3),
        "frames[1].detections[1].heatmaps",
        "a string",
    ),
    (
        "heatmaps_without_roi",
        _delete(["frames", 1, "detections", 1, "roi"]),
        "frames[1].detections[1].roi",
        "missing: required with 'heatmaps'",
    ),
    ("images_not_object", _set(["frames", 0, "images"], ["f0.png"]), "frames[0].images", "expected an object"),
    (
        "images_unknown_camera",
        _set(["frames", 0, "images", "cam9"], "data/f0_cam0.png"),
        "frames[0].images.cam9",
        "unknown camera 'cam9'; known: cam0, cam1",
    ),
    (
        "images_missing_file",
        _set(["frames", 0, "images", "cam1"], "data/none.png"),
        "frames[0].images.cam1",
        "file not found",
    ),
    ("images_not_string", _set(["frames", 0, "images", "cam1"], 5), "frames[0].images.cam1", "a string"),
    (
        "covariances_eleven",
        lambda d: d["frames"][0]["detections"][1]["keypoint_covariances"].pop(),
        "frames[0].detections[1].keypoint_covariances",
        "expected 12 entries",
    ),
    (
        "covariance_asymmetric",
        _set(["frames", 0, "detections", 1, "keypoint_covariances", 3], [[2.0, 0.5], [0.4, 2.0]]),
        "frames[0].detections[1].keypoint_covariances[3]",
        "symmetric",
    ),
    (
        "covariance_not_pd",
        _set(["frames", 0, "detections", 1, "keypoint_covariances", 3], [[1.0, 2.0], [2.0, 1.0]]),
        "frames[0].detections[1].keypoint_covariances[3]",
        "positive-definite",
    ),
    (
        "covariance_shape",
        _set(["frames", 0, "detections", 1, "keypoint_covariances", 3], [1.0, 2.0]),
        "frames[0].detections[1].keypoint_covariances[3]",
        "2x2",
    ),
]


@pytest.mark.parametrize("name, edit, field, message", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_bad_scene_raises_scene_error_naming_the_field(tmp_path, name, edit, field, message):
    data = base_scene(tmp_path)
    edit(data)
    with pytest.raises(SceneError) as info:
        scene_from_dict(data, base_dir=tmp_path)
    assert type(info.value) is SceneError
    assert info.value.field == field
    assert message in info.value.problem, info.value.problem


@pytest.mark.parametrize(
    "name, array, message",
    [
        ("wrong_shape", np.zeros((11, 8, 8), dtype=np.float32), "shape (12, H, W), got (11, 8, 8)"),
        ("two_d", np.zeros((8, 8), dtype=np.float32), "shape (12, H, W)"),
        ("integer", np.zeros((12, 8, 8), dtype=np.int32), "float array, got dtype int32"),
        ("nan", np.full((12, 8, 8), np.nan, dtype=np.float32), "NaN"),
    ],
)
def test_bad_heatmap_files(tmp_path, name, array, message):
    data = base_scene(tmp_path)
    np.save(tmp_path / "data" / f"{name}.npy", array)
    data["frames"][1]["detections"][1]["heatmaps"] = f"data/{name}.npy"
    with pytest.raises(SceneError) as info:
        scene_from_dict(data, base_dir=tmp_path)
    assert info.value.field == "frames[1].detections[1].heatmaps"
    assert message in info.value.problem


def test_heatmap_file_not_npy(tmp_path):
    data = base_scene(tmp_path)
    (tmp_path / "data" / "text.npy").write_text("not numpy")
    data["frames"][1]["detections"][1]["heatmaps"] = "data/text.npy"
    with pytest.raises(SceneError) as info:
        scene_from_dict(data, base_dir=tmp_path)
    assert info.value.field == "frames[1].detections[1].heatmaps"
    assert "expected a .npy file" in info.value.problem


def test_top_level_not_an_object():
    with pytest.raises(SceneError) as info:
        scene_from_dict([1, 2, 3])
    assert info.value.field == "" and "expected an object, got a list of 3" in str(info.value)


def test_file_not_found_and_not_json(tmp_path):
    missing = tmp_path / "missing.json"
    with pytest.raises(SceneError) as info:
        load_scene(missing)
    assert info.value.field == str(missing) and "file not found" in info.value.problem
    with pytest.raises(SceneError, match="got a directory"):
        load_scene(tmp_path)
    if os.path.exists(os.devnull) and not os.path.isfile(os.devnull):  # a character device: no folder
        with pytest.raises(SceneError, match="expected a regular file, got a device, pipe or socket"):
            load_scene(os.devnull)

    broken = tmp_path / "broken.json"
    broken.write_text('{"cameras": [}', encoding="utf-8")
    with pytest.raises(SceneError) as info:
        load_scene(broken)
    assert info.value.field == str(broken) and "not valid JSON" in info.value.problem and "line 1" in info.value.problem

    duplicated = tmp_path / "duplicated.json"
    duplicated.write_text('{"cameras": [], "cameras": []}', encoding="utf-8")
    with pytest.raises(SceneError) as info:
        load_scene(duplicated)
    assert info.value.field == str(duplicated) and "'cameras' appears twice" in info.value.problem


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity"])
def test_json_non_finite_literals_are_rejected_at_their_field(tmp_path, literal):
    data = base_scene(tmp_path)
    data["frames"][0]["detections"][0]["keypoints"][2][1] = "@@"
    text = json.dumps(data).replace('"@@"', literal)
    path = tmp_path / "scene.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert info.value.field == "frames[0].detections[0].keypoints[2]"
    assert f"got {literal}" in info.value.problem


# ------------------------------------------------------------------ results
def make_results() -> list[FrameResult]:
    rng = np.random.default_rng(11)
    wireframe = preset("toyota_prius").wireframe()
    pose = gtsam.Pose3(gtsam.Rot3.RzRyRx(0.02, -0.01, 1.1), gtsam.Point3(3.2, -1.5, 0.33))
    A = rng.normal(size=(6, 6))
    pose_cov = A @ A.T * 1e-3 + np.eye(6) * 1e-4
    B = rng.normal(size=(12, 3, 3))
    kp_cov = np.einsum("kij,klj->kil", B, B) * 1e-4 + np.eye(3) * 1e-5
    pose2 = gtsam.Pose3(gtsam.Rot3.Yaw(-0.4), gtsam.Point3(-8.0, 2.0, 0.31))
    return [
        FrameResult(
            t=0.0,
            vehicles=[
                VehicleResult(
                    id="v1",
                    status=Status.CONVERGED,
                    world_T_vehicle=pose,
                    wireframe=wireframe,
                    pose_covariance=pose_cov,
                    keypoint_covariances_world=kp_cov,
                    iterations=7,
                    final_error=3.2,
                ),
                VehicleResult(
                    id="v2",
                    status=Status.MAX_ITERATIONS,
                    world_T_vehicle=pose2,
                    wireframe=preset("suv").wireframe(),
                    iterations=100,
                    final_error=41.5,
                    message="stopped at the iteration limit",
                ),
            ],
        ),
        FrameResult(
            t=0.1,
            vehicles=[
                VehicleResult(id="v1", status=Status.DEGENERATE, message="only 3 keypoints seen"),
                VehicleResult(id="v2", status=Status.FAILED, iterations=4, final_error=math.inf, message="diverged"),
            ],
        ),
        FrameResult(t=0.2, vehicles=[]),
    ]


def assert_results_equal(a: list[FrameResult], b: list[FrameResult]) -> None:
    assert len(a) == len(b)
    for fa, fb in zip(a, b, strict=True):
        assert fa.t == fb.t and len(fa.vehicles) == len(fb.vehicles)
        for va, vb in zip(fa.vehicles, fb.vehicles, strict=True):
            assert (va.id, va.status, va.iterations, va.message) == (vb.id, vb.status, vb.iterations, vb.message)
            fe_a = va.final_error if math.isfinite(va.final_error) else math.nan
            assert same_array(fe_a, vb.final_error)
            if va.world_T_vehicle is None:
                assert vb.world_T_vehicle is None
            else:
                np.testing.assert_array_equal(va.world_T_vehicle.matrix(), vb.world_T_vehicle.matrix())
            assert va.wireframe == vb.wireframe
            assert same_array(va.pose_covariance, vb.pose_covariance)
            assert same_array(va.keypoint_covariances_world, vb.keypoint_covariances_world)


def test_results_round_trip(tmp_path):
    results = make_results()
    path = tmp_path / "results.json"
    save_results(results, path)
    written = strict_json(path.read_text(encoding="utf-8"))
    v1, v2 = written["frames"][0]["vehicles"]
    assert list(v1) == [
        "id",
        "world_T_vehicle",
        "keypoints_world",
        "keypoints_vehicle",
        "pose_covariance",
        "status",
        "iterations",
        "final_error",
        "keypoint_covariances_world",
    ]
    assert v1["status"] == "converged" and v1["iterations"] == 7 and v1["final_error"] == 3.2
    assert np.asarray(v1["world_T_vehicle"]).shape == (4, 4)
    assert np.asarray(v1["keypoints_world"]).shape == (12, 3)
    assert np.asarray(v1["keypoint_covariances_world"]).shape == (12, 3, 3)
    assert v2["pose_covariance"] is None and "keypoint_covariances_world" not in v2
    assert v2["message"] == "stopped at the iteration limit"
    degenerate, failed = written["frames"][1]["vehicles"]
    for entry in (degenerate, failed):
        for key in ("world_T_vehicle", "keypoints_world", "keypoints_vehicle", "pose_covariance"):
            assert entry[key] is None
    assert degenerate["status"] == "degenerate" and degenerate["final_error"] is None
    assert degenerate["message"] == "only 3 keypoints seen"
    assert failed["final_error"] is None  # inf is not JSON
    assert written["frames"][2] == {"t": 0.2, "vehicles": []}

    loaded = load_results(path)
    assert_results_equal(results, loaded)
    np.testing.assert_allclose(
        loaded[0].vehicles[0].keypoints_world, results[0].vehicles[0].keypoints_world, atol=1e-12
    )
    assert results_to_dict(loaded) == results_to_dict(results)


def test_results_non_finite_covariance_written_as_null():
    results = make_results()
    results[0].vehicles[0].pose_covariance[0, 0] = np.nan
    data = results_to_dict(results)
    assert data["frames"][0]["vehicles"][0]["pose_covariance"] is None


def test_results_converged_without_pose_cannot_be_written():
    with pytest.raises(SceneError) as info:
        results_to_dict([FrameResult(t=0.0, vehicles=[VehicleResult(id="v1", status=Status.CONVERGED)])])
    assert info.value.field == "frames[0].vehicles[0].world_T_vehicle"


V = "frames[0].vehicles[0]"
BAD_RESULTS = [
    ("unknown_key", _set(["frames", 0, "vehicles", 0, "colour"], 1), f"{V}.colour", "unknown key"),
    ("bad_status", _set(["frames", 0, "vehicles", 0, "status"], "done"), f"{V}.status", "converged, max_iterations"),
    ("id_missing", _delete(["frames", 0, "vehicles", 0, "id"]), f"{V}.id", "missing"),
    ("pose_missing", _set(["frames", 0, "vehicles", 0, "world_T_vehicle"], None), f"{V}.world_T_vehicle", "missing"),
    (
        "pose_not_rigid",
        _set(["frames", 0, "vehicles", 0, "world_T_vehicle", 0, 1], 0.5),
        f"{V}.world_T_vehicle",
        "rotation",
    ),
    (
        "keypoints_shape",
        lambda d: d["frames"][0]["vehicles"][0]["keypoints_vehicle"].pop(),
        f"{V}.keypoints_vehicle",
        "12x3",
    ),
    (
        "keypoints_world_off",
        _set(["frames", 0, "vehicles", 0, "keypoints_world", 4, 2], 9.0),
        f"{V}.keypoints_world",
        "differs",
    ),
    ("covariance_shape", _set(["frames", 0, "vehicles", 0, "pose_covariance"], [[1.0]]), f"{V}.pose_covariance", "6x6"),
    (
        "covariance_nan",
        _set(["frames", 0, "vehicles", 0, "pose_covariance", 2, 2], math.nan),
        f"{V}.pose_covariance",
        "NaN",
    ),
    (
        "kp_covariance_asymmetric",
        _set(["frames", 0, "vehicles", 0, "keypoint_covariances_world", 2, 0, 1], 5.0),
        f"{V}.keypoint_covariances_world[2]",
        "symmetric",
    ),
    (
        "iterations_negative",
        _set(["frames", 0, "vehicles", 0, "iterations"], -1),
        f"{V}.iterations",
        "non-negative integer",
    ),
    (
        "final_error_string",
        _set(["frames", 0, "vehicles", 0, "final_error"], "3"),
        f"{V}.final_error",
        "finite number or null",
    ),
    ("message_not_string", _set(["frames", 0, "vehicles", 0, "message"], 3), f"{V}.message", "string"),
    (
        "degenerate_with_pose",
        _set(["frames", 1, "vehicles", 0, "world_T_vehicle"], np.eye(4).tolist()),
        "frames[1].vehicles[0].world_T_vehicle",
        "expected null for a 'degenerate' vehicle",
    ),
    (
        "duplicate_id",
        _set(["frames", 0, "vehicles", 1, "id"], "v1"),
        "frames[0].vehicles[1].id",
        "duplicate vehicle id 'v1'",
    ),
    ("t_missing", _delete(["frames", 0, "t"]), "frames[0].t", "missing"),
    ("unknown_top", _set(["meta"], {}), "meta", "unknown key"),
]


@pytest.mark.parametrize("name, edit, field, message", BAD_RESULTS, ids=[c[0] for c in BAD_RESULTS])
def test_bad_results_raise_scene_error_naming_the_field(tmp_path, name, edit, field, message):
    data = copy.deepcopy(results_to_dict(make_results()))
    edit(data)
    path = write_json(tmp_path / "results.json", data)
    with pytest.raises(SceneError) as info:
        load_results(path)
    assert info.value.field == field
    assert message in info.value.problem, info.value.problem


def test_ground_plane_round_trips_and_is_validated(tmp_path):
    from vfactor.factors.ground_plane import GroundPlane
    from vfactor.scene import load_scene, save_scene, scene_from_dict
    from vfactor.errors import InputError, SceneError

    data = {"cameras": [{"name": "c", "K": [[800, 0, 640], [0, 800, 360], [0, 0, 1]],
                         "world_T_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}],
            "frames": [], "ground_plane": {"normal": [0, 0, 2], "offset": 0.1}}
    scene = scene_from_dict(data)
    assert scene.ground_plane == GroundPlane((0.0, 0.0, 1.0), 0.05)  # the same plane, 2 z = 0.1, its normal unit
    assert GroundPlane((0.0, 0.0, 4.0), 1.0) == GroundPlane((0.0, 0.0, 1.0), 0.25)
    save_scene(scene, tmp_path / "s.json")
    assert load_scene(tmp_path / "s.json").ground_plane == scene.ground_plane
    for bad, field in (({"normal": [0, 0, -1]}, "ground_plane.normal"), ({"normal": [0, 1]}, "ground_plane.normal"),
                       ({"normal": [0, 0, 1], "tilt": 1}, "ground_plane.tilt")):
        data["ground_plane"] = bad
        with pytest.raises(SceneError) as info:
            scene_from_dict(data)
        assert info.value.field == field


def image_box_scene(tmp_path: Path) -> dict:
    """base_scene plus a detection of frame 0 given only as a box in cam0's image."""
    data = base_scene(tmp_path)
    data["frames"][0]["detections"].append({"camera": "cam0", "vehicle": "v3", "roi": [500, 300, 700, 420]})
    return data


def test_box_only_detection_waits_for_the_network_and_round_trips(tmp_path):
    scene = load_scene(write_json(tmp_path / "scene.json", image_box_scene(tmp_path)))
    det = scene.frames[0].detections[3]
    assert det.from_image and det.roi == (500.0, 300.0, 700.0, 420.0)
    assert np.all(np.isnan(det.keypoints)) and np.all(det.confidence == 0) and det.covariance is None
    assert not any(d.from_image for d in scene.frames[0].detections[:3])
    assert scene.undetected() == [(0, 3)]
    with pytest.raises(InputError) as info:
        scene.require_keypoints()
    assert info.value.field == "frames[0].detections[3].keypoints" and "keypoint network" in str(info.value)
    assert scene_to_dict(scene)["frames"][0]["detections"][3] == {
        "camera": "cam0", "vehicle": "v3", "roi": [500.0, 300.0, 700.0, 420.0]}
    save_scene(scene, tmp_path / "copy.json")
    again = load_scene(tmp_path / "copy.json")
    assert_scenes_equal(scene, again)
    assert again.frames[0].detections[3].from_image


@pytest.mark.parametrize(
    "edit, field, message",
    [
        (_set(["frames", 0, "images"], None), "frames[0].detections[3]", "needs this frame's image of camera 'cam0'"),
        (_set(["frames", 0, "detections", 3, "camera"], "cam1"), "frames[0].detections[3]", "camera 'cam1'"),
        (_set(["frames", 0, "detections", 3, "keypoint_covariances"], [None] * 12),
         "frames[0].detections[3].keypoint_covariances", "without 'keypoints'"),
        (_delete(["frames", 0, "detections", 3, "roi"]), "frames[0].detections[3]", "found none"),
    ],
    ids=["no_images", "camera_without_image", "covariances_without_keypoints", "no_roi"],
)
def test_bad_box_only_detection(tmp_path, edit, field, message):
    data = image_box_scene(tmp_path)
    edit(data)
    with pytest.raises(SceneError) as info:
        scene_from_dict(data, base_dir=tmp_path)
    assert info.value.field == field and message in str(info.value)


def test_boxes_and_covariance_kinds_round_trip_through_the_result_file(tmp_path):
    """A solved frame's boxes (with sigmas) and a fixed-lag track's covariance kinds survive save and load."""
    from vfactor.sim import simulate
    from vfactor.solve import solve_scene
    from vfactor.track import TrackOptions, track_scene

    sim = simulate("intersection_2cam_track", seed=0, num_frames=6)
    solved = solve_scene(sim.scene)
    tracked = track_scene(sim.scene, TrackOptions(lag=0.3)).frames
    for frames in (solved, tracked):
        path = tmp_path / "r.json"
        save_results(frames, path)
        loaded = load_results(path)
        for a, b in zip(frames, loaded):
            for va, vb in zip(a.vehicles, b.vehicles):
                np.testing.assert_allclose(vb.box.world_T_box.matrix(), va.box.world_T_box.matrix(), atol=1e-12)
                np.testing.assert_allclose(vb.box.size, va.box.size)
                assert (vb.box.size_sigma is None) == (va.box.size_sigma is None)
                assert vb.extras.get("covariance") == va.extras.get("covariance")
        assert results_to_dict(loaded) == results_to_dict(frames)
    assert all(v.box.size_sigma is not None for f in solved for v in f.vehicles)
    kinds = {v.extras.get("covariance") for f in tracked for v in f.vehicles}
    assert kinds == {"fixed_lag"}
    data = results_to_dict(tracked)
    entry = data["frames"][0]["vehicles"][0]
    for key, value, field in (("pose_covariance_kind", "guessed", "pose_covariance_kind"),
                              ("box", {"size": [4.0, 1.8, 1.5]}, "box.world_T_box")):
        bad = copy.deepcopy(data)
        bad["frames"][0]["vehicles"][0][key] = value
        with pytest.raises(SceneError) as info:
            load_results(write_json(tmp_path / "bad.json", bad))
        assert info.value.field == f"frames[0].vehicles[0].{field}"
    assert entry["pose_covariance_kind"] == "fixed_lag"


def test_frames_of_several_vehicles_without_ids_wait_for_the_association(tmp_path):
    """No vehicle ids, but two detections of cam0 (or per-camera track ids): the vehicles are to be found."""
    from vfactor.observations import UNASSIGNED

    data = base_scene(tmp_path)
    _all_unnamed_two_from_cam0(data)
    data["frames"][1]["detections"][0]["track"] = "cam0-17"
    scene = scene_from_dict(data, base_dir=tmp_path)
    frame = scene.frames[1]
    assert [d.vehicle for d in frame.detections] == [UNASSIGNED] * len(frame.detections)
    assert frame.detections[0].track == "cam0-17" and scene.unassigned() == [(1, j) for j in range(len(frame.detections))]
    with pytest.raises(ValueError) as info:  # an InputError
        scene.require_keypoints()
    assert info.value.field == "frames[1].detections[0].vehicle" and "associate them first" in info.value.problem
    save_scene(scene, tmp_path / "again.json")
    written = json.loads((tmp_path / "again.json").read_text())["frames"][1]["detections"]
    assert all("vehicle" not in d for d in written) and written[0]["track"] == "cam0-17"
    assert load_scene(tmp_path / "again.json").unassigned() == scene.unassigned()


def test_results_written_as_they_come(tmp_path):
    """save_results takes an iterator (vfactor solve writes frames as they are solved): the same text as the
    whole list, and nothing at the path when the iterator fails part-way."""
    from vfactor.scene import _dumps, results_to_dict

    results = make_results()
    path = tmp_path / "streamed.json"
    save_results(iter(results), path)
    assert path.read_text(encoding="utf-8") == _dumps(results_to_dict(results)) + "\n"
    save_results(iter([]), tmp_path / "empty.json")
    assert strict_json((tmp_path / "empty.json").read_text(encoding="utf-8")) == {"frames": []}

    def failing():
        yield results[0]
        raise RuntimeError("solver crashed")

    with pytest.raises(RuntimeError, match="solver crashed"):
        save_results(failing(), tmp_path / "partial.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.json", "streamed.json"]  # no partial file, no temp


def test_save_results_takes_the_results_first_as_save_scene_takes_the_scene(tmp_path):
    """save_results(path, frames) was the reverse of save_scene(scene, path): the old order still writes the same
    file, with a DeprecationWarning."""
    results = make_results()
    save_results(results, tmp_path / "new.json")
    with pytest.warns(DeprecationWarning, match=r"save_results\(frames, path\)"):
        save_results(tmp_path / "old.json", results)
    assert (tmp_path / "old.json").read_bytes() == (tmp_path / "new.json").read_bytes()
    with pytest.warns(DeprecationWarning):
        save_results(str(tmp_path / "old_str.json"), iter(results))
    assert (tmp_path / "old_str.json").read_bytes() == (tmp_path / "new.json").read_bytes()


def test_two_frames_at_one_time_are_refused(tmp_path):
    """`t` is unique per frame (docs/scene-format.md): `vfactor solve` refused it no more than `vfactor track` does."""
    data = base_scene(tmp_path)
    data["frames"].append(dict(data["frames"][0]))
    with pytest.raises(SceneError) as info:
        load_scene(write_json(tmp_path / "scene.json", data))
    assert info.value.field == f"frames[{len(data['frames']) - 1}].t" and "same time as frames[0]" in info.value.problem
