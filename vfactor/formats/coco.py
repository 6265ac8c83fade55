"""COCO-style keypoint files (detector results, annotation files) -> vfactor scene.

Keypoint detectors (mmpose, OpenPifPaf, detectron2, ...) write their output as
a COCO *results* file: a JSON list of
``{"image_id", "category_id", "keypoints": [x1, y1, s1, ...], "score", "bbox"?}``.
Data sets come as COCO *annotation* files: ``{"images", "annotations",
"categories"}``, whose keypoints carry a visibility flag (0 not labelled, 1
labelled but not visible, 2 visible). :func:`coco_to_scene` reads one such
file per camera and builds a vfactor :class:`~vfactor.observations.Scene`
(docs/keypoint-sets.md describes every option; the short version):

* keypoints: the file's points are in a named keypoint set
  (:data:`vfactor.formats.keypoint_sets.KEYPOINT_SETS`), mapped to vfactor's 12.
* third values: confidences in [0, 1] (results files) or visibility flags
  (annotation files): ``values="auto"`` picks by the file's kind.
* pixels: COCO keypoints are pixel indices, integer at pixel centres
  (detectron2 says so and shifts its own predictions by -0.5 on writing; mmpose
  and OpenPifPaf flip images as ``x' = w - 1 - x``), which is vfactor's
  convention: no shift by default; ``pixel_origin="corner"`` for a tool whose
  coordinates start at the top-left pixel's outer corner (subtracts 0.5 px).
* frames: by default ``image_id`` is the frame index; with an ``images`` list
  (an annotation file, or ``images=`` for a results file) the k-th image by
  ``file_name`` of each camera is frame k; or a given mapping. Times ``t`` are
  ``index / fps``, else the images' ``timestamp`` (seconds), else the index.
* vehicles: an annotation's ``track_id`` or ``vehicle`` is the detection's
  vehicle id; without ids a frame may hold one detection per camera (one vehicle).

The scene is built as a scene-file dictionary (:func:`coco_to_scene_dict`) and
passed through :func:`vfactor.scene.scene_from_dict`, so every check of a scene
file applies; :func:`import_coco` also writes it with :func:`vfactor.scene.save_scene`.
Bad input raises :class:`~vfactor.errors.SceneError` whose field is the file and
the path inside it (``cam0.json[3].keypoints``), or
:class:`~vfactor.errors.InputError` naming the option.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vfactor.camera import Camera
from vfactor.errors import InputError, SceneError
from vfactor.formats.keypoint_sets import KEYPOINT_SETS, KeypointSet, keypoint_set as _keypoint_set
from vfactor.jsonio import describe as _kind, is_number as _is_number, read_json
from vfactor.observations import Scene
from vfactor.scene import save_scene, scene_from_dict

__all__ = [
    "KEYPOINT_SETS",
    "VALUE_KINDS",
    "TRACK_ID_KINDS",
    "FRAME_MODES",
    "PIXEL_ORIGINS",
    "DEFAULT_VISIBILITY_CONFIDENCE",
    "SKIP_REASONS",
    "coco_to_scene_dict",
    "coco_to_scene",
    "import_coco",
]

#: How the third number of each keypoint is read: ``"confidence"`` in [0, 1]
#: (detector output), ``"visibility"`` 0/1/2 (annotations), ``"auto"``:
#: confidence for a results list, visibility for an annotation file.
VALUE_KINDS = ("auto", "confidence", "visibility")
#: How images map to frames: ``"auto"`` (``"file_name"`` when every camera has
#: an images list, else ``"image_id"``), ``"image_id"`` (the id is the frame
#: index), ``"file_name"`` (the k-th image of a camera by file name is frame k);
#: or a mapping camera -> {image id: frame index}.
FRAME_MODES = ("auto", "image_id", "file_name")
#: Where pixel (0, 0) lies: ``"centre"`` of the top-left pixel (COCO, vfactor;
#: no shift) or its outer ``"corner"`` (0.5 px subtracted from x and y).
PIXEL_ORIGINS = ("centre", "corner")
#: What an entry's ``track_id`` is: the vehicle id every camera shares, or a camera's own 2D tracker's id.
TRACK_ID_KINDS = ("shared", "per-camera")
#: Confidence of an annotated keypoint of visibility 1 (labelled, not visible)
#: and 2 (visible); visibility 0 (not labelled) is always not seen.
DEFAULT_VISIBILITY_CONFIDENCE = (0.5, 1.0)

_ID_KEYS = ("track_id", "vehicle")
#: Why a detection of a file is left out of the scene: a crowd annotation (``iscrowd`` 1), a ``score`` under
#: ``min_score``, or no keypoint of vfactor's 12 seen (after ``min_confidence``).
SKIP_REASONS = ("crowd", "score", "no keypoint")


# ================================================================ public API
def coco_to_scene_dict(
    cameras,
    results: Mapping[str, str | os.PathLike],
    keypoint_set: str | KeypointSet,
    *,
    values: str = "auto",
    visibility_confidence: tuple[float, float] = DEFAULT_VISIBILITY_CONFIDENCE,
    min_confidence: float = 0.0,
    min_score: float = 0.0,
    frames: str | Mapping[str, Mapping[Any, int]] = "auto",
    images: Mapping[str, str | os.PathLike] | None = None,
    fps: float | None = None,
    pixel_origin: str = "centre",
    track_ids: str = "shared",
    skipped: dict | None = None,
) -> dict:
    """A scene-file dictionary (docs/scene-format.md) from COCO keypoint files, one per camera.

    Args:
        cameras: the calibrated cameras: a list or dict of
            :class:`~vfactor.camera.Camera`, a :class:`~vfactor.observations.Scene`,
            or the path of a JSON file with a ``cameras`` list (a scene file or
            one with its ``cameras`` and optional ``ground_plane`` only; its
            frames are ignored, its ground plane kept).
        results: camera name -> COCO file: a results list
            ``[{"image_id", "category_id", "keypoints", "score", "bbox"?}, ...]``
            or an annotation file ``{"images", "annotations", "categories"?}``.
        keypoint_set: the files' keypoint set, a name in :data:`KEYPOINT_SETS`
            (``vfactor12``, ``carfusion14``, ``apollocar3d24``, ``apollocar3d66``)
            or a :class:`~vfactor.formats.keypoint_sets.KeypointSet`.
        values: how the third number of each keypoint is read (:data:`VALUE_KINDS`).
        visibility_confidence: confidence given to annotated keypoints of
            visibility 1 and 2, each in (0, 1].
        min_confidence: a point of the set with a lower confidence is not seen
            (applied before points are combined into a vfactor keypoint).
        min_score: detections with a lower ``score`` are dropped (entries
            without a score count as 1).
        frames: how image ids map to frame indices (:data:`FRAME_MODES`), or
            camera name -> {image id: frame index}.
        images: camera name -> COCO annotation file whose ``images`` (and
            ``categories``) a results file refers to, for ``frames="file_name"``,
            timestamps and class names.
        fps: frames per second: frame k is at ``t = k / fps`` s. When None,
            the images' numeric ``timestamp`` (seconds; the earliest of a
            frame's images) when every frame has one, else ``t = k``.
        pixel_origin: :data:`PIXEL_ORIGINS`; ``"corner"`` subtracts 0.5 px from
            keypoints and boxes.
        track_ids: :data:`TRACK_ID_KINDS`: ``"shared"`` takes an entry's ``track_id`` as the vehicle id that
            every camera shares; ``"per-camera"`` as the id a camera's own 2D tracker gave (the scene's per-camera
            ``track``: evidence for the association across frames, docs/association.md), the vehicle left to the
            association (an entry's ``vehicle`` stays its vehicle).
        skipped: when given, a dict filled with why detections were left out
            (:data:`SKIP_REASONS`) -> how many, so that the caller can say so.

    Returns:
        ``{"cameras", "frames"(, "ground_plane")}``, frames in frame-index order,
        each ``{"t", "detections"}``; a detection has ``camera``, ``keypoints``
        (12 rows ``[u, v, confidence]``, ``[None, None, 0]`` where not seen) and,
        where known, ``vehicle``, ``roi`` (``bbox`` ``[x, y, w, h]`` as
        ``[x, y, x + w, y + h]``, px) and ``class`` (the category name).
        Detections left with no seen keypoint, crowd annotations
        (``iscrowd`` 1) and those under ``min_score`` are dropped.

    Raises:
        SceneError: a file is missing or malformed; ``field`` is the file and
            the path inside it, e.g. ``cam0.json[3].keypoints``.
        InputError: a bad option (``field`` names it), e.g. an unknown camera in ``results``.
    """
    kps = _keypoint_set(keypoint_set)
    opts = _Options.checked(values, visibility_confidence, min_confidence, min_score, fps, pixel_origin, track_ids)
    camera_dicts, ground_plane = _cameras(cameras)
    names = [c["name"] for c in camera_dicts]
    if not isinstance(results, Mapping) or not results:
        raise InputError("results", "expected a non-empty mapping camera name -> COCO file")
    if images is not None and not isinstance(images, Mapping):
        raise InputError("images", f"expected a mapping camera name -> COCO annotation file, got {_kind(images)}")
    for option, given in (("results", results), ("images", images or {})):
        for name in given:
            if name not in names:
                raise InputError(f"{option}.{name}", f"unknown camera {name!r}; known: {', '.join(names)}")
    files = {name: _read_coco(path, kps) for name, path in results.items()}
    for name, path in (images or {}).items():
        if name not in files:  # it was ignored: the images file of a camera without detections
            raise InputError(f"images.{name}", f"camera {name!r} has no results file; give its detections too")
        files[name].use_images_of(_read_coco(path, kps, images_only=True))
    frame_of = _frame_maps(files, frames)

    detections: dict[int, list[_Det]] = {}
    reasons: dict = {} if skipped is None else skipped
    for name, f in files.items():
        for det in f.detections(name, kps, opts, reasons):
            index = frame_of[name].index(det.image_id, f"{det.where}.image_id")
            detections.setdefault(index, []).append(det)
    indices = set(detections)
    for name, f in files.items():
        if isinstance(frame_of[name], _ImageFrames):
            indices.update(frame_of[name].indices())
    times = _times(sorted(indices), files, frame_of, opts.fps)

    out_frames = []
    for index in sorted(indices):
        dets = detections.get(index, [])
        _check_vehicles(dets, index)
        out_frames.append({"t": times[index], "detections": [d.to_dict() for d in dets]})
    out: dict[str, Any] = {"cameras": camera_dicts, "frames": out_frames}
    if ground_plane is not None:
        out["ground_plane"] = ground_plane
    return out


def coco_to_scene(cameras, results: Mapping[str, str | os.PathLike], keypoint_set: str | KeypointSet,
                  **options) -> Scene:
    """The :class:`~vfactor.observations.Scene` of COCO keypoint files, one per camera.

    :func:`coco_to_scene_dict` (same arguments and options) passed through
    :func:`vfactor.scene.scene_from_dict`, so every scene-file check applies.
    A detection without a ``track_id`` / ``vehicle`` gets the vehicle id
    :data:`~vfactor.observations.DEFAULT_VEHICLE_ID`.

    Raises:
        SceneError, InputError: as :func:`coco_to_scene_dict`.
    """
    return scene_from_dict(coco_to_scene_dict(cameras, results, keypoint_set, **options))


def import_coco(cameras, results: Mapping[str, str | os.PathLike], keypoint_set: str | KeypointSet,
                out: str | os.PathLike, **options) -> Scene:
    """Reads COCO keypoint files (:func:`coco_to_scene`) and writes the scene file ``out``.

    The file is written by :func:`vfactor.scene.save_scene` (atomically); every
    detection names its vehicle there. This is ``vfactor import coco``.

    Returns:
        The scene written.

    Raises:
        SceneError, InputError: as :func:`coco_to_scene_dict`; and an
            InputError where the files hold detections and the options leave
            out every one (``field``: ``min_score`` or ``min_confidence``, the
            one that left out the most): no scene file is written then.
    """
    skipped = options.pop("skipped", None)
    skipped = {} if skipped is None else skipped
    scene = coco_to_scene(cameras, results, keypoint_set, skipped=skipped, **options)
    by_option = {"min_score": skipped.get("score", 0), "min_confidence": skipped.get("no keypoint", 0)}
    if any(by_option.values()) and not any(f.detections for f in scene.frames):
        field_name = max(by_option, key=by_option.get)
        left_out = ", ".join(f"{n} {why}" for why, n in skipped.items())
        raise InputError(field_name, f"every detection was left out ({left_out}); no scene written")
    save_scene(scene, out)
    return scene


# ================================================================== options
@dataclass(frozen=True)
class _Options:
    values: str
    visibility_confidence: tuple[float, float]
    min_confidence: float
    min_score: float
    fps: float | None
    shift: float
    per_camera_tracks: bool = False

    @classmethod
    def checked(cls, values, visibility_confidence, min_confidence, min_score, fps, pixel_origin,
                track_ids: str = "shared") -> "_Options":
        if values not in VALUE_KINDS:
            raise InputError("values", f"expected one of {', '.join(VALUE_KINDS)}, got {values!r}")
        vc = visibility_confidence
        if (not isinstance(vc, (list, tuple)) or len(vc) != 2
                or not all(_is_number(c) and 0.0 < float(c) <= 1.0 for c in vc)):
            raise InputError("visibility_confidence", f"expected two confidences in (0, 1] (for visibility 1 and 2), "
                                                      f"got {vc!r}")
        if not _is_number(min_confidence) or not 0.0 <= float(min_confidence) <= 1.0:
            raise InputError("min_confidence", f"expected a number in [0, 1], got {min_confidence!r}")
        if not _is_number(min_score) or not math.isfinite(float(min_score)):
            raise InputError("min_score", f"expected a finite number, got {min_score!r}")
        if fps is not None and not (_is_number(fps) and math.isfinite(float(fps)) and float(fps) > 0):
            raise InputError("fps", f"expected a positive number of frames per second, got {fps!r}")
        if pixel_origin not in PIXEL_ORIGINS:
            raise InputError("pixel_origin", f"expected one of {', '.join(PIXEL_ORIGINS)}, got {pixel_origin!r}")
        if track_ids not in TRACK_ID_KINDS:
            raise InputError("track_ids", f"expected one of {', '.join(TRACK_ID_KINDS)}, got {track_ids!r}")
        return cls(values, (float(vc[0]), float(vc[1])), float(min_confidence), float(min_score),
                   None if fps is None else float(fps), -0.5 if pixel_origin == "corner" else 0.0,
                   track_ids == "per-camera")


def _cameras(cameras) -> tuple[list[dict], dict | None]:
    """Camera entries of a scene file (validated) and the optional ground plane."""
    if isinstance(cameras, Scene):
        gp = cameras.ground_plane
        return ([c.to_dict() for c in cameras.cameras.values()],
                None if gp is None else {"normal": list(gp.normal), "offset": gp.offset})
    if isinstance(cameras, (str, os.PathLike)):
        where = str(cameras)
        data = read_json(cameras, SceneError)
        if not isinstance(data, dict) or "cameras" not in data:
            raise SceneError(where, "expected an object with a 'cameras' list (a scene or cameras file)")
        for key in data:
            if key not in ("cameras", "frames", "ground_plane"):
                raise SceneError(f"{where}.{key}", "unknown key; known keys: cameras, frames, ground_plane")
        part = {"cameras": data["cameras"], "frames": []}
        if data.get("ground_plane") is not None:
            part["ground_plane"] = data["ground_plane"]
        try:  # calibration files named in it are relative to its folder, as in a scene file
            scene = scene_from_dict(part, base_dir=Path(os.path.abspath(cameras)).parent)
        except SceneError as exc:
            err = exc.within(where)
            raise SceneError(err.field, err.problem) from None
        return _cameras(scene)
    if isinstance(cameras, Mapping):
        for key, cam in cameras.items():
            if not isinstance(cam, Camera) or cam.name != key:
                raise InputError(f"cameras.{key}", f"expected a Camera named {key!r}, got {_kind(cam)}")
        cameras = list(cameras.values())
    if not isinstance(cameras, (list, tuple)) or not cameras or not all(isinstance(c, Camera) for c in cameras):
        raise InputError("cameras", "expected Cameras (a non-empty list or dict), a Scene, or a scene/cameras file")
    return [c.to_dict() for c in cameras], None


# ================================================================ COCO files
@dataclass
class _Det:
    """One detection read from a COCO entry, already in vfactor's 12 keypoints."""

    where: str
    camera: str
    image_id: Any
    uv: np.ndarray
    confidence: np.ndarray
    vehicle: str | None = None
    roi: list[float] | None = None
    vehicle_class: str | None = None
    track: str | None = None

    def to_dict(self) -> dict:
        rows = [[float(u), float(v), float(c)] if c > 0 else [None, None, 0]
                for (u, v), c in zip(self.uv, self.confidence, strict=True)]
        out: dict[str, Any] = {"camera": self.camera, "keypoints": rows}
        if self.vehicle is not None:
            out["vehicle"] = self.vehicle
        if self.roi is not None:
            out["roi"] = self.roi
        if self.vehicle_class is not None:
            out["class"] = self.vehicle_class
        if self.track is not None:
            out["track"] = self.track
        return out


@dataclass
class _Image:
    id: Any
    file_name: str
    timestamp: float | None
    where: str


@dataclass
class _CocoFile:
    """A parsed COCO file: its entries, and its images and category names when it has them."""

    where: str
    kind: str  # "results" or "dataset"
    entries: list[tuple[str, Any]]
    images: dict[Any, _Image] | None = None
    images_where: str | None = None
    categories: dict[Any, str] = field(default_factory=dict)

    def use_images_of(self, other: "_CocoFile") -> None:
        """Takes the images and category names of another (annotation) file, for a results file."""
        self.images, self.images_where = other.images, other.images_where
        self.categories = {**other.categories, **self.categories}

    def detections(self, camera: str, kps: KeypointSet, opts: _Options, skipped: dict) -> list[_Det]:
        """The file's detections; those left out are counted by reason in ``skipped``."""
        kind = opts.values if opts.values != "auto" else ("confidence" if self.kind == "results" else "visibility")
        out = []
        for where, entry in self.entries:
            det = _detection(entry, where, camera, kps, kind, opts, self.categories)
            if isinstance(det, str):
                skipped[det] = skipped.get(det, 0) + 1
            else:
                out.append(det)
        return out


def _read_coco(path, kps: KeypointSet, images_only: bool = False) -> _CocoFile:
    where = str(path)
    data = read_json(path, SceneError)
    if isinstance(data, list) and not images_only:
        return _CocoFile(where, "results", [(f"{where}[{i}]", e) for i, e in enumerate(data)])
    key = "images" if images_only else "annotations"
    if not isinstance(data, dict) or key not in data:
        what = ("a COCO annotation file (an object with 'images')" if images_only else
                "a COCO results list, or an annotation file (an object with 'images' and 'annotations')")
        raise SceneError(where, f"expected {what}, got {_kind(data)}")
    entries = []
    if not images_only:
        items = data["annotations"]
        if not isinstance(items, list):
            raise SceneError(f"{where}.annotations", f"expected a list of annotations, got {_kind(items)}")
        entries = [(f"{where}.annotations[{i}]", e) for i, e in enumerate(items)]
    f = _CocoFile(where, "dataset", entries, categories=_categories(data.get("categories"), where, kps))
    if data.get("images") is not None:
        f.images, f.images_where = _images(data["images"], f"{where}.images"), where
    return f


def _images(items, where: str) -> dict[Any, _Image]:
    if not isinstance(items, list):
        raise SceneError(where, f"expected a list of images, got {_kind(items)}")
    out: dict[Any, _Image] = {}
    for j, item in enumerate(items):
        path = f"{where}[{j}]"
        if not isinstance(item, dict):
            raise SceneError(path, f"expected an image object, got {_kind(item)}")
        image_id = _image_id(item.get("id"), f"{path}.id")
        if image_id in out:
            raise SceneError(f"{path}.id", f"image id {image_id!r} appears twice (also {out[image_id].where})")
        name = item.get("file_name")
        if not isinstance(name, str) or not name:
            raise SceneError(f"{path}.file_name", f"expected a non-empty string, got {_kind(name)}")
        stamp = item.get("timestamp")
        if stamp is not None and not (_is_number(stamp) and math.isfinite(float(stamp))):
            raise SceneError(f"{path}.timestamp", f"expected a finite number of seconds, got {_kind(stamp)}")
        out[image_id] = _Image(image_id, name, None if stamp is None else float(stamp), path)
    return out


def _categories(items, where: str, kps: KeypointSet) -> dict[Any, str]:
    if items is None:
        return {}
    if not isinstance(items, list):
        raise SceneError(f"{where}.categories", f"expected a list of categories, got {_kind(items)}")
    out = {}
    for j, item in enumerate(items):
        path = f"{where}.categories[{j}]"
        if not isinstance(item, dict):
            raise SceneError(path, f"expected a category object, got {_kind(item)}")
        names = item.get("keypoints")
        if names is not None and (not isinstance(names, list) or len(names) != kps.num_keypoints):
            got = f"{len(names)}" if isinstance(names, list) else _kind(names)
            raise SceneError(f"{path}.keypoints", f"expected {kps.num_keypoints} keypoint names for {kps.name}, "
                                                  f"got {got}")
        name = item.get("name")
        if isinstance(name, str) and name and item.get("id") is not None:
            out[_image_id(item["id"], f"{path}.id")] = name
    return out


def _detection(entry, where: str, camera: str, kps: KeypointSet, kind: str, opts: _Options,
               categories: dict) -> _Det | str:
    """The detection of a file entry, or why it is left out (one of :data:`SKIP_REASONS`)."""
    if not isinstance(entry, dict):
        raise SceneError(where, f"expected an object, got {_kind(entry)}")
    if "image_id" not in entry:
        raise SceneError(f"{where}.image_id", "missing (required)")
    image_id = _image_id(entry["image_id"], f"{where}.image_id")
    if entry.get("iscrowd") in (1, True):
        return "crowd"
    score = entry.get("score")
    if score is not None:
        if not (_is_number(score) and math.isfinite(float(score))):
            raise SceneError(f"{where}.score", f"expected a finite number, got {_kind(score)}")
        if float(score) < opts.min_score:
            return "score"
    xy, conf = _keypoints(entry.get("keypoints"), f"{where}.keypoints", kps, kind, opts)
    conf[conf < opts.min_confidence] = 0.0
    uv, confidence = kps.to_vfactor(xy + opts.shift, conf)
    if not np.any(confidence > 0):
        return "no keypoint"
    det = _Det(where, camera, image_id, uv, confidence)
    ids = {key: entry[key] for key in _ID_KEYS if entry.get(key) is not None}
    for key, value in ids.items():
        if not ((isinstance(value, int) and not isinstance(value, bool)) or (isinstance(value, str) and value)):
            raise SceneError(f"{where}.{key}", f"expected an integer or a non-empty string, got {_kind(value)}")
    if opts.per_camera_tracks and "track_id" in ids:  # a camera's own tracker's id: evidence, not the vehicle
        det.track = str(ids.pop("track_id"))
    if len({str(v) for v in ids.values()}) > 1:
        raise SceneError(f"{where}.vehicle", f"differs from track_id ({ids['vehicle']!r} and {ids['track_id']!r})")
    if ids:
        det.vehicle = str(next(iter(ids.values())))
    if entry.get("bbox") is not None:
        det.roi = _roi(entry["bbox"], f"{where}.bbox", opts.shift)
    category = entry.get("category_id")
    if category is not None and _image_id(category, f"{where}.category_id") in categories:
        det.vehicle_class = categories[category]
    return det


def _keypoints(value, where: str, kps: KeypointSet, kind: str, opts: _Options) -> tuple[np.ndarray, np.ndarray]:
    n = kps.num_keypoints
    expected = f"{3 * n} numbers ({n} x 3) for {kps.name}"
    if value is None:
        raise SceneError(where, f"missing: expected {expected}")
    if not isinstance(value, list) or len(value) != 3 * n:
        got = f"{len(value)}" if isinstance(value, list) else _kind(value)
        raise SceneError(where, f"expected {expected}, got {got}")
    xy = np.zeros((n, 2))
    conf = np.zeros(n)
    for i in range(n):
        x, y, s = value[3 * i: 3 * i + 3]
        point = f"{where}[{3 * i + 2}]"
        if kind == "visibility":
            if not _is_number(s) or float(s) not in (0.0, 1.0, 2.0):
                raise SceneError(point, f"expected a COCO visibility 0, 1 or 2 (point {i}, "
                                        f"{kps.keypoint_names[i]!r}), got {_kind(s)}")
            c = 0.0 if float(s) == 0 else opts.visibility_confidence[int(s) - 1]
        else:
            if not _is_number(s) or not 0.0 <= float(s) <= 1.0:
                raise SceneError(point, f"expected a confidence in [0, 1] (point {i}, {kps.keypoint_names[i]!r}), "
                                        f"got {_kind(s)}")
            c = float(s)
        for k, v in ((0, x), (1, y)):
            if c > 0 and not (_is_number(v) and math.isfinite(float(v))):
                raise SceneError(f"{where}[{3 * i + k}]", f"expected a finite number of pixels (point {i} is seen), "
                                                          f"got {_kind(v)}")
        conf[i] = c
        if c > 0:
            xy[i] = (float(x), float(y))
    return xy, conf


def _roi(value, where: str, shift: float) -> list[float]:
    if (not isinstance(value, list) or len(value) != 4
            or not all(_is_number(b) and math.isfinite(float(b)) for b in value)):
        raise SceneError(where, f"expected [x, y, width, height], four finite numbers (px), got {_kind(value)}")
    x, y, w, h = (float(b) for b in value)
    if not (w > 0 and h > 0):
        raise SceneError(where, f"expected a positive width and height, got {[x, y, w, h]}")
    return [x + shift, y + shift, x + w + shift, y + h + shift]


def _image_id(value, where: str):
    """An image (or category) id: an integer or a non-empty string."""
    if (isinstance(value, int) and not isinstance(value, bool)) or (isinstance(value, str) and value):
        return value
    raise SceneError(where, f"expected an integer or a non-empty string, got {_kind(value)}")


# ==================================================================== frames
class _IdFrames:
    """``frames="image_id"``: the image id is the frame index."""

    def index(self, image_id, where: str) -> int:
        """The frame index of an image id; ``where``: the field that holds the id, for errors."""
        if not isinstance(image_id, int) or image_id < 0:
            raise SceneError(where, f"expected a non-negative integer (the frame index, frames='image_id'), got "
                                    f"{_kind(image_id)}")
        return image_id


class _ImageFrames:
    """``frames="file_name"`` or a mapping: image id -> frame index, from a camera's images or the given map."""

    def __init__(self, index_of: dict, source: str):
        self.index_of = index_of
        self.source = source

    def index(self, image_id, where: str) -> int:
        """The frame index of an image id; ``where``: the field that holds the id, for errors."""
        if image_id not in self.index_of:
            raise SceneError(where, f"image id {image_id!r} is not in {self.source}")
        return self.index_of[image_id]

    def indices(self) -> set[int]:
        return set(self.index_of.values())


def _frame_maps(files: dict[str, _CocoFile], frames) -> dict[str, Any]:
    if isinstance(frames, Mapping):
        out = {}
        for name in files:
            given = frames.get(name)
            if not isinstance(given, Mapping):
                raise InputError(f"frames.{name}", f"expected a mapping image id -> frame index, got {_kind(given)}")
            for image_id, index in given.items():
                if not (isinstance(index, int) and not isinstance(index, bool)) or index < 0:
                    raise InputError(f"frames.{name}[{image_id!r}]", f"expected a non-negative frame index, got "
                                                                     f"{_kind(index)}")
            out[name] = _ImageFrames(dict(given), f"the frames mapping of camera {name!r}")
        return out
    if frames not in FRAME_MODES:
        raise InputError("frames", f"expected one of {', '.join(FRAME_MODES)} or a mapping, got {frames!r}")
    if frames == "auto":
        frames = "file_name" if all(f.images is not None for f in files.values()) else "image_id"
    if frames == "image_id":
        return {name: _IdFrames() for name in files}
    out = {}
    for name, f in files.items():
        if f.images is None:
            raise InputError(f"images.{name}", f"frames='file_name' needs the images of camera {name!r}: give an "
                                               "annotation file with 'images' (images=)")
        order = sorted(f.images.values(), key=lambda im: im.file_name)
        out[name] = _ImageFrames({im.id: k for k, im in enumerate(order)}, f"{f.images_where}.images")
    return out


def _times(indices: list[int], files: dict[str, _CocoFile], frame_of: dict, fps: float | None) -> dict[int, float]:
    if fps is not None:
        return {k: k / fps for k in indices}
    stamps: dict[int, list[float]] = {}
    for name, f in files.items():
        if f.images is None:
            continue
        for im in f.images.values():
            if im.timestamp is None:
                continue
            try:
                k = frame_of[name].index(im.id, f"{im.where}.id")
            except SceneError:
                continue  # an image of no frame (a frames mapping without it)
            stamps.setdefault(k, []).append(im.timestamp)
    if not stamps:
        return {k: float(k) for k in indices}
    missing = [k for k in indices if k not in stamps]
    if missing:
        raise InputError("fps", f"frame {missing[0]} has no image with a 'timestamp' while others have: give "
                                "timestamps for every frame, or fps")
    times = {k: min(stamps[k]) for k in indices}
    seen: dict[float, int] = {}
    for k in indices:
        if times[k] in seen:
            raise InputError("fps", f"frames {seen[times[k]]} and {k} have the same image timestamp {times[k]} s; "
                                    "give fps instead")
        seen[times[k]] = k
    return times


def _check_vehicles(dets: list[_Det], index: int) -> None:
    """The scene format's rule for one frame: all detections name their vehicle, or none does (then one vehicle
    where each camera has one detection, else the vehicles are found from geometry: vfactor.association)."""
    named = [d for d in dets if d.vehicle is not None]
    if named and len(named) != len(dets):
        d = next(d for d in dets if d.vehicle is None)
        raise SceneError(f"{d.where}.track_id", f"missing: other detections of frame {index} ({named[0].where}) "
                                                "name their vehicle; give a track_id to all or none")
    seen: dict[tuple[str, str | None], _Det] = {}
    for d in dets:
        key = (d.camera, d.vehicle)
        if key in seen and d.vehicle is not None:
            raise SceneError(f"{d.where}.track_id", f"camera {d.camera!r} has two detections of vehicle "
                                                    f"{d.vehicle!r} in frame {index} (also {seen[key].where})")
        seen[key] = d

