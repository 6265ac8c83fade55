"""nuScenes detection results read as the devkit's README defines them, rotations through pyquaternion."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pyquaternion import Quaternion

from tests.formats.helpers import DEG, MM, assert_same_box, rotation_error
from vfactor.errors import InputError
from vfactor.formats import read_nuscenes, write_nuscenes
from vfactor.formats.nuscenes import nuscenes_dict

SAMPLE_RESULT_KEYS = {"sample_token", "translation", "size", "rotation", "velocity", "detection_name",
                      "detection_score", "attribute_name"}
META_KEYS = {"use_camera", "use_lidar", "use_radar", "use_map", "use_external"}
ATTRIBUTES = {"vehicle.moving", "vehicle.parked", "vehicle.stopped", ""}


def devkit_yaw(q: Quaternion) -> float:
    """The devkit's quaternion_yaw: the box x axis rotated, its angle in the world x-y plane."""
    v = q.rotation_matrix @ np.array([1.0, 0.0, 0.0])
    return math.atan2(v[1], v[0])


@pytest.fixture(scope="module")
def written(known, tmp_path_factory):
    scene, results = known
    path = tmp_path_factory.mktemp("nuscenes") / "results.json"
    report = write_nuscenes(path, results, scene)
    return json.loads(path.read_text()), report, path


def check_submission(data: dict, n_samples: int):
    assert set(data) == {"meta", "results"} and set(data["meta"]) == META_KEYS
    assert all(isinstance(v, bool) for v in data["meta"].values())
    assert len(data["results"]) == n_samples
    for token, entries in data["results"].items():
        for e in entries:
            assert set(e) == SAMPLE_RESULT_KEYS and e["sample_token"] == token
            assert len(e["translation"]) == 3 and len(e["size"]) == 3 and len(e["velocity"]) == 2
            assert isinstance(e["detection_score"], float) and 0 <= e["detection_score"] <= 1
            assert e["detection_name"] in {"car", "truck"} and e["attribute_name"] in ATTRIBUTES
            assert abs(Quaternion(e["rotation"]).norm - 1) < 1e-6


def test_structure_is_the_devkits(written, real):
    check_submission(written[0], 3)
    assert list(written[0]["results"]) == ["000000", "000001", "000002"]
    assert written[0]["meta"]["use_camera"] is True and written[0]["meta"]["use_lidar"] is False
    check_submission(nuscenes_dict(real[1]), 2)


def test_boxes_are_world_centres_wlh_and_wxyz(written, known):
    data, _, _ = written
    _, results = known
    for f, frame in enumerate(results):
        entries = data["results"][f"{f:06d}"]
        boxes = [v.box for v in frame.vehicles if v.box is not None]
        assert len(entries) == len(boxes)
        for e, box in zip(entries, boxes):
            assert np.allclose(e["translation"], box.world_T_box.translation(), atol=MM)  # centre, not bottom
            assert np.allclose(e["size"], [box.size[1], box.size[0], box.size[2]], atol=MM)  # w, l, h
            q = Quaternion(e["rotation"])  # (w, x, y, z)
            assert rotation_error(q.rotation_matrix, box.world_T_box.rotation().matrix()) < DEG  # roll/pitch kept
            assert abs(math.remainder(devkit_yaw(q) - box.heading, 2 * math.pi)) < DEG
    a = data["results"]["000000"][0]
    assert math.degrees(devkit_yaw(Quaternion(a["rotation"]))) == pytest.approx(90.0, abs=0.1)
    b = data["results"]["000000"][1]  # heading 0, pitch 5 deg, roll -3 deg: R = Ry(5) Rx(-3)
    p, r = math.radians(5.0), math.radians(-3.0)
    Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    assert rotation_error(Quaternion(b["rotation"]).rotation_matrix, Ry @ Rx) < DEG


def test_velocity_attribute_class_and_score(written):
    data, _, _ = written
    a = [e for token in data["results"] for e in data["results"][token] if e["translation"][0] == 10.0]
    assert [e["velocity"] for e in a] == [pytest.approx([0.0, 5.0], abs=1e-6)] * 3  # 2.5 m per 0.5 s along +y
    assert {e["attribute_name"] for e in a} == {"vehicle.moving"}
    b0, b1 = data["results"]["000000"][1], data["results"]["000001"][1]
    assert b0["velocity"] == [0.0, 0.0] and b0["attribute_name"] == b1["attribute_name"] == "vehicle.stopped"
    d = data["results"]["000001"][2]  # a pickup (0.7) that might be an SUV (0.2) or a van (0.1)
    assert d["attribute_name"] == "" and d["velocity"] == [0.0, 0.0]  # one frame: speed unknown
    assert d["detection_name"] == "truck" and d["detection_score"] == pytest.approx(0.7)
    assert data["results"]["000000"][0]["detection_name"] == "car"


def test_unsolved_are_skipped_and_reported(written):
    data, report, _ = written
    assert len(data["results"]["000000"]) == 2
    assert report.skipped == [(0, "c", "failed")]


def test_sample_tokens_and_bad_arguments(known, tmp_path):
    _, results = known
    tokens = ["3e8750f331d7499e9b5123e9eb70f2e2", "e93e98b63d3b40209056d129dc53ceee", "f9878012c3f6412184c294c13ba4bac3"]
    data = nuscenes_dict(results, sample_tokens=tokens)
    assert list(data["results"]) == tokens
    for bad, field in [({"sample_tokens": tokens[:2]}, "sample_tokens"), ({"sample_tokens": [tokens[0]] * 3},
                       "sample_tokens"), ({"meta": {"use_camera": True}}, "meta"), ({"names": {"van": "lorry"}},
                       "names"), ({"moving_speed": -1.0}, "moving_speed")]:
        with pytest.raises(InputError, match=f"^{field}:"):
            write_nuscenes(tmp_path / "x.json", results, **bad)
    assert not (tmp_path / "x.json").exists()


def test_read_nuscenes_gives_the_boxes_back(written, known):
    _, _, path = written
    _, results = known
    back = read_nuscenes(path)
    want = [v.box for frame in results for v in frame.vehicles if v.box is not None]
    assert len(back) == len(want)
    for r, box in zip(back, want):
        assert_same_box(r.box, box)
