"""KITTI labels read by a parser written from the object devkit's readme, with the devkit's box model."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tests.formats.helpers import DEG, MM, assert_same_box, make_box, solved
from vfactor.errors import InputError
from vfactor.formats import read_kitti, write_kitti
from vfactor.formats.common import box_corners
from vfactor.observations import Scene
from vfactor.result import FrameResult

FIELDS = ("type", "truncated", "occluded", "alpha", "x1", "y1", "x2", "y2", "h", "w", "l", "x", "y", "z",
          "rotation_y", "score")


def parse_labels(path: Path) -> list[dict]:
    """The readme's fields: type, then 14 numbers (+ score for results)."""
    out = []
    for line in path.read_text().splitlines():
        parts = line.split(" ")
        assert len(parts) == 16, line
        out.append({k: (v if k == "type" else float(v)) for k, v in zip(FIELDS, parts)})
    return out


def parse_calib(path: Path) -> dict[str, np.ndarray]:
    out = {}
    for line in path.read_text().splitlines():
        key, values = line.split(":")
        out[key] = np.array([float(v) for v in values.split()])
    return out


def devkit_corners(label: dict) -> np.ndarray:
    """(8, 3) corners in the label frame as the devkit's computeBox3D builds them."""
    h, w, length, ry = label["h"], label["w"], label["l"], label["rotation_y"]
    x = [length / 2, length / 2, -length / 2, -length / 2, length / 2, length / 2, -length / 2, -length / 2]
    y = [0, 0, 0, 0, -h, -h, -h, -h]
    z = [w / 2, -w / 2, -w / 2, w / 2, w / 2, -w / 2, -w / 2, w / 2]
    R = np.array([[math.cos(ry), 0, math.sin(ry)], [0, 1, 0], [-math.sin(ry), 0, math.cos(ry)]])
    return (R @ np.array([x, y, z])).T + [label["x"], label["y"], label["z"]]


def same_angle(a: float, b: float) -> bool:
    return abs(math.remainder(a - b, 2 * math.pi)) < DEG


def same_corner_sets(a: np.ndarray, b: np.ndarray, tol: float = MM) -> bool:
    return all(np.min(np.linalg.norm(b - p, axis=1)) < tol for p in a)


@pytest.fixture(scope="module")
def written(known, tmp_path_factory):
    scene, results = known
    folder = tmp_path_factory.mktemp("kitti")
    return folder, write_kitti(folder, results, scene)


def test_level_camera_by_hand(written):
    """Camera at (0, 0, 1.5) looking along +x: a box at (10, 2, 0.75), heading +90 deg, h 1.5."""
    folder, _ = written
    a = parse_labels(folder / "level" / "label_2" / "000000.txt")[0]
    assert a["type"] == "Car" and a["score"] == pytest.approx(1.0)  # sedan 0.9 + suv 0.1, both Car
    assert [a["h"], a["w"], a["l"]] == pytest.approx([1.5, 1.8, 4.5], abs=MM)
    assert [a["x"], a["y"], a["z"]] == pytest.approx([-2.0, 1.5, 10.0], abs=MM)  # bottom centre, camera frame
    assert same_angle(a["rotation_y"], math.pi)  # forward = world +y = camera -x
    assert same_angle(a["alpha"], math.pi - math.atan2(-2.0, 10.0))
    assert a["occluded"] == 3
    d = parse_labels(folder / "level" / "label_2" / "000001.txt")[-1]  # heading 180: facing the camera
    assert d["type"] == "Truck" and d["score"] == pytest.approx(0.7)
    assert d["rotation_y"] == pytest.approx(math.pi / 2, abs=DEG)


def test_heading_along_the_optical_axis_is_minus_half_pi(known, tmp_path):
    scene, _ = known
    results = [FrameResult(0.0, [solved("e", make_box([20.0, 0.0, 0.75], 0.0))])]
    write_kitti(tmp_path, results, Scene(scene.cameras, scene.frames[:1]), cameras=["level"])
    (e,) = parse_labels(tmp_path / "level" / "label_2" / "000000.txt")
    assert e["rotation_y"] == pytest.approx(-math.pi / 2, abs=DEG)


def test_devkit_box_model_gives_our_corners_and_2d_box(written, known):
    folder, _ = written
    scene, results = known
    cam = scene.cameras["level"]
    label = parse_labels(folder / "level" / "label_2" / "000000.txt")[0]
    ours = cam.to_camera(box_corners(results[0].vehicles[0].box))
    assert same_corner_sets(devkit_corners(label), ours)
    P2 = parse_calib(folder / "level" / "calib" / "000000.txt")["P2"].reshape(3, 4)
    x = P2 @ np.vstack([devkit_corners(label).T, np.ones(8)])
    uv = (x[:2] / x[2]).T
    assert [label["x1"], label["y1"], label["x2"], label["y2"]] == pytest.approx(
        [*np.clip(uv.min(0), 0, [1279, 719]), *np.clip(uv.max(0), 0, [1279, 719])], abs=0.01)


def test_pitched_box_keeps_centre_and_size_and_projected_yaw(written, known):
    folder, _ = written
    scene, results = known
    cam = scene.cameras["level"]
    box = results[0].vehicles[1].box  # heading 0, pitch 5, roll -3
    b = parse_labels(folder / "level" / "label_2" / "000000.txt")[1]
    centre = cam.to_camera(box.world_T_box.translation()[None])[0]
    assert [b["x"], b["y"] - b["h"] / 2, b["z"]] == pytest.approx(centre, abs=MM)
    assert [b["l"], b["w"], b["h"]] == pytest.approx(box.size, abs=MM)
    f = cam.camera_T_world[:3, :3] @ box.world_T_box.rotation().matrix()[:, 0]
    assert b["rotation_y"] == pytest.approx(math.atan2(-f[2], f[0]), abs=DEG)


def test_level_frame_makes_a_tilted_camera_exact(known, tmp_path):
    scene, results = known
    write_kitti(tmp_path, results, scene, cameras=["tilted"], frame="level")
    calib = parse_calib(tmp_path / "tilted" / "calib" / "000000.txt")
    label_T_world = np.vstack([calib["Tr_velo_to_cam"].reshape(3, 4), [0, 0, 0, 1]])
    assert np.allclose(label_T_world[:3, :3].T @ [0, 1, 0], [0, 0, -1])  # label y = world down
    (a, _) = parse_labels(tmp_path / "tilted" / "label_2" / "000000.txt")
    want = box_corners(results[0].vehicles[0].box) @ label_T_world[:3, :3].T + label_T_world[:3, 3]
    assert same_corner_sets(devkit_corners(a), want)
    # P2 projects label-frame points like the camera (without its distortion)
    cam = scene.cameras["tilted"]
    P2 = calib["P2"].reshape(3, 4)
    x = P2 @ np.append(want[0], 1.0)
    k = cam.K @ cam.to_camera(box_corners(results[0].vehicles[0].box)[:1])[0]
    assert np.allclose(x[:2] / x[2], k[:2] / k[2], atol=1e-6)
    with pytest.raises(InputError, match="^frame:"):
        write_kitti(tmp_path, results, scene, frame="rectified")


def test_truncation_and_clipping_at_the_image_border(known, tmp_path):
    scene, _ = known
    results = [FrameResult(0.0, [solved("edge", make_box([8.0, 7.0, 0.75], 0.0))])]  # half out on the left
    write_kitti(tmp_path, results, Scene(scene.cameras, scene.frames[:1]), cameras=["level"])
    (e,) = parse_labels(tmp_path / "level" / "label_2" / "000000.txt")
    assert e["x1"] == 0.0 and 0.05 < e["truncated"] < 0.95
    behind = [FrameResult(0.0, [solved("behind", make_box([-8.0, 0.0, 0.75], 0.0))])]
    write_kitti(tmp_path, behind, Scene(scene.cameras, scene.frames[:1]), cameras=["level"])
    assert (tmp_path / "level" / "label_2" / "000000.txt").read_text() == ""


def test_unsolved_are_skipped_and_reported(written, known):
    folder, report = written
    assert report.skipped == [(0, "c", "failed")] and "left out of the kitti output" in report.note()
    assert len(parse_labels(folder / "level" / "label_2" / "000000.txt")) == 2  # a, b; not c
    assert sorted(p.name for p in (folder / "tilted" / "label_2").iterdir()) == ["000000.txt", "000001.txt",
                                                                                 "000002.txt"]


def test_read_kitti_gives_the_world_boxes_back(written, known, real, tmp_path):
    folder, _ = written
    _, results = known
    back = [r for r in read_kitti(folder) if r.camera == "level" and r.frame == 0]
    assert_same_box(back[0].box, results[0].vehicles[0].box)  # level box, level camera: exact
    scene, results = real
    write_kitti(tmp_path, results, scene, frame="level")
    for r in read_kitti(tmp_path):
        v = results[r.frame].vehicles[0]
        assert_same_box(r.box, v.box, rotation=False)  # centre, size, heading; the small tilt is not KITTI's


def test_a_rerun_with_fewer_frames_leaves_no_stale_frame(known, tmp_path):
    scene, results = known
    write_kitti(tmp_path, results, scene)
    (tmp_path / "tilted" / "notes.txt").write_text("mine")  # not a frame file: kept
    import dataclasses

    write_kitti(tmp_path, results[:1], dataclasses.replace(scene, frames=scene.frames[:1]))
    for kind in ("label_2", "calib"):
        assert sorted(p.name for p in (tmp_path / "tilted" / kind).iterdir()) == ["000000.txt"]
    assert (tmp_path / "tilted" / "notes.txt").read_text() == "mine"
    assert {r.frame for r in read_kitti(tmp_path)} == {0}


@pytest.mark.parametrize("name", ["../escaped", "a/b", "..", "/tmp/abs"])
def test_a_camera_name_that_is_not_a_folder_name_is_refused(known, tmp_path, name):
    import dataclasses

    scene, results = known
    first = next(iter(scene.cameras))
    renamed = {(name if n == first else n): dataclasses.replace(c, name=name if n == first else n)
               for n, c in scene.cameras.items()}
    bad = dataclasses.replace(scene, cameras=renamed)
    with pytest.raises(InputError) as info:
        write_kitti(tmp_path / "out", results, bad)
    assert info.value.field == "cameras[0].name" and not (tmp_path / "out").exists()
    assert not (tmp_path / "escaped").exists()


def test_other_cameras_folders_in_the_output_are_named(known, tmp_path):
    scene, results = known
    write_kitti(tmp_path, results, scene)  # both cameras
    report = write_kitti(tmp_path, results, scene, cameras=["level"])
    assert report.foreign == ["tilted/"] and "also holds tilted/, which this run did not write" in report.note()
    assert write_kitti(tmp_path / "fresh", results, scene).foreign == []
