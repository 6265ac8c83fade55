"""OpenLABEL: valid against the official 1.0.0 schema; boxes, quaternion order, cameras and keypoints read by hand."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from pyquaternion import Quaternion

from tests.formats.helpers import DEG, MM, assert_same_box, rotation_error
from vfactor.errors import InputError
from vfactor.formats import read_openlabel, write_openlabel
from vfactor.keypoints import KEYPOINT_NAMES

SCHEMA = json.loads((Path(__file__).parent / "data" / "openlabel_json_schema-v1.0.0.json").read_text())


def validate(data):
    jsonschema.Draft7Validator(SCHEMA).validate(data)


@pytest.fixture(scope="module")
def written(known, tmp_path_factory):
    scene, results = known
    path = tmp_path_factory.mktemp("openlabel") / "labels.json"
    report = write_openlabel(path, results, scene, name="known")
    return path, json.loads(path.read_text()), report


def test_files_are_valid_openlabel_1_0_0(written, real, tmp_path):
    validate(written[1])
    scene, results = real
    write_openlabel(tmp_path / "real.json", results, scene)
    data = json.loads((tmp_path / "real.json").read_text())
    validate(data)
    assert data["openlabel"]["metadata"]["schema_version"] == "1.0.0"


@pytest.mark.parametrize("break_it", [
    lambda d: d["openlabel"]["objects"].update({"a": d["openlabel"]["objects"].pop("0")}),  # uid must be a number
    lambda d: d["openlabel"]["frames"]["0"]["objects"]["0"]["object_data"]["cuboid"][0]["val"].append(1.0),
    lambda d: d["openlabel"]["streams"]["level"].update(type="webcam"),
    lambda d: d["openlabel"]["metadata"].update(schema_version="0.3.0"),
])
def test_the_schema_check_is_live(written, break_it):
    data = copy.deepcopy(written[1])
    break_it(data)
    with pytest.raises(jsonschema.ValidationError):
        validate(data)


def test_cuboid_is_the_world_box_centre_xyzw_quaternion_and_lwh(written, known):
    _, results = known
    ol = written[1]["openlabel"]
    uid = {o["name"]: k for k, o in ol["objects"].items()}
    for f, frame in enumerate(results):
        for v in frame.vehicles:
            data = ol["frames"][str(f)]["objects"][uid[v.id]]["object_data"]
            if v.box is None:
                continue
            (cuboid,) = data["cuboid"]
            assert cuboid["name"] == "shape3D" and cuboid["coordinate_system"] == "world"
            x, y, z, qx, qy, qz, qw, length, width, height = cuboid["val"]
            assert np.allclose([x, y, z], v.box.world_T_box.translation(), atol=MM)  # the centre, not the bottom
            assert np.allclose([length, width, height], v.box.size, atol=MM)
            q = Quaternion(qw, qx, qy, qz)  # pyquaternion takes (w, x, y, z)
            assert rotation_error(q.rotation_matrix, v.box.world_T_box.rotation().matrix()) < DEG
    a = ol["frames"]["0"]["objects"][uid["a"]]["object_data"]["cuboid"][0]["val"]
    yaw = Quaternion(a[6], a[3], a[4], a[5]).yaw_pitch_roll[0]
    assert math.degrees(yaw) == pytest.approx(90.0, abs=0.1)  # heading +90 deg about world z stays +90


def test_cameras_are_world_children_with_their_pose_and_intrinsics(written, known):
    scene, _ = known
    ol = written[1]["openlabel"]
    assert ol["coordinate_systems"]["world"]["parent"] == ""
    point = np.array([12.0, 1.0, 0.5, 1.0])
    for name, cam in scene.cameras.items():
        cs, stream = ol["coordinate_systems"][name], ol["streams"][name]
        assert cs["parent"] == "world" and stream["type"] == "camera"
        M = np.array(cs["pose_wrt_parent"]["matrix4x4"]).reshape(4, 4)  # X_world = M X_camera
        pinhole = stream["stream_properties"]["intrinsics_pinhole"]
        P = np.array(pinhole["camera_matrix"]).reshape(3, 4)
        assert np.allclose(np.array(pinhole["camera_matrix_3x4"]), P)
        x = P @ np.linalg.inv(M) @ point
        cam_undistorted = cam.K @ cam.to_camera(point[None, :3])[0]
        assert np.allclose(x[:2] / x[2], cam_undistorted[:2] / cam_undistorted[2], atol=1e-6)
        assert pinhole["distortion_coeffs"] == pytest.approx(list(cam.dist))
        assert (pinhole["width_px"], pinhole["height_px"]) == cam.image_size


def test_keypoints_each_camera_saw_are_point2d_on_its_stream(written, known):
    scene, _ = known
    ol = written[1]["openlabel"]
    uid = {o["name"]: k for k, o in ol["objects"].items()}
    for det in scene.frames[1].detections:
        points = {p["name"]: p for p in ol["frames"]["1"]["objects"][uid[det.vehicle]]["object_data"]["point2d"]}
        for k, name in enumerate(KEYPOINT_NAMES):
            p = points.get(f"{det.camera}:{name}")
            if det.confidence[k] == 0:
                assert p is None
                continue
            assert p["stream"] == det.camera and p["coordinate_system"] == det.camera and p["id"] == k
            assert np.allclose(p["val"], det.keypoints[k], atol=1e-3)


def test_unsolved_vehicle_keeps_its_object_and_status_but_no_cuboid(written):
    _, data, report = written
    ol = data["openlabel"]
    uid = {o["name"]: k for k, o in ol["objects"].items()}
    c = ol["frames"]["0"]["objects"][uid["c"]]["object_data"]
    assert "cuboid" not in c and "point2d" in c
    texts = {t["name"]: t["val"] for t in c["text"]}
    assert texts["status"] == "failed" and texts["message"] == "LM raised on every start"
    assert report.unsolved == [(0, "c", "failed")] and report.skipped == []
    assert ol["objects"][uid["a"]]["frame_intervals"] == [{"frame_start": 0, "frame_end": 2}]
    assert ol["objects"][uid["d"]]["type"] == "pickup" and ol["objects"][uid["c"]]["type"] == "vehicle"


def test_read_openlabel_gives_the_boxes_back(written, known, real, tmp_path):
    _, results = known
    back = {(r.frame, r.id): r for r in read_openlabel(written[0])}
    for f, frame in enumerate(results):
        for v in frame.vehicles:
            got = back[(f, v.id)]
            assert got.status == v.status.value
            if v.box is None:
                assert got.box is None
            else:
                assert_same_box(got.box, v.box)
    scene, results = real
    write_openlabel(tmp_path / "real.json", results, scene)
    for r in read_openlabel(tmp_path / "real.json"):
        v = next(v for v in results[r.frame].vehicles if v.id == r.id)
        assert_same_box(r.box, v.box)


def test_bad_arguments_name_the_field(known, tmp_path):
    scene, results = known
    with pytest.raises(InputError, match="^world:"):
        write_openlabel(tmp_path / "x.json", results, scene, world="level")
    with pytest.raises(InputError, match="^scene:"):
        write_openlabel(tmp_path / "x.json", results[:2], scene)
    assert not (tmp_path / "x.json").exists()


def test_a_camera_named_world_does_not_stop_the_output(known, tmp_path):
    """The CLI names no world coordinate system: a camera called "world" made --format openlabel fail."""
    import dataclasses
    import json

    scene, results = known
    first = next(iter(scene.cameras))
    renamed = {("world" if n == first else n): dataclasses.replace(c, name="world" if n == first else n)
               for n, c in scene.cameras.items()}
    frames = [dataclasses.replace(f, detections=[dataclasses.replace(d, camera="world" if d.camera == first
                                                                     else d.camera) for d in f.detections])
              for f in scene.frames]
    named = dataclasses.replace(scene, cameras=renamed, frames=frames)
    write_openlabel(tmp_path / "w.json", results, named)
    systems = json.loads((tmp_path / "w.json").read_text())["openlabel"]["coordinate_systems"]
    assert systems["world_cs"]["type"] == "scene_cs" and systems["world"]["parent"] == "world_cs"
    assert len(read_openlabel(tmp_path / "w.json")) == len(read_openlabel(write_openlabel(
        tmp_path / "plain.json", results, scene).paths[0]))
