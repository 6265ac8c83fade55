"""ASAM OpenLABEL 1.0.0 JSON: cameras, vehicles, boxes, wireframes and the keypoints each camera saw.

The file follows the OpenLABEL 1.0.0 JSON schema (``$id``
``https://openlabel.asam.net/V1-0-0/schema#``; the tests validate every file
against it) and the layout of the TUM Traffic (A9) intersection labels where
the schema leaves a choice. docs/output-formats.md gives every field; in short:

* ``coordinate_systems``: the world (``type "scene_cs"``, no parent) and one
  ``sensor_cs`` per camera, child of the world, ``pose_wrt_parent.matrix4x4``
  = ``world_T_camera`` flattened row-major (it maps camera points to world
  points, ``X_world = M X_camera``, as the VCD library reads it).
* ``streams``: one ``camera`` stream per camera (same name as its coordinate
  system), ``uri`` empty (a frame's image of the camera, when the scene names
  one, is ``frame_properties.streams.<camera>.uri``), with ``intrinsics_pinhole``: ``camera_matrix`` (K with a zero fourth
  column, 12 numbers row-major: the schema's key), ``camera_matrix_3x4`` (the
  same 3x4 as rows: the key of the TUM Traffic files and the VCD library),
  ``distortion_coeffs`` and ``distortion_coeffs_1xN`` (OpenCV ``k1 k2 p1 p2
  k3``), ``width_px`` and ``height_px`` when the image size is known.
* ``objects``: one per vehicle id, uid ``"0"``, ``"1"``, ... in order of first
  appearance (the schema allows only integer or UUID uids), ``name`` = the
  vehicle id, ``type`` = its most frequent body type (``"vehicle"`` when none
  was chosen), ``frame_intervals`` where it appears.
* ``frames``: key = frame index in the results, ``frame_properties.timestamp``
  = ``t`` (s); per object ``object_data``: ``cuboid`` ``shape3D`` (only for a
  solved vehicle) with ``val = [x, y, z, qx, qy, qz, qw, l, w, h]``: the box
  centre and rotation (box -> world, quaternion in (x, y, z, w) order) in the
  world frame and its length, width, height (m); ``point3d`` per solved
  keypoint (world, m); ``point2d`` per seen keypoint per camera (pixels,
  ``coordinate_system`` and ``stream`` = the camera); ``text`` ``status``,
  ``body_type``, ``message``; ``num`` ``body_type_probability``; ``vec``
  ``pose_covariance``.

A vehicle that was not solved keeps its object, its ``status`` and
``message`` and its 2D keypoints, and has no cuboid or 3D points.
"""

from __future__ import annotations

import json
import math
import os
from collections import Counter

import numpy as np

from vfactor.errors import InputError
from vfactor.formats.common import (
    ReadBox,
    WriteReport,
    box_from_centre,
    check_output_path,
    check_results,
    number,
    quaternion_wxyz,
    rotation_from_wxyz,
    solved_box,
    unsolved_of,
)
from vfactor.jsonio import read_json, write_text_atomic
from vfactor.keypoints import KEYPOINT_NAMES
from vfactor.observations import Scene
from vfactor.result import FrameResult

__all__ = ["SCHEMA_VERSION", "CUBOID_NAME", "openlabel_dict", "write_openlabel", "read_openlabel"]

#: ``openlabel.metadata.schema_version`` written.
SCHEMA_VERSION = "1.0.0"
#: ``name`` of the box cuboid (the TUM Traffic labels' name).
CUBOID_NAME = "shape3D"


def openlabel_dict(results: list[FrameResult], scene: Scene, name: str | None = None,
                   world: str | None = None) -> dict:
    """The results as an OpenLABEL 1.0.0 dictionary (module docstring; docs/output-formats.md).

    Args:
        results: one :class:`~vfactor.result.FrameResult` per scene frame, in the scene's order.
        scene: the scene they were solved from (cameras, 2D keypoints).
        name: ``metadata.name``; None: none written.
        world: the world coordinate system's name; None: ``"world"``, or where a camera has that name,
            ``"world_cs"`` (and so on: a name no camera has).

    Raises:
        InputError: the results and the scene do not pair up, ``world`` is empty or a camera's name.
    """
    check_results(results, scene, True, "OpenLABEL")
    if world is None:  # the CLI names none: a camera called "world" must not stop the output
        world = "world"
        while world in scene.cameras:
            world += "_cs"
    if not isinstance(world, str) or not world or world in scene.cameras:
        raise InputError("world", f"expected a coordinate-system name that no camera has, got {world!r}")
    from vfactor import __version__

    metadata = {"schema_version": SCHEMA_VERSION, "annotator": f"vfactor {__version__}",
                "comment": "vfactor estimates: boxes, wireframes and poses in the world frame (m, rad, s)"}
    if name is not None:
        metadata["name"] = str(name)
    systems = {world: {"type": "scene_cs", "parent": "", "children": list(scene.cameras)}}
    streams = {}
    for cam_name, cam in scene.cameras.items():
        systems[cam_name] = {"type": "sensor_cs", "parent": world, "children": [],
                             "pose_wrt_parent": {"matrix4x4": [number(x, 9) for x in cam.world_T_camera.ravel()]}}
        P = np.hstack([cam.K, np.zeros((3, 1))])
        pinhole = {"camera_matrix": [number(x, 9) for x in P.ravel()],
                   "camera_matrix_3x4": [[number(x, 9) for x in row] for row in P],
                   "distortion_coeffs": [number(x, 12) for x in cam.dist],
                   "distortion_coeffs_1xN": [number(x, 12) for x in cam.dist]}
        if cam.image_size is not None:
            pinhole["width_px"], pinhole["height_px"] = int(cam.image_size[0]), int(cam.image_size[1])
        streams[cam_name] = {"type": "camera", "uri": "", "description": f"camera {cam_name} (OpenCV pinhole, "
                             "x right, y down, z forward)", "stream_properties": {"intrinsics_pinhole": pinhole}}

    uids: dict[str, str] = {}
    seen_frames: dict[str, list[int]] = {}
    body_types: dict[str, Counter] = {}
    frames = {}
    for i, (frame, scene_frame) in enumerate(zip(results, scene.frames)):
        objects = {}
        for v in frame.vehicles:
            uid = uids.setdefault(v.id, str(len(uids)))
            seen_frames.setdefault(v.id, []).append(i)
            if v.ok and v.body_type is not None:
                body_types.setdefault(v.id, Counter())[v.body_type] += 1
            objects[uid] = {"object_data": _object_data(v, scene_frame.detections_of(v.id), world)}
        properties: dict = {"timestamp": number(frame.t, 9)}
        if scene_frame.images:
            properties["streams"] = {cam: {"uri": str(image)} for cam, image in scene_frame.images.items()}
        frames[str(i)] = {"frame_properties": properties, "objects": objects}
    objects = {}
    for vid, uid in uids.items():
        counts = body_types.get(vid)
        objects[uid] = {"name": str(vid), "type": counts.most_common(1)[0][0] if counts else "vehicle",
                        "coordinate_system": world, "frame_intervals": _intervals(seen_frames[vid])}
    return {"openlabel": {"metadata": metadata, "coordinate_systems": systems, "streams": streams,
                          "objects": objects, "frames": frames}}


def write_openlabel(path: str | os.PathLike, results: list[FrameResult], scene: Scene, name: str | None = None,
                    world: str | None = None) -> WriteReport:
    """Writes the results as one OpenLABEL 1.0.0 JSON file, atomically (:func:`openlabel_dict`).

    Unsolved vehicles stay in the file: their object, ``status`` and ``message`` text and 2D keypoints,
    without a cuboid (so :attr:`WriteReport.skipped` is empty).

    Raises:
        InputError: see :func:`openlabel_dict`.
        OSError: the file cannot be written (the old one, if any, is left as it was).
    """
    path = check_output_path(path, "OpenLABEL")
    data = openlabel_dict(results, scene, name, world)
    write_text_atomic(path, json.dumps(data, indent=1, allow_nan=False) + "\n")
    return WriteReport("openlabel", [path], unsolved_of(results), [])


def read_openlabel(path: str | os.PathLike) -> list[ReadBox]:
    """Reads the boxes of an OpenLABEL file written by :func:`write_openlabel` (or any file with
    ``shape3D``-style 10-value cuboids in the world frame).

    Returns:
        One :class:`~vfactor.formats.common.ReadBox` per object per frame, frames in key order:
        ``id`` = the object's name, ``box`` from the cuboid (None without one), ``status`` and ``label``
        (body type) from the ``text`` data, ``score`` = ``body_type_probability``.

    Raises:
        InputError: not JSON, or a field this reader needs is missing or malformed (the error names it).
    """
    data = read_json(path, InputError)
    root = _field(data, "openlabel", "", dict)
    objects = _field(root, "objects", "openlabel", dict, {})
    out = []
    frames = _field(root, "frames", "openlabel", dict, {})
    for key in sorted(frames, key=lambda k: int(k) if k.isdigit() else math.inf):
        where = f"openlabel.frames.{key}"
        if not key.isdigit():
            raise InputError(where, "expected a frame number as the key")
        frame = _field(frames, key, "openlabel.frames", dict)
        for uid, entry in _field(frame, "objects", where, dict, {}).items():
            od = _field(entry, "object_data", f"{where}.objects.{uid}", dict, {})
            texts = {t.get("name"): t.get("val") for t in od.get("text", []) if isinstance(t, dict)}
            nums = {t.get("name"): t.get("val") for t in od.get("num", []) if isinstance(t, dict)}
            box = None
            cuboids = [c for c in od.get("cuboid", []) if isinstance(c, dict) and c.get("name") == CUBOID_NAME]
            if cuboids:
                val = cuboids[0].get("val")
                field = f"{where}.objects.{uid}.object_data.cuboid[0].val"
                if not isinstance(val, list) or len(val) != 10 or not all(_is_number(x) for x in val):
                    raise InputError(field, f"expected 10 numbers [x, y, z, qx, qy, qz, qw, l, w, h], got {val!r}")
                x, y, z, qx, qy, qz, qw, length, width, height = (float(v) for v in val)
                try:
                    R = rotation_from_wxyz([qw, qx, qy, qz])
                except InputError as exc:
                    raise InputError(field, exc.problem) from None
                box = box_from_centre([x, y, z], R, [length, width, height], field)
            obj = objects.get(uid, {}) if isinstance(objects.get(uid), dict) else {}
            out.append(ReadBox(frame=int(key), id=str(obj.get("name", uid)), box=box, status=texts.get("status"),
                               label=texts.get("body_type"), score=nums.get("body_type_probability"),
                               extras={"uid": uid, "message": texts.get("message"),
                                       "timestamp": frame.get("frame_properties", {}).get("timestamp")}))
    return out


def _object_data(v, detections, world: str) -> dict:
    status = getattr(v.status, "value", str(v.status))
    texts = [{"name": "status", "val": status}]
    if v.message:
        texts.append({"name": "message", "val": str(v.message)})
    data: dict = {}
    box = solved_box(v)
    if box is not None:
        T = np.asarray(box.world_T_box.matrix(), dtype=float)
        w, qx, qy, qz = quaternion_wxyz(T[:3, :3])
        val = [*T[:3, 3], qx, qy, qz, w, *box.size]
        attributes: dict = {"num": [{"name": "heading", "val": number(box.heading, 9)}]}
        vec = [{"name": n, "val": [number(x) for x in s]} for n, s in
               (("size_sigma", box.size_sigma), ("centre_sigma", box.centre_sigma))
               if s is not None and np.all(np.isfinite(s))]
        if box.heading_sigma is not None and math.isfinite(box.heading_sigma):
            attributes["num"].append({"name": "heading_sigma", "val": number(box.heading_sigma, 9)})
        if vec:
            attributes["vec"] = vec
        data["cuboid"] = [{"name": CUBOID_NAME, "val": [number(x, 9) for x in val], "coordinate_system": world,
                           "attributes": attributes}]
        kp = v.keypoints_world
        if kp is not None:
            data["point3d"] = [{"name": f"keypoint3d:{KEYPOINT_NAMES[k]}", "id": k, "coordinate_system": world,
                                "val": [number(x) for x in kp[k]]} for k in range(len(kp))]
        if v.body_type is not None:
            texts.append({"name": "body_type", "val": str(v.body_type)})
            data["num"] = [{"name": "body_type_probability", "val": number(v.body_type_probability or 0.0)}]
        cov = v.pose_covariance
        if cov is not None and np.shape(cov) == (6, 6) and np.all(np.isfinite(cov)):
            data["vec"] = [{"name": "pose_covariance", "val": [float(x) for x in np.asarray(cov).ravel()]}]
    points = []
    for det in detections:
        for k in np.flatnonzero(det.seen):
            points.append({"name": f"{det.camera}:{KEYPOINT_NAMES[k]}", "id": int(k), "coordinate_system": det.camera,
                           "stream": det.camera, "val": [number(x, 3) for x in det.keypoints[k]],
                           "attributes": {"num": [{"name": "confidence", "val": number(det.confidence[k], 4)}]}})
    if points:
        data["point2d"] = points
    data["text"] = texts
    return data


def _intervals(frames: list[int]) -> list[dict]:
    out: list[dict] = []
    for f in sorted(set(frames)):
        if out and out[-1]["frame_end"] == f - 1:
            out[-1]["frame_end"] = f
        else:
            out.append({"frame_start": f, "frame_end": f})
    return out


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


_MISSING = object()


def _field(obj, key: str, where: str, kind: type, default=_MISSING):
    if not isinstance(obj, dict):
        raise InputError(where or key, f"expected a JSON object, got {type(obj).__name__}")
    if key not in obj:
        if default is _MISSING:
            raise InputError(f"{where}.{key}" if where else key, "missing")
        return default
    value = obj[key]
    if not isinstance(value, kind):
        raise InputError(f"{where}.{key}" if where else key, f"expected a JSON {kind.__name__}, "
                                                             f"got {type(value).__name__}")
    return value
