"""Scene files (input) and result files (output): load, validate, save.

The formats are specified in docs/scene-format.md. Every field of a scene or result file
is validated on load; any problem raises :class:`~vfactor.errors.SceneError`
whose ``field`` is the full path of the offending field (for example
``frames[3].detections[0].keypoints[5]`` or ``cameras[1].K``) and whose message
says what was expected and what was found. Unknown keys are errors too, so a
misspelt optional field is never silently ignored.

Scene file, in short (units: pixels for image quantities, metres and seconds
otherwise)::

    {"cameras": [camera, ...],
     "frames": [{"t", "detections": [detection, ...], "images"?: {camera: path}}, ...]}

    camera = {"name", "K", "world_T_camera", "model"?, "dist"?, "image_size"?}          (inline)
           | {"name", "calibration", "calibration_format"?, "chain_camera"?,
              "world_T_camera"?, "image_size"?}                                    (by file)
             and either: "extrinsic_sigma"?: {"rotation_deg", "translation_m"}

    detection = {"camera", "vehicle"?, "keypoints"?: 12 x [u, v, confidence],
                 "keypoint_covariances"?: 12 x (null | 2x2), "covariances_calibrated"?: bool,
                 "shape_sigma"?: metres, "bias_sigma"?: 6 x number, "heatmaps"?: "x.npy",
                 "roi"?: [x0, y0, x1, y1], "class"?: "car" | "truck" | "bus" | body type}

A detection gives ``keypoints``, or ``heatmaps`` with ``roi``, or only a
``roi`` when its frame's ``images`` hold its camera's image (the keypoint
network then finds the keypoints, see :mod:`vfactor.net.pipeline`).

``keypoint_covariances`` is a vfactor extension: per keypoint a symmetric
positive-definite 2x2 pixel covariance (px^2), or null where unknown;
``covariances_calibrated`` (default false) says they are calibrated against the
detector's true errors (the keypoint network's, as ``vfactor.net`` writes them),
so the result's covariances are computed at no less than them; ``shape_sigma``
(metres, default none) is the detector's error shaped like a change of the
vehicle's shape (for a vehicle whose keypoints span 9 m^3; the solver takes it
at the vehicle's size), which widens the result's pose, shape and keypoint covariances;
``bias_sigma`` (default none) the sigmas of the detector's error that repeats
over a vehicle's frames and cameras, a rigid motion of the vehicle (``[roll,
pitch, yaw]`` radians, ``[x, y, z]`` metres, body frame), which tracks take into
their poses' covariances (:class:`vfactor.observations.Detection`). Optional fields may also be given as
null, which means "absent".

Paths (``heatmaps``, ``images``, ``calibration``) are relative to the scene file's
folder (or to ``base_dir``); in memory they are held as absolute paths, and written
back relative to the folder of the file being saved. A camera given by a
calibration file (:mod:`vfactor.calibration`) is written back inline.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gtsam
import numpy as np

from vfactor.box import Box
from vfactor.calibration import CALIBRATION_FORMATS, detect_format, kalibr_cameras, read_calibration
from vfactor.camera import DIST_SIZES, LENS_MODELS, Camera, check_rigid_transform, extrinsic_sigma
from vfactor.factors.ground_plane import GroundPlane
from vfactor.errors import CalibrationError, SceneError
from vfactor.heatmaps import decode_heatmaps
from vfactor.jsonio import (describe as _kind, is_int as _is_int, is_number as _is_number, parse_json, read_json,
                            read_text, write_text_atomic)
from vfactor.keypoints import NUM_KEYPOINTS
from vfactor.label_swaps import SwapFinding
from vfactor.observations import (DEFAULT_VEHICLE_ID, SYMMETRY_RTOL, UNASSIGNED, Detection, Frame, Scene,
                                  covariance_problem, resolve_path)
from vfactor.result import COVARIANCE_KINDS, ESTIMATE_STATUSES, FrameResult, Status, VehicleResult
from vfactor.wireframe import Wireframe

__all__ = [
    "load_scene",
    "scene_from_dict",
    "frame_from_dict",
    "save_scene",
    "scene_to_dict",
    "load_results",
    "results_from_dict",
    "save_results",
    "results_to_dict",
    "frame_result_to_dict",
    "box_to_dict",
    "box_from_dict",
]

_TOP_KEYS = ("cameras", "frames", "ground_plane")
_REQUIRED_TOP_KEYS = ("cameras", "frames")
_CAMERA_KEYS = ("name", "model", "K", "dist", "image_size", "world_T_camera", "calibration", "calibration_format",
                "chain_camera", "extrinsic_sigma")
_EXTRINSIC_SIGMA_KEYS = ("rotation_deg", "translation_m")
#: Inline camera fields a ``calibration`` file replaces (an error beside it).
_INTRINSIC_KEYS = ("model", "K", "dist")
_FRAME_KEYS = ("t", "detections", "images")
_DETECTION_KEYS = ("camera", "vehicle", "track", "keypoints", "keypoint_covariances", "covariances_calibrated",
                   "shape_sigma", "bias_sigma", "heatmaps", "heatmaps_roi", "roi", "class")
_RESULT_TOP_KEYS = ("frames",)
_RESULT_FRAME_KEYS = ("t", "vehicles")
_VEHICLE_KEYS = (
    "id",
    "world_T_vehicle",
    "keypoints_world",
    "keypoints_vehicle",
    "pose_covariance",
    "status",
    "iterations",
    "final_error",
    "message",
    "keypoint_covariances_world",
    "body_type",
    "body_type_probability",
    "box",
    "pose_covariance_kind",
    "detections",
    "swapped_keypoints",
)
#: keypoints_world must match world_T_vehicle * keypoints_vehicle to within this (metres).
_KEYPOINTS_WORLD_TOL = 1e-6


# ====================================================================== scenes
def load_scene(path: str | os.PathLike, allow_outside_paths: bool = False,
               camera_files: dict[str, str | os.PathLike] | None = None) -> Scene:
    """Loads and validates a scene file (JSON, docs/scene-format.md).

    Relative paths in the file (``heatmaps``, ``images``, ``calibration``) are
    resolved against the file's folder, which becomes ``Scene.base_dir``; they
    must stay inside it (see :func:`scene_from_dict`). See
    :func:`scene_from_dict` for what is checked, how heatmap detections are
    decoded and how ``camera_files`` replace the scene's calibrations.

    Args:
        path: the scene file.
        allow_outside_paths: accept heatmap, image and calibration paths outside
            the file's folder (``vfactor solve --allow-outside-paths``).
        camera_files: camera name -> calibration file that replaces that camera's
            calibration (``vfactor solve --camera NAME=FILE``); see :func:`scene_from_dict`.

    A recorded stream (``.jsonl`` or ``.ndjson``: a header line, then a frame per line, docs/scene-format.md) is
    read as the scene of its header and frames (``frames[k]`` is the file's line ``k + 2`` where the stream has no
    blank line; a line that is not JSON is named ``path:line``), so that it can be tracked and smoothed afterwards.

    Returns:
        The :class:`~vfactor.observations.Scene`, with cameras and frames in file order.

    Raises:
        SceneError: the file is missing (field: the path), is not JSON (field:
            the path; a stream's line: ``path:line``), or any field is invalid (field: its path in the file,
            e.g. ``frames[3].detections[0].keypoints[5]``).
    """
    path = Path(path)
    data = _read_json_lines(path) if path.suffix.lower() in (".jsonl", ".ndjson") else _read_json(path)
    return scene_from_dict(data, base_dir=Path(os.path.abspath(path)).parent, allow_outside_paths=allow_outside_paths,
                           camera_files=camera_files)


def scene_from_dict(data: dict, base_dir: Path | None = None, allow_outside_paths: bool = False,
                    camera_files: dict[str, str | os.PathLike] | None = None) -> Scene:
    """Validates a parsed scene file and builds a :class:`~vfactor.observations.Scene`.

    Checks, among others: the top level is an object with ``cameras`` (a
    non-empty list) and ``frames`` (a list), optionally ``ground_plane``
    (``{"normal": [nx, ny, nz], "offset": d}``, the road ``n . x = d``, normal
    pointing up); no unknown keys anywhere; camera
    names unique and every camera valid (inline: ``K``, ``world_T_camera``,
    ``model`` ``"pinhole"`` or ``"fisheye"``, ``dist`` of 4, 5, 8, 12 or 14 numbers
    (pinhole) or 4 (fisheye), ``image_size``; or by a ``calibration`` file, see
    below; either with an optional ``extrinsic_sigma``, ``{"rotation_deg": r,
    "translation_m": t}``, how well ``world_T_camera`` is known, each one number
    or three per camera axis, >= 0: :attr:`vfactor.camera.Camera.extrinsic_sigma`);
    each detection's camera exists; a
    detection has ``keypoints`` (exactly 12 rows ``[u, v, confidence]``,
    confidence in [0, 1], ``u`` and ``v`` finite where confidence > 0 and null
    or finite where it is 0), ``heatmaps`` with ``roi``, or only a ``roi`` in
    a frame whose ``images`` give that camera's image; ``roi`` is
    ``[x0, y0, x1, y1]`` with ``x1 > x0`` and ``y1 > y0``; a heatmap file exists
    and holds a float ``.npy`` array of shape (12, H, W); no NaN or infinity
    anywhere; ``vehicle`` is omitted by all detections of a frame (which then
    hold one vehicle, :data:`~vfactor.observations.DEFAULT_VEHICLE_ID`) or by
    none; a (camera, vehicle) pair appears once per frame; ``images`` maps
    existing cameras to existing files. Frames need not be in time order.

    Cameras by file: ``{"name", "calibration": path, "calibration_format"?,
    "chain_camera"?, "world_T_camera"?, "image_size"?}`` reads the camera from a
    calibration file (:func:`vfactor.calibration.read_calibration`; format detected
    from the content unless ``calibration_format`` names it; ``chain_camera`` picks
    the camera of a Kalibr camchain of several). The name is the entry's, never
    the file's. Beside ``calibration`` an entry gives only what the file lacks:
    ``model``, ``K`` and ``dist`` are errors; ``world_T_camera`` is required when
    the file has no extrinsic (ROS, Kalibr) and an error when it has one;
    ``image_size`` likewise (optional). A problem in the file is a SceneError at
    ``cameras[i].calibration`` whose message starts with the file and node
    (``cam0.yaml:camera_matrix: ...``).

    ``camera_files`` (name -> calibration file, paths as given: relative to the
    working directory, never checked against ``base_dir``): each file's camera
    replaces the scene camera of that name: its intrinsics, lens and distortion
    always, its extrinsic when the file has one (else the scene's
    ``world_T_camera`` is kept), its image size when the file has one (else the
    scene's is kept; the scene's ``extrinsic_sigma`` is kept). A camchain of
    several cameras gives the entry named like the scene's camera. A name the
    scene lacks is a SceneError at ``camera_files.<name>``; a problem in the
    file too, its message starting with the file and node.

    Paths: a heatmap, image or calibration path resolves inside ``base_dir`` (after
    following symbolic links: a link out of the folder is refused too), unless
    ``allow_outside_paths``; the error names the field.

    Heatmaps: a detection with ``heatmaps`` and ``roi`` but no ``keypoints``
    keeps its ``heatmaps`` (absolute path) and ``roi``, and gets ``keypoints``,
    ``confidence`` and ``covariance`` by decoding the heatmaps with
    :func:`vfactor.heatmaps.decode_heatmaps` (default settings), so the
    solvers can use it directly. When ``keypoints`` are given as well, they are
    used as given, and the covariance comes from ``keypoint_covariances`` if
    given, else from the heatmaps' spread.

    Images: a detection with only a ``roi`` (a 2D detector's box) in a frame
    whose ``images`` name that camera's image is kept with ``from_image`` set,
    NaN keypoints and zero confidences; :func:`vfactor.net.pipeline.detect_scene`
    runs the keypoint network on it (``vfactor solve`` does so itself).

    Args:
        data: the parsed JSON (``json.load``) of a scene file.
        base_dir: folder that relative paths start from; ``None``: the current
            working directory.
        allow_outside_paths: accept heatmap, image and calibration paths outside ``base_dir``.
        camera_files: camera name -> calibration file replacing that camera's calibration (see above).

    Returns:
        The scene; ``Scene.frames`` in the order of ``data["frames"]``.

    Raises:
        SceneError: an invalid field; ``field`` is its path (e.g.
            ``cameras[1].K``), the message says what was expected and found.
    """
    base = _Folder(Path(os.path.abspath(base_dir if base_dir is not None else os.getcwd())), allow_outside_paths)
    top = _object(data, "", _TOP_KEYS, required=_REQUIRED_TOP_KEYS)
    cameras_data = _list(top["cameras"], "cameras", "a non-empty list of cameras")
    if not cameras_data:
        raise SceneError("cameras", "expected a non-empty list of cameras, got an empty list")
    cameras: dict[str, Camera] = {}
    where: dict[str, int] = {}
    for i, item in enumerate(cameras_data):
        camera = _camera_from_dict(item, f"cameras[{i}]", base)
        if camera.name in cameras:
            raise SceneError(
                f"cameras[{i}].name", f"duplicate camera name {camera.name!r} (also cameras[{where[camera.name]}])"
            )
        cameras[camera.name] = camera
        where[camera.name] = i
    if camera_files:
        cameras = _replace_cameras(cameras, camera_files)
    frames = [
        _frame_from_dict(item, f"frames[{i}]", cameras, base) for i, item in enumerate(_list(top["frames"], "frames"))
    ]
    first_at: dict[float, int] = {}
    for i, frame in enumerate(frames):  # solve and track read the same files: a time names one frame
        if first_at.setdefault(frame.t, i) != i:
            raise SceneError(f"frames[{i}].t", f"same time as frames[{first_at[frame.t]}] ({frame.t} s); each frame "
                                               "has its own time")
    return Scene(cameras=cameras, frames=frames, base_dir=base.path, ground_plane=_ground_plane(top.get("ground_plane")))


def frame_from_dict(data: dict, scene: Scene, path: str = "frame", allow_outside_paths: bool = False) -> Frame:
    """One frame of a scene file's ``frames`` (a line of a stream, :mod:`vfactor.stream`), checked as
    :func:`scene_from_dict` checks frames, against ``scene``'s cameras; relative paths start from ``scene.base_dir``.

    Raises:
        SceneError: an invalid field; ``field`` is its path under ``path`` (e.g. ``frame.detections[0].camera``).
    """
    base = _Folder(Path(os.path.abspath(scene.base_dir if scene.base_dir is not None else os.getcwd())),
                   allow_outside_paths)
    return _frame_from_dict(data, path, scene.cameras, base)


def _ground_plane(value) -> GroundPlane | None:
    """The optional ``ground_plane``: ``{"normal": [nx, ny, nz], "offset": d}``, the road ``n . x = d``."""
    if value is None:
        return None
    data = _object(value, "ground_plane", ("normal", "offset"), required=("normal",))
    normal = _numbers(data["normal"], "ground_plane.normal", "3 numbers [nx, ny, nz]", (3,))
    offset = _number(data.get("offset", 0.0), "ground_plane.offset", "a finite number of metres")
    try:
        return GroundPlane(tuple(normal), offset)
    except ValueError as exc:
        raise SceneError("ground_plane.normal", str(exc).split(": ", 1)[-1]) from None


def save_scene(scene: Scene, path: str | os.PathLike) -> None:
    """Writes a scene file (JSON) that :func:`load_scene` reads back to the same content.

    Paths of heatmaps and images are written relative to the file's folder.
    See :func:`scene_to_dict` for the layout.

    Raises:
        SceneError: the scene holds a value a scene file cannot (e.g. a seen
            keypoint with NaN pixels).
    """
    path = Path(path)
    data = scene_to_dict(scene, base_dir=Path(os.path.abspath(path)).parent)
    _write_json(path, data)


def scene_to_dict(scene: Scene, base_dir: Path | None = None) -> dict:
    """The scene as a scene-file dictionary (docs/scene-format.md), JSON-serialisable.

    Keypoints with confidence 0 are written ``[null, null, 0]``; every detection
    names its vehicle; ``keypoint_covariances`` is written when a detection
    has a covariance (null for NaN blocks). A detection decoded from heatmaps
    is written with its decoded keypoints as well as its ``heatmaps`` and ``roi``.

    Args:
        scene: the scene.
        base_dir: folder that written paths are relative to; ``None``:
            ``scene.base_dir`` (or paths as held when that is ``None`` too).
            In-memory relative paths are taken relative to ``scene.base_dir``.

    Raises:
        SceneError: a value that a scene file cannot hold; ``field`` is the
            path it would have in the file.
    """
    out_base = base_dir if base_dir is not None else scene.base_dir
    cameras = [camera.to_dict() for camera in scene.cameras.values()]
    frames = []
    for i, frame in enumerate(scene.frames):
        path = f"frames[{i}]"
        t = float(frame.t)
        if not math.isfinite(t):
            raise SceneError(f"{path}.t", f"expected a finite number of seconds, got {t}")
        entry: dict[str, Any] = {"t": t, "detections": []}
        for j, det in enumerate(frame.detections):
            entry["detections"].append(_detection_to_dict(det, f"{path}.detections[{j}]", scene.base_dir, out_base))
        if frame.images is not None:
            entry["images"] = {name: _path_out(p, scene.base_dir, out_base) for name, p in frame.images.items()}
        frames.append(entry)
    out = {"cameras": cameras, "frames": frames}
    if scene.ground_plane is not None:
        out["ground_plane"] = {"normal": list(scene.ground_plane.normal), "offset": scene.ground_plane.offset}
    return out


def _camera_from_dict(data, path: str, base: "_Folder") -> Camera:
    cam = _object(data, path, _CAMERA_KEYS, required=("name",))
    camera = _camera_entry(cam, path, base)
    if cam.get("extrinsic_sigma") is None:
        return camera
    field = f"{path}.extrinsic_sigma"
    given = _object(cam["extrinsic_sigma"], field, _EXTRINSIC_SIGMA_KEYS, required=_EXTRINSIC_SIGMA_KEYS)
    try:
        sigma = extrinsic_sigma(given["rotation_deg"], given["translation_m"], field)
    except CalibrationError as exc:
        raise SceneError(exc.field, exc.problem) from None
    return dataclasses.replace(camera, extrinsic_sigma=sigma)


def _camera_entry(cam: dict, path: str, base: "_Folder") -> Camera:
    """A scene camera entry's camera, inline or by calibration file (its ``extrinsic_sigma`` aside)."""
    name = _string(cam["name"], f"{path}.name")
    world_T_camera = None
    if cam.get("world_T_camera") is not None:
        world_T_camera = _matrix(cam["world_T_camera"], f"{path}.world_T_camera", (4, 4))
    image_size = cam.get("image_size")
    if image_size is not None:
        if (
            not isinstance(image_size, (list, tuple))
            or len(image_size) != 2
            or not all(_is_int(s) and s > 0 for s in image_size)
        ):
            shown = (f"[{', '.join(_kind(s) if not _is_number(s) else repr(s) for s in image_size)}]"
                     if isinstance(image_size, (list, tuple)) and len(image_size) <= 4 else _kind(image_size))
            raise SceneError(f"{path}.image_size", f"expected [width, height], two positive integers, got {shown}")
        image_size = (int(image_size[0]), int(image_size[1]))
    if cam.get("calibration") is not None:
        return _camera_from_file(cam, path, base, name, world_T_camera, image_size)
    for key in ("calibration_format", "chain_camera"):
        if cam.get(key) is not None:
            raise SceneError(f"{path}.{key}", "given without 'calibration' (the file it describes)")
    for key in ("K", "world_T_camera"):
        if cam.get(key) is None:
            raise SceneError(f"{path}.{key}", "missing (required unless the camera is given by 'calibration')")
    K = _matrix(cam["K"], f"{path}.K", (3, 3))
    model = cam.get("model", "pinhole")
    if model is None:
        model = "pinhole"
    if not isinstance(model, str) or model not in LENS_MODELS:
        raise SceneError(f"{path}.model", f"expected one of {', '.join(LENS_MODELS)}, got {_kind(model)}")
    dist = cam.get("dist")
    if dist is not None:
        what = ("4 numbers [k1, k2, k3, k4] (fisheye model)" if model == "fisheye" else
                "4, 5, 8, 12 or 14 numbers [k1, k2, p1, p2(, k3(, k4, k5, k6(, s1, s2, s3, s4(, tauX, tauY))))]")
        dist = _numbers(dist, f"{path}.dist", what, sizes=DIST_SIZES[model])
    try:
        return Camera(name=name, K=K, world_T_camera=world_T_camera, dist=dist, image_size=image_size, model=model)
    except CalibrationError as exc:
        err = exc.within(path)
        raise SceneError(err.field, err.problem) from None


def _camera_from_file(cam: dict, path: str, base: "_Folder", name: str, world_T_camera, image_size) -> Camera:
    """A scene camera given by ``calibration`` (a file), with what the entry supplies beside it."""
    for key in _INTRINSIC_KEYS:
        if cam.get(key) is not None:
            raise SceneError(f"{path}.{key}", "given beside 'calibration': the calibration file gives the camera's "
                                              "model, K and dist (give the file or the inline fields, not both)")
    field = f"{path}.calibration"
    written = cam["calibration"]
    file = _existing_file(written, field, base, "a calibration file path")
    fmt = cam.get("calibration_format")
    if fmt is not None and fmt not in CALIBRATION_FORMATS:
        raise SceneError(f"{path}.calibration_format", f"expected one of {', '.join(CALIBRATION_FORMATS)}, "
                                                       f"got {_kind(fmt)}")
    chain = cam.get("chain_camera")
    if chain is not None:
        chain = _string(chain, f"{path}.chain_camera")
    try:
        calibration = read_calibration(file, fmt, chain)
    except CalibrationError as exc:
        raise _file_error(exc, field, file, written) from None
    for key, given, has in (("world_T_camera", world_T_camera, calibration.world_T_camera is not None),
                            ("image_size", image_size, calibration.image_size is not None)):
        if given is not None and has:
            node = calibration.nodes.get(key, key)
            raise SceneError(f"{path}.{key}", f"given beside 'calibration', whose file gives it ({written}:{node}); "
                                              "give it once")
    if world_T_camera is None and calibration.world_T_camera is None:
        raise SceneError(f"{path}.world_T_camera", f"missing: the {calibration.format} calibration file {written!r} "
                                                   "has no extrinsic; give world_T_camera (4x4, camera -> world) beside it")
    try:
        return calibration.camera(name, world_T_camera, image_size)
    except CalibrationError as exc:
        if exc.field.startswith(file):
            raise _file_error(exc, field, file, written) from None
        err = exc.within(path)
        raise SceneError(err.field, err.problem) from None


def _file_error(exc: CalibrationError, field: str, file: str, written: str) -> SceneError:
    """A calibration file's error as a SceneError at the scene's field, the message naming the file (as written) and node."""
    where = exc.field
    if where.startswith(file):
        where = str(written) + where[len(file):]
    return SceneError(field, f"{where}: {exc.problem}" if where else exc.problem)


def _replace_cameras(cameras: dict[str, Camera], camera_files) -> dict[str, Camera]:
    """The scene's cameras with those named in ``camera_files`` read from their calibration files."""
    if not isinstance(camera_files, dict):
        raise SceneError("camera_files", f"expected a mapping of camera name to calibration file, got "
                                         f"{_kind(camera_files)}")
    out = dict(cameras)
    for name, file in camera_files.items():
        field = f"camera_files.{name}"
        if name not in cameras:
            raise SceneError(field, f"unknown camera {name!r}; the scene has: {', '.join(cameras)}")
        if not isinstance(file, (str, os.PathLike)) or not str(file):
            raise SceneError(field, f"expected a calibration file path, got {_kind(file)}")
        scene_camera = cameras[name]
        file = str(file)
        try:
            chain = None
            if detect_format(file) == "kalibr":
                keys = kalibr_cameras(file)
                chain = None if len(keys) == 1 else name  # several: the entry named like the scene's camera
            calibration = read_calibration(file, chain_camera=chain)
            out[name] = dataclasses.replace(calibration.camera(
                name, None if calibration.world_T_camera is not None else scene_camera.world_T_camera,
                None if calibration.image_size is not None else scene_camera.image_size),
                extrinsic_sigma=scene_camera.extrinsic_sigma)
        except CalibrationError as exc:
            raise _file_error(exc, field, file, file) from None
    return out


@dataclass(frozen=True)
class _Folder:
    """The folder a scene's paths start from, and whether they may leave it."""

    path: Path
    allow_outside: bool = False


def _frame_from_dict(data, path: str, cameras: dict[str, Camera], base: _Folder) -> Frame:
    frame = _object(data, path, _FRAME_KEYS, required=("t", "detections"))
    t = _number(frame["t"], f"{path}.t", "a finite number of seconds")
    items = _list(frame["detections"], f"{path}.detections")
    images = frame.get("images")
    if images is not None:
        images = _images_from_dict(images, f"{path}.images", cameras, base)
    parsed = [_detection_from_dict(item, f"{path}.detections[{j}]", cameras, base, images or {})
              for j, item in enumerate(items)]
    named = [has_vehicle for _, has_vehicle in parsed]
    if any(named) and not all(named):
        j = named.index(False)
        raise SceneError(
            f"{path}.detections[{j}].vehicle",
            "missing: other detections of this frame name their vehicle; 'vehicle' may be omitted only "
            "when no detection of the frame names one (a frame of a single vehicle, or one to associate)",
        )
    cameras_seen = [det.camera for det, _ in parsed]
    if not any(named) and (len(set(cameras_seen)) < len(cameras_seen) or any(d.track for d, _ in parsed)):
        for det, _ in parsed:  # several vehicles without ids: vfactor.association finds them
            det.vehicle = UNASSIGNED
    seen: dict[tuple[str, str], int] = {}
    for j, (det, _) in enumerate(parsed):
        key = (det.camera, det.vehicle)
        if det.vehicle == UNASSIGNED:  # (several unnamed detections of one camera are associated, never an error)
            continue
        if key in seen:
            raise SceneError(
                f"{path}.detections[{j}]",
                f"camera {det.camera!r} already has a detection of vehicle {det.vehicle!r} in this frame "
                f"(detections[{seen[key]}])",
            )
        seen[key] = j
    return Frame(t=t, detections=[det for det, _ in parsed], images=images)


def _images_from_dict(data, path: str, cameras: dict[str, Camera], base: _Folder) -> dict[str, str]:
    if not isinstance(data, dict):
        raise SceneError(path, f"expected an object mapping camera names to image paths, got {_kind(data)}")
    images = {}
    for name, value in data.items():
        field = f"{path}.{name}"
        if name not in cameras:
            raise SceneError(field, f"unknown camera {name!r}; known: {', '.join(cameras)}")
        images[name] = _existing_file(value, field, base, "an image path")
    return images


def _detection_from_dict(data, path: str, cameras: dict[str, Camera], base: _Folder,
                         images: dict[str, str]) -> tuple[Detection, bool]:
    det = _object(data, path, _DETECTION_KEYS, required=("camera",))
    from_image = False
    camera = _string(det["camera"], f"{path}.camera")
    if camera not in cameras:
        raise SceneError(f"{path}.camera", f"unknown camera {camera!r}; known: {', '.join(cameras)}")
    has_vehicle = det.get("vehicle") is not None
    vehicle = _string(det["vehicle"], f"{path}.vehicle") if has_vehicle else DEFAULT_VEHICLE_ID
    vehicle_class = _string(det["class"], f"{path}.class") if det.get("class") is not None else None
    track = _string(det["track"], f"{path}.track") if det.get("track") is not None else None

    roi = det.get("roi")
    if roi is not None:
        box = _numbers(roi, f"{path}.roi", "[x0, y0, x1, y1]", sizes=(4,))
        if not (box[2] > box[0] and box[3] > box[1]):
            raise SceneError(f"{path}.roi", f"expected [x0, y0, x1, y1] with x1 > x0 and y1 > y0, got {box.tolist()}")
        roi = tuple(float(b) for b in box)

    heatmaps, heatmaps_roi = det.get("heatmaps"), det.get("heatmaps_roi")
    if heatmaps_roi is not None:
        if heatmaps is None:
            raise SceneError(f"{path}.heatmaps_roi", "given without 'heatmaps': the box they cover")
        box = _numbers(heatmaps_roi, f"{path}.heatmaps_roi", "[x0, y0, x1, y1]", sizes=(4,))
        if not (box[2] > box[0] and box[3] > box[1]):
            raise SceneError(f"{path}.heatmaps_roi", f"expected [x0, y0, x1, y1] with x1 > x0 and y1 > y0, got "
                                                     f"{box.tolist()}")
        heatmaps_roi = tuple(float(b) for b in box)
    if heatmaps is not None:
        heatmaps = _existing_file(heatmaps, f"{path}.heatmaps", base, "a path to a .npy heatmap stack")
        if roi is None:
            raise SceneError(f"{path}.roi", "missing: required with 'heatmaps' (the box [x0, y0, x1, y1] they cover)")
        stack = _load_heatmaps(heatmaps, f"{path}.heatmaps")
    covered = heatmaps_roi if heatmaps_roi is not None else roi  # the box the heatmaps cover

    covariance = None
    if det.get("keypoint_covariances") is not None:
        covariance = _keypoint_covariances(det["keypoint_covariances"], f"{path}.keypoint_covariances")
    calibrated = det.get("covariances_calibrated", False)
    if not isinstance(calibrated, bool):
        raise SceneError(f"{path}.covariances_calibrated", f"expected true or false, got {_kind(calibrated)}")
    if calibrated and covariance is None:
        raise SceneError(f"{path}.covariances_calibrated", "true without 'keypoint_covariances'")
    shape_sigma = det.get("shape_sigma")
    if shape_sigma is not None:
        shape_sigma = _number(shape_sigma, f"{path}.shape_sigma", "a finite number of metres >= 0")
        if shape_sigma < 0:
            raise SceneError(f"{path}.shape_sigma", f"expected a finite number of metres >= 0, got {shape_sigma}")
    bias_sigma = det.get("bias_sigma")
    if bias_sigma is not None:
        bias_sigma = _bias_sigma(bias_sigma, f"{path}.bias_sigma")

    if det.get("keypoints") is not None:
        keypoints, confidence = _keypoints(det["keypoints"], f"{path}.keypoints")
        if covariance is None and heatmaps is not None:
            covariance = _decode(stack, covered, f"{path}.heatmaps").covariance
    elif heatmaps is not None:
        decoded = _decode(stack, covered, f"{path}.heatmaps")
        keypoints, confidence = decoded.uv, decoded.confidence
        if covariance is None:
            covariance = decoded.covariance
    elif roi is not None and camera in images:
        if covariance is not None:
            raise SceneError(f"{path}.keypoint_covariances",
                             "given without 'keypoints': covariances of keypoints the network has yet to find")
        keypoints, confidence = np.full((NUM_KEYPOINTS, 2), np.nan), np.zeros(NUM_KEYPOINTS)
        from_image = True
    elif roi is not None:
        raise SceneError(
            path,
            f"has only a 'roi': the keypoint network needs this frame's image of camera {camera!r} in the "
            "frame's 'images' (or give 'keypoints', or 'heatmaps' with 'roi')",
        )
    else:
        raise SceneError(path, "expected 'keypoints', 'heatmaps' with 'roi', or 'roi' with the frame's image of its "
                               "camera in 'images'; found none")
    detection = Detection(
        camera=camera,
        vehicle=vehicle,
        keypoints=keypoints,
        confidence=confidence,
        covariance=covariance,
        heatmaps=heatmaps,
        roi=roi,
        heatmaps_roi=heatmaps_roi,
        from_image=from_image,
        vehicle_class=vehicle_class,
        track=track,
        covariance_calibrated=calibrated,
        shape_sigma=shape_sigma,
        bias_sigma=bias_sigma,
    )
    return detection, has_vehicle


def _bias_sigma(data, path: str) -> tuple[float, ...]:
    """A detection's ``bias_sigma``: 6 finite numbers >= 0 (radians about, then metres along, the body x, y, z)."""
    expected = "6 finite numbers >= 0 ([roll, pitch, yaw] radians, [x, y, z] metres)"
    values = _numbers(data, path, expected, (6,))
    if np.any(values < 0):
        raise SceneError(path, f"expected {expected}, got {values.tolist()}")
    return tuple(float(x) for x in values)


def _keypoints(data, path: str) -> tuple[np.ndarray, np.ndarray]:
    rows = _list(data, path, f"a list of {NUM_KEYPOINTS} rows [u, v, confidence]")
    if len(rows) != NUM_KEYPOINTS:
        raise SceneError(
            path,
            f"expected {NUM_KEYPOINTS} rows [u, v, confidence] (one per keypoint, fixed order), got {len(rows)} rows",
        )
    uv = np.full((NUM_KEYPOINTS, 2), np.nan)
    confidence = np.zeros(NUM_KEYPOINTS)
    for k, row in enumerate(rows):
        field = f"{path}[{k}]"
        if not isinstance(row, (list, tuple)) or len(row) != 3:
            raise SceneError(field, f"expected [u, v, confidence], got {_kind(row)}")
        c = row[2]
        if not _is_number(c) or not 0.0 <= float(c) <= 1.0:
            raise SceneError(field, f"confidence: expected a number in [0, 1], got {_kind(c)}")
        c = float(c)
        for name, value in zip("uv", row[:2], strict=True):
            if c > 0 and not (_is_number(value) and math.isfinite(value)):
                raise SceneError(
                    field, f"{name}: expected a finite number (pixels) as confidence is {c:g} > 0, got {_kind(value)}"
                )
            if c == 0 and value is not None and not (_is_number(value) and math.isfinite(value)):
                raise SceneError(field, f"{name}: expected a finite number or null, got {_kind(value)}")
        confidence[k] = c
        if c > 0:
            uv[k] = (float(row[0]), float(row[1]))
    return uv, confidence


def _keypoint_covariances(data, path: str) -> np.ndarray:
    items = _list(data, path, f"a list of {NUM_KEYPOINTS} entries (null or a 2x2 matrix, px^2)")
    if len(items) != NUM_KEYPOINTS:
        raise SceneError(path, f"expected {NUM_KEYPOINTS} entries (null or a 2x2 matrix, px^2), got {len(items)}")
    out = np.full((NUM_KEYPOINTS, 2, 2), np.nan)
    for k, item in enumerate(items):
        if item is None:
            continue
        field = f"{path}[{k}]"
        S = _matrix(item, field, (2, 2), "a 2x2 covariance matrix (px^2) or null")
        problem = covariance_problem(S)
        if problem:
            raise SceneError(field, problem)
        out[k] = S
    return out


def _load_heatmaps(path_str: str, field: str) -> np.ndarray:
    try:
        stack = np.load(path_str, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise SceneError(field, f"expected a .npy file, could not read {path_str}: {exc}") from None
    if not isinstance(stack, np.ndarray):
        if hasattr(stack, "close"):
            stack.close()
        raise SceneError(field, f"expected a .npy array, got a {type(stack).__name__} in {path_str}")
    if stack.ndim != 3 or stack.shape[0] != NUM_KEYPOINTS or stack.shape[1] < 1 or stack.shape[2] < 1:
        raise SceneError(field, f"expected an array of shape ({NUM_KEYPOINTS}, H, W), got {stack.shape} in {path_str}")
    if not np.issubdtype(stack.dtype, np.floating):
        raise SceneError(field, f"expected a float array, got dtype {stack.dtype} in {path_str}")
    return stack


def _decode(stack: np.ndarray, roi, field: str):
    try:
        return decode_heatmaps(np.asarray(stack), roi=roi)
    except ValueError as exc:
        raise SceneError(field, str(exc)) from None


def _detection_to_dict(det: Detection, path: str, scene_base: Path | None, out_base: Path | None) -> dict:
    if det.from_image:
        out = {"camera": det.camera, **_vehicle_fields(det), "roi": [float(b) for b in det.roi]}
        if det.vehicle_class:
            out["class"] = det.vehicle_class
        return out
    keypoints = np.asarray(det.keypoints, dtype=float)
    confidence = np.asarray(det.confidence, dtype=float)
    if keypoints.shape != (NUM_KEYPOINTS, 2) or confidence.shape != (NUM_KEYPOINTS,):
        raise SceneError(
            f"{path}.keypoints",
            f"expected keypoints (12, 2) and confidence (12,), got {keypoints.shape} and {confidence.shape}",
        )
    rows = []
    for k in range(NUM_KEYPOINTS):
        c = float(confidence[k])
        if not 0.0 <= c <= 1.0:
            raise SceneError(f"{path}.keypoints[{k}]", f"confidence: expected a number in [0, 1], got {c}")
        if c == 0:
            rows.append([None, None, 0])
            continue
        u, v = float(keypoints[k, 0]), float(keypoints[k, 1])
        if not (math.isfinite(u) and math.isfinite(v)):
            raise SceneError(
                f"{path}.keypoints[{k}]", f"expected finite u, v as confidence is {c:g} > 0, got [{u}, {v}]"
            )
        rows.append([u, v, c])
    out: dict[str, Any] = {"camera": det.camera, **_vehicle_fields(det), "keypoints": rows}
    if det.covariance is not None:
        cov = np.asarray(det.covariance, dtype=float)
        if cov.shape != (NUM_KEYPOINTS, 2, 2):
            raise SceneError(f"{path}.keypoint_covariances", f"expected shape (12, 2, 2), got {cov.shape}")
        blocks = [S.tolist() if np.all(np.isfinite(S)) else None for S in cov]
        if any(b is not None for b in blocks):
            out["keypoint_covariances"] = blocks
            if det.covariance_calibrated:
                out["covariances_calibrated"] = True
    if det.shape_sigma:
        out["shape_sigma"] = float(det.shape_sigma)
    if det.bias_sigma is not None:
        out["bias_sigma"] = [float(x) for x in det.bias_sigma]
    if det.heatmaps is not None:
        out["heatmaps"] = _path_out(det.heatmaps, scene_base, out_base)
    if det.roi is not None:
        out["roi"] = [float(b) for b in det.roi]
    if det.heatmaps is not None and det.heatmaps_roi is not None:
        out["heatmaps_roi"] = [float(b) for b in det.heatmaps_roi]
    if det.vehicle_class:
        out["class"] = det.vehicle_class
    return out


def _vehicle_fields(det: Detection) -> dict:
    """A detection's ``vehicle`` (absent while :data:`~vfactor.observations.UNASSIGNED`) and ``track``."""
    out = {} if det.vehicle == UNASSIGNED else {"vehicle": det.vehicle}
    if det.track is not None:
        out["track"] = det.track
    return out


# ===================================================================== results
def save_results(frames: Iterable[FrameResult], path: str | os.PathLike) -> None:
    """Writes a result file (JSON, docs/scene-format.md and :func:`results_to_dict`), atomically.

    The results first and the file second, as :func:`save_scene` takes them.
    ``frames`` may be an iterator (:func:`vfactor.solve.iter_solve_scene`): each
    frame is written as it comes, and the file appears when the last is in.
    The order of vfactor 0.x before 2026-12-07, ``save_results(path, frames)``,
    still works and warns (``DeprecationWarning``).

    Raises:
        SceneError: a result that the file cannot hold (e.g. a converged
            vehicle without a pose); ``field`` is its path in the file. The file is then not written.
    """
    if isinstance(frames, (str, os.PathLike)) and not isinstance(path, (str, os.PathLike)):
        import warnings

        warnings.warn("save_results(path, frames) is deprecated: save_results(frames, path), as save_scene(scene, "
                      "path)", DeprecationWarning, stacklevel=2)
        frames, path = path, frames
    write_text_atomic(Path(path), _result_pieces(frames))


def _result_pieces(frames: Iterable[FrameResult]) -> Iterator[str]:
    """The text of :func:`_dumps` ``(results_to_dict(frames))``, one frame at a time."""
    yield '{\n  "frames": ['
    count = 0
    for i, frame in enumerate(frames):
        yield ("," if i else "") + "\n    " + _dumps(frame_result_to_dict(frame, i), 2)
        count += 1
    yield ("\n  ]" if count else "]") + "\n}\n"


def frame_result_to_dict(frame: FrameResult, index: int = 0) -> dict:
    """One frame of :func:`results_to_dict` (``{"t", "vehicles"}``; ``index`` names it in errors)."""
    t = float(frame.t)
    if not math.isfinite(t):
        raise SceneError(f"frames[{index}].t", f"expected a finite number of seconds, got {t}")
    return {"t": t, "vehicles": [_vehicle_to_dict(v, f"frames[{index}].vehicles[{j}]") for j, v in enumerate(frame.vehicles)]}


def results_to_dict(frames: list[FrameResult]) -> dict:
    """The results as a result-file dictionary, JSON-serialisable.

    Each vehicle entry holds, in this order: ``id``; ``world_T_vehicle`` (4x4,
    body -> world, metres); ``keypoints_world`` and ``keypoints_vehicle``
    (12x3, metres); ``pose_covariance`` (6x6, GTSAM tangent order: rotation
    (rad) then translation (m), body frame; null when not computed); ``status``
    (the :class:`~vfactor.result.Status` value); ``iterations``;
    ``final_error`` (null when NaN); ``message`` (when non-empty); and
    ``keypoint_covariances_world`` (12x3x3, m^2) when computed; ``body_type``
    and ``body_type_probability``; ``box`` (:func:`box_to_dict`:
    ``world_T_box``, ``size`` and their sigmas). For a
    ``degenerate`` or ``failed`` vehicle the pose, keypoint and covariance
    fields are null. A covariance with non-finite entries is written as null.

    Raises:
        SceneError: a converged / max_iterations vehicle without a pose or wireframe.
    """
    return {"frames": [frame_result_to_dict(frame, i) for i, frame in enumerate(frames)]}


def load_results(path: str | os.PathLike) -> list[FrameResult]:
    """Loads and validates a result file written by :func:`save_results`.

    Raises:
        SceneError: missing file or not JSON (field: the path), or an invalid
            field (field: its path, e.g. ``frames[0].vehicles[1].status``).
    """
    return results_from_dict(_read_json(Path(path)))


def results_from_dict(data: dict) -> list[FrameResult]:
    """Validates a parsed result file and builds the :class:`~vfactor.result.FrameResult` list.

    Checks every field: shapes (4x4 rigid ``world_T_vehicle``, 12x3 keypoints,
    6x6 symmetric ``pose_covariance``, 12x3x3 ``keypoint_covariances_world``),
    finite numbers, a known ``status``, null pose/keypoints/covariances for
    ``degenerate`` and ``failed`` and a pose and keypoints otherwise,
    ``keypoints_world`` consistent with the pose and ``keypoints_vehicle``,
    unique vehicle ids per frame, no unknown keys.

    Raises:
        SceneError: an invalid field, named by its path.
    """
    top = _object(data, "", _RESULT_TOP_KEYS, required=_RESULT_TOP_KEYS)
    frames = []
    for i, item in enumerate(_list(top["frames"], "frames")):
        path = f"frames[{i}]"
        frame = _object(item, path, _RESULT_FRAME_KEYS, required=_RESULT_FRAME_KEYS)
        t = _number(frame["t"], f"{path}.t", "a finite number of seconds")
        vehicles = []
        ids: dict[str, int] = {}
        for j, entry in enumerate(_list(frame["vehicles"], f"{path}.vehicles")):
            vehicle = _vehicle_from_dict(entry, f"{path}.vehicles[{j}]")
            if vehicle.id in ids:
                raise SceneError(
                    f"{path}.vehicles[{j}].id",
                    f"duplicate vehicle id {vehicle.id!r} (also vehicles[{ids[vehicle.id]}])",
                )
            ids[vehicle.id] = j
            vehicles.append(vehicle)
        frames.append(FrameResult(t=t, vehicles=vehicles))
    return frames


def _vehicle_to_dict(v: VehicleResult, path: str) -> dict:
    try:
        status = Status(v.status)
    except ValueError:
        raise SceneError(f"{path}.status", f"expected one of {[s.value for s in Status]}, got {v.status!r}") from None
    ok = status in ESTIMATE_STATUSES
    if ok and (v.world_T_vehicle is None or v.wireframe is None):
        raise SceneError(f"{path}.world_T_vehicle", f"status {status.value!r} needs a pose and a wireframe, got None")
    out: dict[str, Any] = {"id": str(v.id)}
    if ok:
        out["world_T_vehicle"] = np.asarray(v.world_T_vehicle.matrix(), dtype=float).tolist()
        out["keypoints_world"] = v.keypoints_world.tolist()
        out["keypoints_vehicle"] = v.keypoints_vehicle.tolist()
        out["pose_covariance"] = _finite_or_none(v.pose_covariance, (6, 6), f"{path}.pose_covariance")
        if out["pose_covariance"] is not None and v.extras.get("covariance") in COVARIANCE_KINDS:
            out["pose_covariance_kind"] = v.extras["covariance"]
    else:
        out.update(world_T_vehicle=None, keypoints_world=None, keypoints_vehicle=None, pose_covariance=None)
    out["status"] = status.value
    if v.extras.get("detections") is not None:
        out["detections"] = [int(j) for j in v.extras["detections"]]
    if ok and v.extras.get("swapped_keypoints"):
        out["swapped_keypoints"] = [finding.to_dict() for finding in v.extras["swapped_keypoints"]]
    out["iterations"] = int(v.iterations)
    error = float("nan") if v.final_error is None else float(v.final_error)
    out["final_error"] = error if math.isfinite(error) else None
    if v.message:
        out["message"] = str(v.message)
    if ok and v.body_type is not None:
        out["body_type"] = str(v.body_type)
        out["body_type_probability"] = float(v.body_type_probability)
    if ok:
        kp_cov = _finite_or_none(
            v.keypoint_covariances_world, (NUM_KEYPOINTS, 3, 3), f"{path}.keypoint_covariances_world"
        )
        if kp_cov is not None:
            out["keypoint_covariances_world"] = kp_cov
        if v.box is not None:
            out["box"] = box_to_dict(v.box)
    return out


def _finite_or_none(value, shape, path):
    if value is None:
        return None
    array = np.asarray(value, dtype=float)
    if array.shape != shape:
        raise SceneError(path, f"expected shape {shape}, got {array.shape}")
    return array.tolist() if np.all(np.isfinite(array)) else None


def _vehicle_from_dict(data, path: str) -> VehicleResult:
    entry = _object(data, path, _VEHICLE_KEYS, required=("id", "status"))
    vid = _string(entry["id"], f"{path}.id")
    status_value = entry["status"]
    try:
        status = Status(status_value) if isinstance(status_value, str) else None
    except ValueError:
        status = None
    if status is None:
        raise SceneError(
            f"{path}.status", f"expected one of {', '.join(s.value for s in Status)}, got {_kind(status_value)}"
        )
    ok = status in ESTIMATE_STATUSES
    fields = (
        "world_T_vehicle",
        "keypoints_world",
        "keypoints_vehicle",
        "pose_covariance",
        "keypoint_covariances_world",
        "box",
    )
    if not ok:
        for name in fields:
            if entry.get(name) is not None:
                raise SceneError(
                    f"{path}.{name}", f"expected null for a {status.value!r} vehicle, got {_kind(entry[name])}"
                )
    pose = wireframe = pose_covariance = keypoint_covariances = None
    if ok:
        for name in ("world_T_vehicle", "keypoints_vehicle"):
            if entry.get(name) is None:
                raise SceneError(f"{path}.{name}", f"missing: required for a {status.value!r} vehicle")
        T = _matrix(entry["world_T_vehicle"], f"{path}.world_T_vehicle", (4, 4))
        try:
            check_rigid_transform(T, f"{path}.world_T_vehicle")
        except CalibrationError as exc:
            raise SceneError(exc.field, exc.problem) from None
        pose = gtsam.Pose3(T)
        wireframe = Wireframe(_matrix(entry["keypoints_vehicle"], f"{path}.keypoints_vehicle", (NUM_KEYPOINTS, 3)))
        if entry.get("keypoints_world") is not None:
            world = _matrix(entry["keypoints_world"], f"{path}.keypoints_world", (NUM_KEYPOINTS, 3))
            gap = float(np.abs(world - wireframe.in_world(pose)).max())
            if gap > _KEYPOINTS_WORLD_TOL * max(1.0, float(np.abs(world).max())):
                raise SceneError(
                    f"{path}.keypoints_world",
                    f"expected world_T_vehicle applied to keypoints_vehicle, differs by up to {gap:.3g} m",
                )
        if entry.get("pose_covariance") is not None:
            pose_covariance = _matrix(entry["pose_covariance"], f"{path}.pose_covariance", (6, 6))
            _check_symmetric(pose_covariance, f"{path}.pose_covariance")
        if entry.get("keypoint_covariances_world") is not None:
            field = f"{path}.keypoint_covariances_world"
            items = _list(entry["keypoint_covariances_world"], field, f"a list of {NUM_KEYPOINTS} 3x3 matrices (m^2)")
            if len(items) != NUM_KEYPOINTS:
                raise SceneError(field, f"expected {NUM_KEYPOINTS} 3x3 matrices (m^2), got {len(items)} entries")
            keypoint_covariances = np.stack([_matrix(S, f"{field}[{k}]", (3, 3)) for k, S in enumerate(items)])
            for k, S in enumerate(keypoint_covariances):
                _check_symmetric(S, f"{field}[{k}]")
    iterations = entry.get("iterations", 0)
    if not _is_int(iterations) or iterations < 0:
        raise SceneError(f"{path}.iterations", f"expected a non-negative integer, got {_kind(iterations)}")
    final_error = entry.get("final_error")
    final_error = (
        float("nan") if final_error is None else _number(final_error, f"{path}.final_error", "a finite number or null")
    )
    message = entry.get("message", "")
    if not isinstance(message, str):
        raise SceneError(f"{path}.message", f"expected a string, got {_kind(message)}")
    body_type = _string(entry["body_type"], f"{path}.body_type") if entry.get("body_type") is not None else None
    body_type_probability = None
    if entry.get("body_type_probability") is not None:
        body_type_probability = _number(entry["body_type_probability"], f"{path}.body_type_probability",
                                        "a probability in [0, 1]")
        if not 0.0 <= body_type_probability <= 1.0:
            raise SceneError(f"{path}.body_type_probability", f"expected a probability in [0, 1], got "
                                                              f"{body_type_probability}")
    box = box_from_dict(entry["box"], f"{path}.box") if ok and entry.get("box") is not None else None
    detections = entry.get("detections")
    if detections is not None:
        items = _list(detections, f"{path}.detections", "a list of detection indices")
        if not all(_is_int(j) and j >= 0 for j in items) or len(set(items)) != len(items):
            raise SceneError(f"{path}.detections", f"expected distinct indices >= 0 into the frame's detections, "
                                                   f"got {_kind(detections)}")
    swapped = entry.get("swapped_keypoints")
    if swapped is not None:
        swapped = [SwapFinding.from_dict(item, f"{path}.swapped_keypoints[{k}]")
                   for k, item in enumerate(_list(swapped, f"{path}.swapped_keypoints", "a list of swapped pairs"))]
    kind = entry.get("pose_covariance_kind")
    if kind is not None and (kind not in COVARIANCE_KINDS or pose_covariance is None):
        raise SceneError(f"{path}.pose_covariance_kind", f"expected one of {', '.join(COVARIANCE_KINDS)} beside a "
                                                         f"pose_covariance, got {_kind(kind)}")
    return VehicleResult(
        id=vid,
        status=status,
        world_T_vehicle=pose,
        wireframe=wireframe,
        box=box,
        pose_covariance=pose_covariance,
        keypoint_covariances_world=keypoint_covariances,
        iterations=int(iterations),
        final_error=final_error,
        message=message,
        body_type=body_type,
        body_type_probability=body_type_probability,
        extras={**({} if kind is None else {"covariance": kind}),
                **({} if detections is None else {"detections": [int(j) for j in detections]}),
                **({"swapped_keypoints": swapped} if swapped else {})},
    )


_BOX_KEYS = ("world_T_box", "size", "size_sigma", "heading", "heading_sigma", "centre_sigma")


def box_to_dict(box: Box) -> dict:
    """A result vehicle's ``box`` (docs/scene-format.md): metres and radians, null sigmas where not computed."""
    def listed(a):
        return None if a is None or not np.all(np.isfinite(a)) else np.asarray(a, dtype=float).tolist()

    sigma = box.heading_sigma
    return {"world_T_box": np.asarray(box.world_T_box.matrix(), dtype=float).tolist(), "size": listed(box.size),
            "size_sigma": listed(box.size_sigma), "heading": float(box.heading),
            "heading_sigma": None if sigma is None or not math.isfinite(sigma) else float(sigma),
            "centre_sigma": listed(box.centre_sigma)}


def box_from_dict(data, path: str) -> Box:
    """A result vehicle's ``box`` back as a :class:`vfactor.box.Box`.

    Raises:
        SceneError: a field is missing or wrong (the error names it, under ``path``).
    """
    entry = _object(data, path, _BOX_KEYS, required=("world_T_box", "size", "heading"))
    T = _matrix(entry["world_T_box"], _join(path, "world_T_box"), (4, 4))
    try:
        check_rigid_transform(T, _join(path, "world_T_box"))
    except CalibrationError as exc:
        raise SceneError(exc.field, exc.problem) from None

    def lengths(name, optional):
        if optional and entry.get(name) is None:
            return None
        values = _numbers(entry[name], _join(path, name), "3 non-negative numbers (m)" + (" or null" if optional else ""),
                          (3,))
        if np.any(values < 0):
            raise SceneError(_join(path, name), f"expected 3 non-negative numbers (m), got {values.tolist()}")
        return values

    heading_sigma = None
    if entry.get("heading_sigma") is not None:
        heading_sigma = _number(entry["heading_sigma"], _join(path, "heading_sigma"),
                                "a non-negative number (rad) or null")
        if heading_sigma < 0:
            raise SceneError(_join(path, "heading_sigma"), f"expected a non-negative number (rad), got {heading_sigma}")
    return Box(gtsam.Pose3(T), lengths("size", False), lengths("size_sigma", True),
               _number(entry["heading"], _join(path, "heading"), "a finite number (rad)"), heading_sigma,
               lengths("centre_sigma", True))


def _check_symmetric(S: np.ndarray, field: str) -> None:
    if np.abs(S - S.T).max() > SYMMETRY_RTOL * max(np.abs(S).max(), np.finfo(float).tiny):
        raise SceneError(field, "expected a symmetric matrix, got an asymmetric one")
    if np.any(np.diag(S) < 0):
        raise SceneError(field, f"expected non-negative variances on the diagonal, got {np.diag(S).tolist()}")


# ============================================================== JSON helpers
def _read_json(path: Path):
    return read_json(path, SceneError)


def _read_json_lines(path: Path) -> dict:
    """A recorded stream as a scene file's dictionary: its header line with the frame lines after its own
    ``frames``, if any (as :func:`vfactor.stream.stream_header` reads a live stream's)."""
    lines = [(n, line) for n, line in enumerate(read_text(path, SceneError).splitlines(), 1) if line.strip()]
    if not lines:
        raise SceneError(str(path), "empty: a stream starts with its header line (the scene's cameras)")
    header, *frames = [parse_json(line, f"{path}:{n}", SceneError) for n, line in lines]
    if not isinstance(header, dict):
        raise SceneError(f"{path}:{lines[0][0]}", "expected the stream's header: an object with the cameras")
    given = header.get("frames", [])
    return {**header, "frames": given + frames} if isinstance(given, list) else header  # the reader names a bad one


def _write_json(path: Path, data) -> None:
    """The one writer of scene and result files: atomic (:func:`vfactor.jsonio.write_text_atomic`)."""
    write_text_atomic(path, _dumps(data) + "\n")


def _depth(value) -> int:
    if isinstance(value, list):
        return 1 + max((_depth(v) for v in value), default=0)
    return 0


def _dumps(value, indent: int = 0) -> str:
    """JSON with one line per matrix row (or per small matrix) and strict finite floats."""
    pad = "  " * indent
    if isinstance(value, dict):
        if not value:
            return "{}"
        items = [f"{pad}  {json.dumps(str(k))}: {_dumps(v, indent + 1)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(value, list):
        if not value or _depth(value) == 1 and not any(isinstance(v, dict) for v in value):
            return json.dumps(value, allow_nan=False)
        if _depth(value) in (2, 3) and not _has_dict(value):
            items = [f"{pad}  {json.dumps(v, allow_nan=False)}" for v in value]
        else:
            items = [f"{pad}  {_dumps(v, indent + 1)}" for v in value]
        return "[\n" + ",\n".join(items) + "\n" + pad + "]"
    return json.dumps(value, allow_nan=False)


def _has_dict(value) -> bool:
    if isinstance(value, dict):
        return True
    if isinstance(value, list):
        return any(_has_dict(v) for v in value)
    return False


# ========================================================= validation helpers






def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else str(key)


def _object(value, path: str, known: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
    if not isinstance(value, dict):
        raise SceneError(path, f"expected an object, got {_kind(value)}")
    for key in value:
        if key not in known:
            raise SceneError(_join(path, str(key)), f"unknown key; known keys: {', '.join(known)}")
    for key in required:
        if key not in value:
            raise SceneError(_join(path, key), "missing (required)")
    return value


def _list(value, path: str, what: str = "a list") -> list:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        raise SceneError(path, f"expected {what}, got {_kind(value)}")
    return list(value)


def _string(value, path: str) -> str:
    if not isinstance(value, str) or not value:
        raise SceneError(path, f"expected a non-empty string, got {_kind(value)}")
    return value


def _number(value, path: str, what: str = "a finite number") -> float:
    if not _is_number(value) or not math.isfinite(float(value)):
        raise SceneError(path, f"expected {what}, got {_kind(value)}")
    return float(value)


def _numbers(value, path: str, what: str, sizes: tuple[int, ...]) -> np.ndarray:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) not in sizes:
        raise SceneError(path, f"expected {what}, got {_kind(value)}")
    for k, item in enumerate(value):
        if not _is_number(item) or not math.isfinite(float(item)):
            raise SceneError(path, f"expected {what}, got {_kind(item)} at [{k}]")
    return np.array(value, dtype=float)


def _matrix(value, path: str, shape: tuple[int, int], what: str | None = None) -> np.ndarray:
    what = what or f"a {shape[0]}x{shape[1]} matrix of finite numbers"
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) != shape[0]:
        raise SceneError(path, f"expected {what}, got {_kind(value)}")
    for r, row in enumerate(value):
        if not isinstance(row, (list, tuple)) or len(row) != shape[1]:
            raise SceneError(path, f"expected {what}, got {_kind(row)} as row {r}")
        for c, item in enumerate(row):
            if not _is_number(item) or not math.isfinite(float(item)):
                raise SceneError(path, f"expected {what}, got {_kind(item)} at [{r}][{c}]")
    return np.array(value, dtype=float)


def _existing_file(value, path: str, base: _Folder, what: str) -> str:
    if not isinstance(value, str) or not value or "\x00" in value:
        raise SceneError(path, f"expected {what} (a string), got {_kind(value)}")
    resolved = str(resolve_path(value, base.path))
    if not base.allow_outside:
        inside = _inside(resolved, str(base.path))
        if not inside or not _inside(os.path.realpath(resolved), os.path.realpath(base.path)):
            how = "is" if not inside else f"is a symbolic link to {os.path.realpath(resolved)},"
            raise SceneError(path, f"{value!r} {how} outside the scene's folder {base.path} (allow it with "
                             "--allow-outside-paths, or load_scene(..., allow_outside_paths=True))")
    if not os.path.isfile(resolved):
        raise SceneError(path, f"file not found: {resolved}")
    return resolved


def _inside(path: str, folder: str) -> bool:
    try:
        return os.path.commonpath([folder, path]) == folder
    except ValueError:  # another drive (Windows)
        return False


def _path_out(path_str: str, scene_base: Path | None, out_base: Path | None) -> str:
    """A held path as written into a file whose relative paths start at ``out_base``."""
    if out_base is None:
        return str(path_str)
    absolute = str(resolve_path(path_str, scene_base))
    try:
        return Path(os.path.relpath(absolute, os.path.abspath(out_base))).as_posix()
    except ValueError:  # another drive (Windows)
        return absolute
