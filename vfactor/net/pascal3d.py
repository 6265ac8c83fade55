"""PASCAL3D+ car keypoint annotations as vfactor training samples (numpy, scipy and OpenCV; no torch).

PASCAL3D+ (release 1.1, Stanford CVGL; a research dataset the user obtains
separately) annotates cars in ``Annotations/car_imagenet/*.mat`` and
``Annotations/car_pascal/*.mat``, the pictures being in
``Images/car_imagenet/`` and ``Images/car_pascal/``. Each file holds a MATLAB
struct ``record`` with ``filename`` (the picture), and ``objects``, a struct
array whose elements have ``class`` ("car"), ``bbox`` ``[xmin ymin xmax ymax]``
(1-based, inclusive pixel indices, as in PASCAL VOC), ``truncated``,
``occluded``, ``difficult``, and ``anchors``: a struct with one field per car
keypoint, each a struct with ``location`` (``[x y]``, 1-based MATLAB pixel
coordinates; empty when not annotated) and ``status``.

Keypoints (PASCAL3D+ name -> vfactor name, :data:`PASCAL3D_TO_VFACTOR`):

=========================  =======================
left_front_wheel           left_front_wheel
right_front_wheel          right_front_wheel
left_back_wheel            left_back_wheel
right_back_wheel           right_back_wheel
left_front_light           left_front_light
right_front_light          right_front_light
left_back_trunk            left_back_light
right_back_trunk           right_back_light
upper_left_windshield      left_up_windshield
upper_right_windshield     right_up_windshield
upper_left_rearwindow      left_up_rear_window
upper_right_rearwindow     right_up_rear_window
=========================  =======================

PASCAL3D+ has no back-light keypoints: its rear corners of the trunk stand in
for vfactor's back lights (they sit a little higher and further back than the
lamps, the price of reusing the dataset).

Status (:data:`STATUS`): 1 visible, 2 self-occluded, 3 occluded by another
object, 4 truncated (outside the picture), 5 unknown -- the codes of the
PASCAL3D+ annotation tool. ``visible`` is status 1, ``self_occluded`` status 2;
a keypoint with a location but another status is still a training target (its
weight is 1 inside the crop) but is scored in neither PCK category.

Left and right: ``vfactor/data/pascal3d_car_shapes.json`` records that PASCAL3D+'s
own left/right labels are inconsistent between the front and the rear parts of
its CAD anchors (vfactor assigns left/right there by geometry). In pictures no
geometry is at hand, so :func:`load_pascal3d` checks the convention from the
annotations themselves (``rear_left_right="auto"``): in a side view the two
wheels of the near side are visible and the two of the far side self-occluded;
if, over the files read, the visible pairs are mostly (left front, right back)
rather than (left front, left back), the rear keypoints' left and right (back
wheels, trunk corners, rear-window corners) are swapped. ``"as_named"`` and
``"swap_rear"`` force either reading.

Coordinates: MATLAB's pixel ``(x, y)`` (1-based, centre of the pixel) is
vfactor's ``(u, v) = (x - 1, y - 1)`` (0-based centres, OpenCV); the VOC box
``[xmin ymin xmax ymax]`` covers pixel edges ``(xmin - 1, ymin - 1, xmax, ymax)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator

import cv2
import numpy as np
import scipy.io

from vfactor.keypoints import KEYPOINT_NAMES, NUM_KEYPOINTS
from vfactor.net.crop import crop_roi, expand_roi, image_to_crop
from vfactor.net.data import Sample
from vfactor.net.targets import in_crop

__all__ = [
    "PASCAL3D_CAR_KEYPOINTS",
    "PASCAL3D_TO_VFACTOR",
    "STATUS",
    "PascalObject",
    "read_annotation",
    "find_annotations",
    "rear_left_right_votes",
    "iter_samples",
    "load_pascal3d",
]

log = logging.getLogger("vfactor.net.pascal3d")

#: The 12 car anchors of PASCAL3D+ (the field names of ``objects(i).anchors``).
PASCAL3D_CAR_KEYPOINTS: tuple[str, ...] = (
    "left_front_wheel", "left_back_wheel", "right_front_wheel", "right_back_wheel",
    "upper_left_windshield", "upper_right_windshield", "upper_left_rearwindow", "upper_right_rearwindow",
    "left_front_light", "right_front_light", "left_back_trunk", "right_back_trunk",
)

#: PASCAL3D+ anchor name -> vfactor keypoint name (the trunk corners stand in for the back lights).
PASCAL3D_TO_VFACTOR: dict[str, str] = {
    "left_front_wheel": "left_front_wheel",
    "right_front_wheel": "right_front_wheel",
    "left_back_wheel": "left_back_wheel",
    "right_back_wheel": "right_back_wheel",
    "left_front_light": "left_front_light",
    "right_front_light": "right_front_light",
    "left_back_trunk": "left_back_light",
    "right_back_trunk": "right_back_light",
    "upper_left_windshield": "left_up_windshield",
    "upper_right_windshield": "right_up_windshield",
    "upper_left_rearwindow": "left_up_rear_window",
    "upper_right_rearwindow": "right_up_rear_window",
}

#: Anchor status codes of the PASCAL3D+ annotations.
STATUS: dict[str, int] = {"visible": 1, "self_occluded": 2, "occluded": 3, "truncated": 4, "unknown": 5}

#: vfactor indices of the rear keypoints whose left/right may be swapped: back wheels, back lights, rear window.
_REAR_PAIRS = ((2, 3), (6, 7), (10, 11))
_VF_INDEX = {name: i for i, name in enumerate(KEYPOINT_NAMES)}
_LEFT_RIGHT_MODES = ("auto", "as_named", "swap_rear")


@dataclass
class PascalObject:
    """One annotated car of a PASCAL3D+ file, in vfactor's keypoint order and pixel convention.

    Attributes:
        annotation: the ``.mat`` file.
        image_file: the picture's file name (``record.filename``).
        index: the object's index in ``record.objects`` (0-based).
        bbox: ``(x0, y0, x1, y1)`` pixel edges.
        keypoints: (12, 2) image pixels ``(u, v)``; NaN where not annotated.
        status: (12,) PASCAL3D+ status codes (0 where absent).
        truncated, occluded, difficult: the object's flags.
    """

    annotation: Path
    image_file: str
    index: int
    bbox: tuple
    keypoints: np.ndarray
    status: np.ndarray
    truncated: bool = False
    occluded: bool = False
    difficult: bool = False
    meta: dict = field(default_factory=dict)

    @property
    def visible(self) -> np.ndarray:
        return self.status == STATUS["visible"]

    @property
    def self_occluded(self) -> np.ndarray:
        return self.status == STATUS["self_occluded"]

    def swapped_rear(self) -> "PascalObject":
        """The same object with the rear keypoints' left and right exchanged."""
        perm = np.arange(NUM_KEYPOINTS)
        for a, b in _REAR_PAIRS:
            perm[a], perm[b] = b, a
        return PascalObject(self.annotation, self.image_file, self.index, self.bbox, self.keypoints[perm],
                            self.status[perm], self.truncated, self.occluded, self.difficult,
                            dict(self.meta, rear_left_right="swapped"))


def read_annotation(path, class_name: str = "car") -> list[PascalObject]:
    """The objects of class ``class_name`` with car anchors in one PASCAL3D+ ``.mat`` file.

    Raises:
        ValueError: not a PASCAL3D+ annotation (no ``record`` struct), or a malformed field (named).
    """
    path = Path(path)
    try:
        mat = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    except (OSError, ValueError, TypeError) as exc:
        raise ValueError(f"{path}: cannot read as a MATLAB file: {exc}") from None
    if "record" not in mat:
        raise ValueError(f"{path}: no 'record' struct (not a PASCAL3D+ annotation)")
    record = mat["record"]
    image_file = str(getattr(record, "filename", ""))
    objects = np.atleast_1d(getattr(record, "objects", np.array([])))
    out = []
    for i, obj in enumerate(objects):
        if str(getattr(obj, "class", "")) != class_name:
            continue
        anchors = getattr(obj, "anchors", None)
        if anchors is None or isinstance(anchors, np.ndarray) or not hasattr(anchors, "_fieldnames"):
            continue  # no keypoints for this object
        where = f"{path.name}: objects[{i}]"
        kp = np.full((NUM_KEYPOINTS, 2), np.nan)
        status = np.zeros(NUM_KEYPOINTS, dtype=int)
        for name in PASCAL3D_CAR_KEYPOINTS:
            a = getattr(anchors, name, None)
            if a is None:
                continue
            k = _VF_INDEX[PASCAL3D_TO_VFACTOR[name]]
            loc = np.asarray(getattr(a, "location", []), dtype=float).ravel()
            st = np.asarray(getattr(a, "status", [])).ravel()
            if st.size:
                status[k] = int(st[0])
            if loc.size == 2 and np.all(np.isfinite(loc)):
                kp[k] = loc - 1.0  # MATLAB 1-based pixel centres -> 0-based
            elif loc.size not in (0, 2):
                raise ValueError(f"{where}.anchors.{name}.location: expected [x y] or empty, got {loc.tolist()}")
        bbox = np.asarray(getattr(obj, "bbox", []), dtype=float).ravel()
        if bbox.size != 4 or not np.all(np.isfinite(bbox)) or bbox[2] < bbox[0] or bbox[3] < bbox[1]:
            raise ValueError(f"{where}.bbox: expected [xmin ymin xmax ymax], got {bbox.tolist()}")
        out.append(PascalObject(
            annotation=path, image_file=image_file, index=i,
            bbox=(bbox[0] - 1.0, bbox[1] - 1.0, bbox[2], bbox[3]), keypoints=kp, status=status,
            truncated=_flag(obj, "truncated"), occluded=_flag(obj, "occluded"), difficult=_flag(obj, "difficult"),
        ))
    return out


def find_annotations(root, subsets: Iterable[str] = ("car_imagenet", "car_pascal")) -> list[Path]:
    """The ``.mat`` files of ``root/Annotations/<subset>/`` (or of ``root`` itself when it holds them)."""
    root = Path(root)
    files: list[Path] = []
    if any(root.glob("*.mat")):
        files = sorted(root.glob("*.mat"))
    else:
        for sub in subsets:
            files.extend(sorted((root / "Annotations" / sub).glob("*.mat")))
    if not files:
        raise ValueError(f"{root}: no PASCAL3D+ annotations (expected Annotations/{{{','.join(subsets)}}}/*.mat)")
    return files


def rear_left_right_votes(objects: Iterable[PascalObject]) -> tuple[int, int]:
    """Counts side views whose visible wheel pair reads consistently vs crossed.

    A side view: two wheels visible and the other two self-occluded. Consistent:
    the visible pair is (left front, left back) or (right front, right back).
    Crossed: (left front, right back) or (right front, left back), the sign of
    rear labels given from the other side.

    Returns:
        ``(consistent, crossed)``.
    """
    consistent = crossed = 0
    vis_code, occ_code = STATUS["visible"], STATUS["self_occluded"]
    for o in objects:
        s = o.status[:4]  # left front, right front, left back, right back
        vis, occ = s == vis_code, s == occ_code
        if vis.sum() != 2 or occ.sum() != 2:
            continue
        pair = tuple(np.flatnonzero(vis))
        if pair in ((0, 2), (1, 3)):
            consistent += 1
        elif pair in ((0, 3), (1, 2)):
            crossed += 1
    return consistent, crossed


def iter_samples(objects: Iterable[PascalObject], image_dir, size: int = 128, margin: float = 0.1,
                 square: bool = True, min_keypoints: int = 1) -> Iterator:
    """Crops each object's box (grown by ``margin`` per side, squared) to ``size x size`` samples.

    Args:
        objects: from :func:`read_annotation`.
        image_dir: folder of the pictures (``Images/car_imagenet`` ...), or a
            callable ``(PascalObject) -> Path``.
        size: side of the crops.
        margin, square: framing of the crop around the box (see
            :func:`vfactor.net.crop.expand_roi`); use the same at inference.
        min_keypoints: skip objects with fewer annotated keypoints.

    Yields:
        ``Sample`` records (image, keypoints in crop pixels, visible,
        self_occluded, roi in picture pixels, meta with the file, object index
        and statuses).
    """
    cache: dict[Path, np.ndarray] = {}
    for o in objects:
        if np.count_nonzero(np.all(np.isfinite(o.keypoints), axis=1)) < min_keypoints:
            continue
        path = Path(image_dir(o)) if callable(image_dir) else Path(image_dir) / o.image_file
        if path not in cache:
            cache.clear()  # objects of one picture come together: keep one picture
            bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if bgr is None:
                raise ValueError(f"{o.annotation.name}: cannot read the picture {path}")
            cache[path] = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        image = cache[path]
        box = expand_roi(o.bbox, margin, square)
        crop, used = crop_roi(image, box, size)
        keypoints = image_to_crop(o.keypoints, used, size).astype(np.float32)
        inside = in_crop(keypoints, size)
        yield Sample(
            image=crop,
            keypoints=keypoints,
            visible=o.visible & inside,
            self_occluded=o.self_occluded & inside,
            roi=used,
            meta={"source": "pascal3d", "annotation": str(o.annotation), "image": str(path), "object": o.index,
                  "status": o.status.tolist(), "difficult": o.difficult, **o.meta},
            occluded_by_other=(o.status == STATUS["occluded"]) & inside,
            in_crop=inside,
        )


def load_pascal3d(root, image_root=None, subsets=("car_imagenet", "car_pascal"), size: int = 128,
                  margin: float = 0.1, square: bool = True, rear_left_right: str = "auto",
                  skip_difficult: bool = True, min_keypoints: int = 1, limit: int | None = None) -> list:
    """PASCAL3D+ car samples, ready for :func:`vfactor.net.train.train`.

    Args:
        root: the PASCAL3D+ folder (``PASCAL3D+_release1.1``) or a folder of ``.mat`` files.
        image_root: the pictures' folder when ``root`` is a folder of ``.mat``
            files; else ``root/Images/<subset>`` is used for each file.
        subsets: annotation subsets under ``root/Annotations``.
        size, margin, square, min_keypoints: see :func:`iter_samples`.
        rear_left_right: "auto" (decide from :func:`rear_left_right_votes`),
            "as_named" or "swap_rear"; see the module docstring.
        skip_difficult: leave out objects flagged ``difficult``.
        limit: read at most this many annotation files.

    Returns:
        A list of ``Sample`` records.
    """
    if rear_left_right not in _LEFT_RIGHT_MODES:
        raise ValueError(f"rear_left_right: expected one of {_LEFT_RIGHT_MODES}, got {rear_left_right!r}")
    files = find_annotations(root, subsets)[: limit if limit is not None else None]
    objects = [o for f in files for o in read_annotation(f) if not (skip_difficult and o.difficult)]
    swap = rear_left_right == "swap_rear"
    if rear_left_right == "auto":
        consistent, crossed = rear_left_right_votes(objects)
        swap = crossed > consistent
        log.info("PASCAL3D+ rear left/right: %d consistent and %d crossed side views -> %s", consistent, crossed,
                 "swapping the rear keypoints" if swap else "labels as named")
    if swap:
        objects = [o.swapped_rear() for o in objects]

    def picture(o: PascalObject) -> Path:
        if image_root is not None:
            return Path(image_root) / o.image_file
        return Path(root) / "Images" / o.annotation.parent.name / o.image_file

    return list(iter_samples(objects, picture, size=size, margin=margin, square=square, min_keypoints=min_keypoints))


def _flag(obj, name: str) -> bool:
    v = np.asarray(getattr(obj, name, 0)).ravel()
    return bool(v[0]) if v.size else False
