"""The PASCAL3D+ car loader on small annotation files written in the dataset's format (scipy.io.savemat)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import scipy.io

from vfactor.keypoints import KEYPOINT_NAMES
from vfactor.net.pascal3d import (
    PASCAL3D_CAR_KEYPOINTS,
    PASCAL3D_TO_VFACTOR,
    load_pascal3d,
    read_annotation,
    rear_left_right_votes,
)

VISIBLE, SELF_OCCLUDED, OCCLUDED, TRUNCATED = 1, 2, 3, 4
#: A car seen from its left, 1-based MATLAB pixels, status per PASCAL3D+ anchor.
LEFT_SIDE_VIEW = {
    "left_front_wheel": ((160.0, 150.0), VISIBLE),
    "left_back_wheel": ((80.0, 148.0), VISIBLE),
    "right_front_wheel": ((170.0, 140.0), SELF_OCCLUDED),
    "right_back_wheel": ((92.0, 139.0), SELF_OCCLUDED),
    "left_front_light": ((180.0, 128.0), VISIBLE),
    "right_front_light": ((186.0, 122.0), SELF_OCCLUDED),
    "left_back_trunk": ((62.0, 118.0), VISIBLE),
    "right_back_trunk": ((70.0, 112.0), OCCLUDED),
    "upper_left_windshield": ((140.0, 100.0), VISIBLE),
    "upper_right_windshield": ((146.0, 96.0), SELF_OCCLUDED),
    "upper_left_rearwindow": ((98.0, 101.0), VISIBLE),
    "upper_right_rearwindow": (None, TRUNCATED),
}
BBOX = [55, 92, 192, 158]  # xmin ymin xmax ymax, 1-based inclusive


def anchors_struct(view: dict, swap_rear: bool = False) -> dict:
    out = {}
    for name, (loc, status) in view.items():
        if swap_rear and ("back" in name or "rear" in name):
            name = name.replace("left", "LEFT").replace("right", "left").replace("LEFT", "right")
        out[name] = {"location": np.zeros((0, 0)) if loc is None else np.array([loc]), "status": float(status)}
    return out


def write_annotation(path: Path, filename: str, objects: list[dict]) -> None:
    dt = [("class", "O"), ("bbox", "O"), ("anchors", "O"), ("truncated", "O"), ("occluded", "O"), ("difficult", "O")]
    objs = np.zeros((1, len(objects)), dtype=dt)
    for i, o in enumerate(objects):
        objs[0, i] = (o["class"], np.array([o["bbox"]], float), o.get("anchors", np.zeros((0, 0))),
                      float(o.get("truncated", 0)), float(o.get("occluded", 0)), float(o.get("difficult", 0)))
    path.parent.mkdir(parents=True, exist_ok=True)
    scipy.io.savemat(path, {"record": {"filename": filename, "objects": objs}})


def draw_picture(path: Path, view: dict, shape=(200, 260)) -> None:
    """A grey picture with a 5x5 dot of a distinct colour at each annotated keypoint (MATLAB 1-based)."""
    img = np.full(shape + (3,), 90, np.uint8)
    for i, name in enumerate(PASCAL3D_CAR_KEYPOINTS):
        loc = view[name][0]
        if loc is not None:
            u, v = int(loc[0]) - 1, int(loc[1]) - 1
            img[v - 2 : v + 3, u - 2 : u + 3] = colour(i)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))


def colour(i: int) -> np.ndarray:
    return np.array([40 + 17 * i, 250 - 15 * i, (97 * i) % 256], np.uint8)


@pytest.fixture
def pascal_root(tmp_path) -> Path:
    root = tmp_path / "PASCAL3D+_release1.1"
    car = {"class": "car", "bbox": BBOX, "anchors": anchors_struct(LEFT_SIDE_VIEW)}
    write_annotation(root / "Annotations" / "car_imagenet" / "n001.mat", "n001.png",
                     [car, {"class": "bus", "bbox": [1, 1, 20, 20]}, {**car, "difficult": 1}])
    draw_picture(root / "Images" / "car_imagenet" / "n001.png", LEFT_SIDE_VIEW)
    write_annotation(root / "Annotations" / "car_pascal" / "2008_000001.mat", "2008_000001.png", [car])
    draw_picture(root / "Images" / "car_pascal" / "2008_000001.png", LEFT_SIDE_VIEW)
    return root


def test_mapping_covers_every_keypoint_once():
    assert set(PASCAL3D_TO_VFACTOR) == set(PASCAL3D_CAR_KEYPOINTS)
    assert sorted(PASCAL3D_TO_VFACTOR.values()) == sorted(KEYPOINT_NAMES)
    assert PASCAL3D_TO_VFACTOR["left_back_trunk"] == "left_back_light"


def test_read_annotation_keeps_cars_in_vfactor_order(pascal_root):
    objs = read_annotation(pascal_root / "Annotations" / "car_imagenet" / "n001.mat")
    assert [o.index for o in objs] == [0, 2] and [o.difficult for o in objs] == [False, True]
    o = objs[0]
    assert o.image_file == "n001.png"
    assert o.bbox == (54.0, 91.0, 192.0, 158.0)  # pixel edges
    for name, (loc, status) in LEFT_SIDE_VIEW.items():
        k = KEYPOINT_NAMES.index(PASCAL3D_TO_VFACTOR[name])
        assert o.status[k] == status
        if loc is None:
            assert np.all(np.isnan(o.keypoints[k]))
        else:
            np.testing.assert_allclose(o.keypoints[k], np.array(loc) - 1.0)  # 0-based pixel centres
    assert o.visible.sum() == 6 and o.self_occluded.sum() == 4


def test_samples_crop_the_box_with_keypoints_on_their_pixels(pascal_root):
    samples = load_pascal3d(pascal_root, size=128, margin=0.1, square=True)
    assert len(samples) == 2  # the bus and the difficult car are left out
    s = samples[0]
    assert s.image.shape == (128, 128, 3) and s.image.dtype == np.uint8
    x0, y0, x1, y1 = s.roi
    assert x1 - x0 == pytest.approx(y1 - y0, abs=1.0) and x0 <= 54 and x1 >= 192  # square, around the box
    assert s.meta["source"] == "pascal3d" and s.meta["object"] == 0
    for i, name in enumerate(PASCAL3D_CAR_KEYPOINTS):
        k = KEYPOINT_NAMES.index(PASCAL3D_TO_VFACTOR[name])
        if LEFT_SIDE_VIEW[name][0] is None:
            assert np.all(np.isnan(s.keypoints[k])) and not s.in_crop[k]
            continue
        u, v = np.rint(s.keypoints[k]).astype(int)
        np.testing.assert_allclose(s.image[v, u], colour(i), atol=12)
    assert s.visible.sum() == 6 and s.self_occluded.sum() == 4 and s.occluded_by_other.sum() == 1


def test_rear_left_right_auto_detects_crossed_labels(tmp_path):
    root = tmp_path / "p3d"
    crossed = {"class": "car", "bbox": BBOX, "anchors": anchors_struct(LEFT_SIDE_VIEW, swap_rear=True)}
    write_annotation(root / "Annotations" / "car_imagenet" / "a.mat", "a.png", [crossed, crossed])
    draw_picture(root / "Images" / "car_imagenet" / "a.png", LEFT_SIDE_VIEW)
    objs = read_annotation(root / "Annotations" / "car_imagenet" / "a.mat")
    assert rear_left_right_votes(objs) == (0, 2)
    as_named = load_pascal3d(root, subsets=("car_imagenet",), rear_left_right="as_named")
    fixed = load_pascal3d(root, subsets=("car_imagenet",), rear_left_right="auto")
    reference = as_named[0]
    lb, rb = KEYPOINT_NAMES.index("left_back_wheel"), KEYPOINT_NAMES.index("right_back_wheel")
    # as named, the visible rear wheel is called "right"; fixed, it is the left one, like the front
    assert as_named[0].visible[rb] and not as_named[0].visible[lb]
    assert fixed[0].visible[lb] and not fixed[0].visible[rb]
    np.testing.assert_array_equal(fixed[0].keypoints[lb], reference.keypoints[rb])
    assert fixed[0].meta["rear_left_right"] == "swapped"


def test_bad_input_is_reported(tmp_path):
    scipy.io.savemat(tmp_path / "x.mat", {"other": 1})
    with pytest.raises(ValueError, match="record"):
        read_annotation(tmp_path / "x.mat")
    with pytest.raises(ValueError, match="no PASCAL3D"):
        load_pascal3d(tmp_path / "empty")
    with pytest.raises(ValueError, match="rear_left_right"):
        load_pascal3d(tmp_path, rear_left_right="mirror")
