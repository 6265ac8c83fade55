"""Camera calibration files: OpenCV FileStorage, ROS CameraInfo YAML, Kalibr camchain YAML, projection matrices.

One entry point, :func:`load_calibration`, reads a file into a
:class:`~vfactor.camera.Camera`; :func:`read_calibration` returns what the file
itself gives (a :class:`Calibration`: intrinsics, lens model, distortion, and the
extrinsic and image size where the file has them), for callers that supply the
rest (the scene loader). The format is detected from the file's content
(:func:`detect_format`) unless given. The camera's name always comes from the
caller, never from the file or its name. docs/calibration.md describes each
format, the fields read, and how the extrinsic is given.

Every problem raises :class:`~vfactor.errors.CalibrationError` whose field names
the file and the node or key, e.g. ``cam0.yaml:camera_matrix`` or
``camchain.yaml:cam1.intrinsics``, in one line; OpenCV, YAML and JSON parse
errors never escape raw. Sizes are checked before anything is allocated
(matrices at most 16 x 16, files at most :data:`MAX_FILE_BYTES`).

Frames (docs/conventions.md): ``world_T_camera`` maps camera points (OpenCV axes:
x right, y down, z forward) to world points, metres; ``camera_T_world`` is its
inverse, what ``cv2.solvePnP`` (``rvec``, ``tvec``) and a projection matrix
``P = K [R | t]`` hold.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vfactor.camera import Camera, _check_dist, _check_K, check_rigid_transform
from vfactor.errors import CalibrationError
from vfactor.jsonio import describe as _kind, is_int as _is_int, is_number as _is_number, not_a_file

__all__ = [
    "CALIBRATION_FORMATS",
    "MAX_FILE_BYTES",
    "Calibration",
    "decompose_projection_matrix",
    "detect_format",
    "kalibr_cameras",
    "load_calibration",
    "read_calibration",
]

#: The formats :func:`read_calibration` reads (``format=`` / the scene's ``calibration_format``).
CALIBRATION_FORMATS = ("opencv", "ros", "kalibr", "projection")
#: Largest calibration file read, bytes (a real one is a few kilobytes).
MAX_FILE_BYTES = 1 << 20
#: Largest rows / cols of a matrix node read from a calibration file (a 4x4 transform is the largest
#: vfactor reads); checked before OpenCV reads the data, as ``rows: 100000`` makes it allocate gigabytes.
_MAX_MATRIX_SIZE = 16
#: Largest image side accepted, pixels.
_MAX_IMAGE_SIDE = 1 << 20

#: Lens-model names of each format -> vfactor's model (Camera.model).
_OPENCV_MODELS = {"pinhole": "pinhole", "plumb_bob": "pinhole", "rational_polynomial": "pinhole",
                  "fisheye": "fisheye", "equidistant": "fisheye"}
_ROS_MODELS = {"plumb_bob": "pinhole", "rational_polynomial": "pinhole", "equidistant": "fisheye",
               "fisheye": "fisheye"}
_ROS_SIZES = {"plumb_bob": (4, 5), "rational_polynomial": (8, 12, 14), "equidistant": (4,), "fisheye": (4,)}
_KALIBR_MODELS = {"radtan": "pinhole", "none": "pinhole", "equidistant": "fisheye"}


@dataclass(frozen=True)
class Calibration:
    """What a calibration file gives (before the caller names the camera and supplies what it lacks).

    Attributes:
        path: the file, as given.
        format: one of :data:`CALIBRATION_FORMATS`.
        K: 3x3 intrinsics, pixels.
        dist: distortion coefficients of ``model`` (OpenCV's order, see :class:`~vfactor.camera.Camera`).
        model: lens model, ``"pinhole"`` or ``"fisheye"``.
        world_T_camera: 4x4 camera -> world (metres) when the file gives an extrinsic, else None.
        image_size: ``(width, height)`` pixels when the file gives it, else None.
        file_camera_name: the name the file gives its camera (``camera_name``, the camchain key), or
            None; informational only: the camera's name is always the caller's.
        nodes: the file's node for each camera field (``"K"`` -> ``"camera_matrix"`` ...), for messages.
    """

    path: str
    format: str
    K: np.ndarray
    dist: np.ndarray
    model: str = "pinhole"
    world_T_camera: np.ndarray | None = None
    image_size: tuple[int, int] | None = None
    file_camera_name: str | None = None
    nodes: dict = field(default_factory=dict)

    def camera(self, name: str, world_T_camera=None, image_size=None) -> Camera:
        """The camera, named by the caller; ``world_T_camera`` / ``image_size`` supply what the file lacks.

        Args:
            name: the camera's name (the scene's).
            world_T_camera: 4x4 camera -> world, metres; required when the file has no extrinsic,
                an error when it has one (the pose would be given twice).
            image_size: ``(width, height)`` pixels, when the file has none (an error when it has one).

        Raises:
            CalibrationError: the extrinsic is missing or given twice, the image size is given
                twice, or a value is invalid (field: ``<file>:<node>``, or ``world_T_camera`` /
                ``image_size`` for the arguments).
        """
        where = self.path
        if world_T_camera is not None and self.world_T_camera is not None:
            raise CalibrationError(f"{where}:{self.nodes.get('world_T_camera', 'world_T_camera')}",
                                   "the file gives the extrinsic; world_T_camera given as well (give it once)")
        if world_T_camera is None and self.world_T_camera is None:
            raise CalibrationError(f"{where}:world_T_camera", f"missing extrinsic: {_EXTRINSIC_HINT[self.format]}; "
                                   "give world_T_camera (4x4, camera -> world) beside the file")
        if image_size is not None and self.image_size is not None:
            raise CalibrationError(f"{where}:{self.nodes.get('image_size', 'image_size')}",
                                   "the file gives the image size; image_size given as well (give it once)")
        from_file = world_T_camera is None
        try:
            return Camera(name=name, K=self.K, world_T_camera=self.world_T_camera if from_file else world_T_camera,
                          dist=self.dist, image_size=self.image_size if image_size is None else image_size,
                          model=self.model)
        except CalibrationError as exc:
            own = exc.field in ("K", "dist", "model") or (exc.field == "world_T_camera" and from_file) or (
                exc.field == "image_size" and image_size is None)
            if own:
                raise CalibrationError(f"{where}:{self.nodes.get(exc.field, exc.field)}", exc.problem) from None
            raise


_EXTRINSIC_HINT = {
    "opencv": "the file has no world_T_camera, camera_T_world or rvec + tvec node",
    "ros": "a ROS camera_info file holds intrinsics only",
    "kalibr": "a Kalibr camchain holds poses relative to other cameras or an IMU only",
    "projection": "a projection matrix always has one",
}


# ================================================================ entry points
def load_calibration(path, name: str, format: str | None = None, world_T_camera=None, chain_camera: str | None = None,
                     image_size=None) -> Camera:
    """Loads a camera from a calibration file.

    Args:
        path: the file (OpenCV FileStorage YAML/XML, ROS CameraInfo YAML, Kalibr camchain
            YAML, or a 3x4 projection matrix as text, JSON or ``.npy``; docs/calibration.md).
        name: the camera's name; never taken from the file.
        format: one of :data:`CALIBRATION_FORMATS`; None: detected from the content.
        world_T_camera: 4x4 camera -> world (metres), for a file without an extrinsic (ROS,
            Kalibr, an OpenCV file without one); an error for a file that has one.
        chain_camera: which camera of a Kalibr camchain (``"cam1"``); None: the only one.
        image_size: ``(width, height)`` pixels, for a file that gives none.

    Returns:
        The :class:`~vfactor.camera.Camera`.

    Raises:
        CalibrationError: unreadable or malformed file, missing or doubly given extrinsic;
            the field names the file and the node (``cam0.yaml:camera_matrix``).
    """
    return read_calibration(path, format, chain_camera).camera(name, world_T_camera, image_size)


def read_calibration(path, format: str | None = None, chain_camera: str | None = None) -> Calibration:
    """Reads what a calibration file gives, checked (see :func:`load_calibration` for the arguments).

    Raises:
        CalibrationError: the file is missing, too large, of an unknown format, or malformed
            (field: ``<file>`` or ``<file>:<node>``).
    """
    where = str(path)
    if format is not None and format not in CALIBRATION_FORMATS:
        raise CalibrationError("format", f"expected one of {', '.join(CALIBRATION_FORMATS)}, got {format!r}")
    if chain_camera is not None and (not isinstance(chain_camera, str) or not chain_camera):
        raise CalibrationError("chain_camera", f"expected a non-empty string, got {chain_camera!r}")
    content = _read_bytes(Path(path), where)
    if format is None:
        format = detect_format(path, content)
    if chain_camera is not None and format != "kalibr":
        raise CalibrationError(where, f"chain_camera {chain_camera!r} given for a {format} file (only a Kalibr "
                                      "camchain holds several cameras)")
    reader = {"opencv": _read_opencv, "ros": _read_ros, "kalibr": _read_kalibr, "projection": _read_projection}[format]
    if format == "kalibr":
        return reader(where, content, chain_camera)
    return reader(where, content)


def detect_format(path, content: bytes | None = None) -> str:
    """The format of a calibration file, from its content.

    ``.npy`` data, or JSON / text of a 3x4 matrix: ``projection``; XML, a ``%YAML`` header or
    ``!!opencv-matrix`` nodes: ``opencv``; YAML with ``camera_matrix``: ``ros``; YAML whose
    entries hold ``intrinsics`` or ``camera_model``: ``kalibr``.

    Raises:
        CalibrationError: (field: the file) none of these.
    """
    where = str(path)
    if content is None:
        content = _read_bytes(Path(path), where)
    if content.startswith(b"\x93NUMPY"):
        return "projection"
    text = _text(content, where).lstrip("\ufeff \t\r\n")
    if text.startswith(("%YAML", "<?xml", "<opencv_storage")) or "!!opencv-matrix" in text:
        return "opencv"
    if text.startswith(("{", "[")):
        try:
            data = _parse_json(text, where)
        except CalibrationError:
            data = None
        if isinstance(data, list) or (isinstance(data, dict) and "P" in data):
            return "projection"
    else:
        data = None
    if data is None and _plain_numbers(text) is not None:
        return "projection"
    if data is None:
        try:
            data = _parse_yaml(text, where)
        except CalibrationError:
            data = None
    if isinstance(data, dict):
        if "camera_matrix" in data:
            return "ros"
        if any(isinstance(v, dict) and ("intrinsics" in v or "camera_model" in v) for v in data.values()):
            return "kalibr"
    raise CalibrationError(where, "unknown calibration format: expected an OpenCV FileStorage file (%YAML:1.0 or "
                                  "XML), a ROS camera_info YAML (camera_matrix), a Kalibr camchain (cam0: intrinsics) "
                                  "or a 3x4 projection matrix; give the format (calibration_format)")


# ================================================================ OpenCV FileStorage
def _read_opencv(where: str, content: bytes) -> Calibration:
    """OpenCV ``cv2.FileStorage`` (YAML or XML): camera_matrix, distortion_coefficients, distortion_model,
    image_width / image_height, camera_name, and world_T_camera | camera_T_world | rvec + tvec."""
    import cv2

    text = _text(content, where)
    try:
        fs = cv2.FileStorage(where, cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # OpenCV 5 wraps parse errors in SystemError
        detail = getattr(exc, "err", None) or getattr(exc.__cause__, "err", None) or "parse error"
        raise CalibrationError(where, f"not a readable OpenCV FileStorage file ({_one_line(detail)}){_hint(text)}") from None
    if not fs.isOpened():
        raise CalibrationError(where, "not a readable OpenCV FileStorage file")
    try:

        def mat(node_name):
            return _read_matrix(fs.getNode(node_name), f"{where}:{node_name}")

        try:
            K = mat("camera_matrix")
        except CalibrationError as exc:
            raise CalibrationError(exc.field, exc.problem + _hint(text)) from None
        if K is None:
            raise CalibrationError(f"{where}:camera_matrix", f"missing{_hint(text)}")
        model = "pinhole"
        node = fs.getNode("distortion_model")
        if not node.empty():
            if not node.isString():
                raise CalibrationError(f"{where}:distortion_model", f"expected a string, got {_node_kind(node)}")
            model = _lens_model(node.string(), f"{where}:distortion_model", _OPENCV_MODELS)
        dist = mat("distortion_coefficients")
        dist = None if dist is None else np.asarray(dist, dtype=float).ravel()
        node = fs.getNode("camera_name")
        if not node.empty() and not node.isString():
            raise CalibrationError(f"{where}:camera_name", f"expected a string, got {_node_kind(node)}")
        file_name = node.string() if not node.empty() and node.string() else None
        width, height = fs.getNode("image_width"), fs.getNode("image_height")
        image_size = None
        if not width.empty() or not height.empty():
            image_size = (_read_size(width, f"{where}:image_width"), _read_size(height, f"{where}:image_height"))
        world_T_camera, extrinsic_node = mat("world_T_camera"), "world_T_camera"
        if world_T_camera is None:
            camera_T_world = mat("camera_T_world")
            if camera_T_world is not None:
                extrinsic_node = "camera_T_world"
                world_T_camera = np.linalg.inv(check_rigid_transform(camera_T_world, f"{where}:camera_T_world"))
            else:
                rvec, tvec = mat("rvec"), mat("tvec")
                if (rvec is None) != (tvec is None):
                    missing = "tvec" if tvec is None else "rvec"
                    raise CalibrationError(f"{where}:{missing}", "missing: rvec and tvec come together")
                if rvec is not None:
                    extrinsic_node = "rvec"
                    world_T_camera = _from_rvec_tvec(rvec, tvec, where)
    finally:
        fs.release()
    return _checked(where, "opencv", K, dist, model, world_T_camera, image_size, file_name,
                    {"K": "camera_matrix", "dist": "distortion_coefficients", "model": "distortion_model",
                     "world_T_camera": extrinsic_node, "image_size": "image_width"})


def _hint(text: str) -> str:
    """What a file given as OpenCV FileStorage looks like instead, for the message."""
    if "!!opencv-matrix" in text or "opencv_storage" in text:
        return ""
    if re.search(r"^camera_matrix:\s*$", text, re.M):
        return " (it looks like a ROS camera_info YAML: calibration_format 'ros')"
    if re.search(r"^\s+intrinsics:", text, re.M):
        return " (it looks like a Kalibr camchain: calibration_format 'kalibr')"
    return ""


def _from_rvec_tvec(rvec, tvec, where: str) -> np.ndarray:
    """world_T_camera from OpenCV's rvec / tvec (world -> camera, as cv2.solvePnP returns them)."""
    import cv2

    rvec, tvec = np.asarray(rvec, float).ravel(), np.asarray(tvec, float).ravel()
    if rvec.size != 3 or tvec.size != 3:
        raise CalibrationError(f"{where}:rvec", "rvec and tvec must have 3 entries each")
    if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        raise CalibrationError(f"{where}:rvec", "rvec and tvec contain NaN or infinite entries")
    camera_T_world = np.eye(4)
    camera_T_world[:3, :3] = cv2.Rodrigues(rvec)[0]
    camera_T_world[:3, 3] = tvec
    return np.linalg.inv(camera_T_world)


def _node_kind(node) -> str:
    """A short description of a FileStorage node for error messages."""
    if node.isString():
        text = node.string()
        return f"the string {text if len(text) <= 40 else text[:37] + '...'!r}"
    if node.isInt() or node.isReal():
        return repr(node.real())
    if node.isSeq():
        return f"a list of {node.size()}"
    if node.isMap():
        return "a map"
    return "an empty node"


def _read_matrix(node, field: str) -> np.ndarray | None:
    """A matrix node (``!!opencv-matrix`` with rows, cols, data), checked before OpenCV reads it; None when absent.

    Raises:
        CalibrationError: (field: ``field``) not a matrix, rows / cols not small positive integers,
            data not ``rows * cols`` numbers, or OpenCV cannot read it.
    """
    import cv2

    if node.empty():
        return None
    what = "an OpenCV matrix (!!opencv-matrix with rows, cols, dt, data)"
    if not node.isMap():
        raise CalibrationError(field, f"expected {what}, got {_node_kind(node)}")
    sizes = node.getNode("sizes")  # !!opencv-nd-matrix (what FileStorage writes for a 1-D array)
    if sizes.isSeq():
        dims = [(f"sizes[{i}]", sizes.at(i)) for i in range(min(sizes.size(), 3))]
        if not 1 <= sizes.size() <= 2:
            raise CalibrationError(field, f"sizes: expected 1 or 2 sizes, got {_node_kind(sizes)}")
    else:
        dims = [(key, node.getNode(key)) for key in ("rows", "cols")]
    shape = []
    for key, n in dims:
        if not n.isInt() or not 1 <= n.real() <= _MAX_MATRIX_SIZE:
            raise CalibrationError(field, f"{key}: expected an integer from 1 to {_MAX_MATRIX_SIZE}, got {_node_kind(n)}")
        shape.append(int(n.real()))
    count = int(np.prod(shape))
    data = node.getNode("data")
    if not data.isSeq() or data.size() != count:
        raise CalibrationError(field, f"data: expected {' x '.join(map(str, shape))} = {count} numbers, "
                               f"got {_node_kind(data)}")
    if node.getNode("dt").empty():
        raise CalibrationError(field, f"expected {what}, got a map without 'dt'")
    try:
        matrix = node.mat()
    except cv2.error as exc:
        raise CalibrationError(field, f"expected {what}, OpenCV cannot read it ({_one_line(exc)})") from None
    if matrix is None:
        raise CalibrationError(field, f"expected {what}, got one OpenCV cannot read")
    return np.asarray(matrix, dtype=float)


def _read_size(node, field: str) -> int:
    """An image side (a positive integer of pixels) from a FileStorage node."""
    value = node.real() if (node.isInt() or node.isReal()) else None
    if value is None or not np.isfinite(value) or value != int(value) or not 0 < value <= _MAX_IMAGE_SIDE:
        raise CalibrationError(field, f"expected a positive integer of pixels (at most {_MAX_IMAGE_SIDE}), "
                               f"got {_node_kind(node)}")
    return int(value)


# ================================================================ ROS CameraInfo YAML
def _read_ros(where: str, content: bytes) -> Calibration:
    """ROS ``sensor_msgs/CameraInfo`` YAML (camera_calibration's ``ost.yaml``, camera_info_manager)."""
    data = _parse_yaml(_text(content, where), where)
    if not isinstance(data, dict):
        raise CalibrationError(where, f"expected a YAML mapping (ROS camera_info), got {_kind(data)}")
    if "camera_matrix" not in data:
        raise CalibrationError(f"{where}:camera_matrix", "missing")
    K = _ros_matrix(data["camera_matrix"], f"{where}:camera_matrix", (3, 3))
    model = "pinhole"
    if data.get("distortion_model") is not None:
        value = data["distortion_model"]
        if not isinstance(value, str):
            raise CalibrationError(f"{where}:distortion_model", f"expected a string, got {_kind(value)}")
        model = _lens_model(value, f"{where}:distortion_model", _ROS_MODELS)
    dist = None
    if data.get("distortion_coefficients") is not None:
        dist = _ros_matrix(data["distortion_coefficients"], f"{where}:distortion_coefficients", None).ravel()
        dist = dist if dist.size else None  # D = [] (no distortion)
        named = data.get("distortion_model")
        if dist is not None and named in _ROS_SIZES and dist.size not in _ROS_SIZES[named]:
            raise CalibrationError(f"{where}:distortion_coefficients", f"expected {' or '.join(map(str, _ROS_SIZES[named]))} "
                                   f"coefficients for distortion_model {named}, got {dist.size}")
    for key, shape in (("rectification_matrix", (3, 3)), ("projection_matrix", (3, 4))):
        if data.get(key) is not None:  # of the rectified image; checked, not used (vfactor works on raw pixels)
            _ros_matrix(data[key], f"{where}:{key}", shape)
    image_size = None
    if data.get("image_width") is not None or data.get("image_height") is not None:
        image_size = (_yaml_size(data.get("image_width"), f"{where}:image_width"),
                      _yaml_size(data.get("image_height"), f"{where}:image_height"))
    name = data.get("camera_name")
    if name is not None and not isinstance(name, str):
        raise CalibrationError(f"{where}:camera_name", f"expected a string, got {_kind(name)}")
    return _checked(where, "ros", K, dist, model, None, image_size, name or None,
                    {"K": "camera_matrix", "dist": "distortion_coefficients", "model": "distortion_model",
                     "image_size": "image_width"})


def _ros_matrix(value, field: str, shape: tuple[int, int] | None) -> np.ndarray:
    """A ROS ``{rows, cols, data}`` matrix, sizes checked first; ``shape`` None: any small one (distortion)."""
    if not isinstance(value, dict):
        raise CalibrationError(field, f"expected a mapping with rows, cols, data, got {_kind(value)}")
    unknown = [str(k) for k in value if k not in ("rows", "cols", "data")]
    if unknown:
        raise CalibrationError(field, f"unknown key {unknown[0][:40]!r}; known keys: rows, cols, data")
    dims = []
    for key in ("rows", "cols"):
        n = value.get(key)
        lowest = 0 if shape is None else 1
        if not _is_int(n) or not lowest <= n <= _MAX_MATRIX_SIZE:
            raise CalibrationError(field, f"{key}: expected an integer from {lowest} to {_MAX_MATRIX_SIZE}, got {_kind(n)}")
        dims.append(int(n))
    if shape is not None and tuple(dims) != shape:
        raise CalibrationError(field, f"expected a {shape[0]}x{shape[1]} matrix, got rows: {dims[0]}, cols: {dims[1]}")
    count = dims[0] * dims[1]
    data = value.get("data")
    if not isinstance(data, list) or len(data) != count:
        raise CalibrationError(field, f"data: expected {dims[0]} x {dims[1]} = {count} numbers, got {_kind(data)}")
    return _numbers(data, f"{field}", "data").reshape(dims)


# ================================================================ Kalibr camchain YAML
def _read_kalibr(where: str, content: bytes, chain_camera: str | None) -> Calibration:
    """Kalibr ``camchain.yaml`` / ``camchain-imucam.yaml``: one camera of the chain (pinhole model)."""
    data = _parse_yaml(_text(content, where), where)
    if not isinstance(data, dict) or not data:
        raise CalibrationError(where, f"expected a YAML mapping of cameras (cam0, cam1, ...), got {_kind(data)}")
    keys = [str(k) for k in data]
    if chain_camera is None:
        if len(data) != 1:
            raise CalibrationError(where, f"the camchain holds {len(data)} cameras ({', '.join(keys)}): say which "
                                          "(chain_camera)")
        key = next(iter(data))
    elif chain_camera in data:
        key = chain_camera
    else:
        raise CalibrationError(f"{where}:{chain_camera}", f"no such camera in the camchain; it holds {', '.join(keys)}")
    entry = data[key]
    node = f"{where}:{key}"
    if not isinstance(entry, dict):
        raise CalibrationError(node, f"expected a mapping (camera_model, intrinsics, ...), got {_kind(entry)}")
    camera_model = entry.get("camera_model", "pinhole")
    if camera_model != "pinhole":
        raise CalibrationError(f"{node}.camera_model", f"expected 'pinhole' (the one Kalibr projection vfactor has), "
                                                       f"got {_kind(camera_model)}")
    if "intrinsics" not in entry:
        raise CalibrationError(f"{node}.intrinsics", "missing")
    intrinsics = entry["intrinsics"]
    if not isinstance(intrinsics, list) or len(intrinsics) != 4:
        raise CalibrationError(f"{node}.intrinsics", f"expected [fu, fv, pu, pv] (pixels), got {_kind(intrinsics)}")
    fu, fv, pu, pv = _numbers(intrinsics, f"{node}.intrinsics")
    K = np.array([[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]])
    value = entry.get("distortion_model", "none")
    if not isinstance(value, str):
        raise CalibrationError(f"{node}.distortion_model", f"expected a string, got {_kind(value)}")
    model = _lens_model(value, f"{node}.distortion_model", _KALIBR_MODELS)
    dist = None
    coeffs = entry.get("distortion_coeffs")
    if value == "none":
        if coeffs not in (None, []) and np.any(_numbers(_list(coeffs, f"{node}.distortion_coeffs"),
                                                        f"{node}.distortion_coeffs")):
            raise CalibrationError(f"{node}.distortion_coeffs", "non-zero coefficients with distortion_model none")
    else:
        if coeffs is None:
            raise CalibrationError(f"{node}.distortion_coeffs", f"missing (required by distortion_model {value})")
        dist = _numbers(_list(coeffs, f"{node}.distortion_coeffs"), f"{node}.distortion_coeffs")
        if dist.size != 4:
            names = "[k1, k2, r1, r2]" if value == "radtan" else "[k1, k2, k3, k4]"
            raise CalibrationError(f"{node}.distortion_coeffs", f"expected 4 numbers {names} ({value}), got {dist.size}")
    image_size = None
    if entry.get("resolution") is not None:
        resolution = _list(entry["resolution"], f"{node}.resolution")
        if len(resolution) != 2:
            raise CalibrationError(f"{node}.resolution", f"expected [width, height] (pixels), got {_kind(resolution)}")
        image_size = tuple(_yaml_size(v, f"{node}.resolution") for v in resolution)
    for rel in ("T_cn_cnm1", "T_cam_imu"):  # relative poses: checked, not used (docs/calibration.md)
        if entry.get(rel) is not None:
            matrix = _list(entry[rel], f"{node}.{rel}")
            if len(matrix) != 4 or not all(isinstance(row, list) and len(row) == 4 for row in matrix):
                raise CalibrationError(f"{node}.{rel}", f"expected a 4x4 matrix (4 rows of 4), got {_kind(matrix)}")
            check_rigid_transform(np.array([_numbers(row, f"{node}.{rel}") for row in matrix]), f"{node}.{rel}")
    return _checked(where, "kalibr", K, dist, model, None, image_size, str(key),
                    {"K": f"{key}.intrinsics", "dist": f"{key}.distortion_coeffs", "model": f"{key}.distortion_model",
                     "image_size": f"{key}.resolution"})


def kalibr_cameras(path) -> list[str]:
    """The camera keys of a Kalibr camchain (``["cam0", "cam1"]``), in file order.

    Raises:
        CalibrationError: (field: the file) unreadable, or not a mapping.
    """
    where = str(path)
    data = _parse_yaml(_text(_read_bytes(Path(path), where), where), where)
    if not isinstance(data, dict) or not data:
        raise CalibrationError(where, f"expected a YAML mapping of cameras (cam0, cam1, ...), got {_kind(data)}")
    return [str(k) for k in data]


# ================================================================ projection matrices
def _read_projection(where: str, content: bytes) -> Calibration:
    """A 3x4 projection matrix ``P = K [R | t]`` (world -> pixels): ``.npy``, JSON or text."""
    image_size = None
    if content.startswith(b"\x93NUMPY"):
        import io

        try:
            array = np.load(io.BytesIO(content), allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise CalibrationError(where, f"not a readable .npy array ({_one_line(exc)})") from None
        if not isinstance(array, np.ndarray) or array.shape != (3, 4) or not np.issubdtype(array.dtype, np.number):
            raise CalibrationError(f"{where}:P", f"expected a 3x4 numeric array, got shape {np.shape(array)}")
        P = np.asarray(array, dtype=float)
    else:
        text = _text(content, where).lstrip("\ufeff \t\r\n")
        if text.startswith(("{", "[")):
            data = _parse_json(text, where)
            if isinstance(data, dict):
                unknown = [k for k in data if k not in ("P", "image_size")]
                if unknown:
                    raise CalibrationError(f"{where}:{unknown[0][:40]}", "unknown key; known keys: P, image_size")
                if "P" not in data:
                    raise CalibrationError(f"{where}:P", "missing")
                if data.get("image_size") is not None:
                    size = _list(data["image_size"], f"{where}:image_size")
                    if len(size) != 2:
                        raise CalibrationError(f"{where}:image_size", f"expected [width, height], got {_kind(size)}")
                    image_size = tuple(_yaml_size(v, f"{where}:image_size") for v in size)
                data = data["P"]
            rows = _list(data, f"{where}:P")
            if len(rows) != 3 or not all(isinstance(r, list) and len(r) == 4 for r in rows):
                raise CalibrationError(f"{where}:P", f"expected a 3x4 matrix (3 rows of 4 numbers), got {_kind(rows)}")
            P = np.array([_numbers(r, f"{where}:P") for r in rows])
        else:
            rows = _plain_numbers(text)
            if rows is None or len(rows) != 3 or any(len(r) != 4 for r in rows):
                found = "text that is not numbers" if rows is None else f"{len(rows)} rows of {[len(r) for r in rows]}"
                raise CalibrationError(f"{where}:P", f"expected 3 lines of 4 numbers (P = K [R | t]), got {found}")
            P = np.array(rows, dtype=float)
    if not np.all(np.isfinite(P)):
        raise CalibrationError(f"{where}:P", "contains NaN or infinite entries")
    try:
        K, camera_T_world = decompose_projection_matrix(P)
    except CalibrationError as exc:
        raise CalibrationError(f"{where}:P", exc.problem) from None
    return _checked(where, "projection", K, None, "pinhole", np.linalg.inv(camera_T_world), image_size, None,
                    {"K": "P", "world_T_camera": "P", "image_size": "image_size"})


def decompose_projection_matrix(P) -> tuple[np.ndarray, np.ndarray]:
    """Splits ``P = s K [R | t]`` (any non-zero scale ``s``, either sign) into ``K`` and ``camera_T_world``.

    RQ decomposition of ``P[:, :3]`` with the signs fixed so that ``K`` has positive focal
    lengths and ``K[2, 2] = 1``, and ``R`` is a rotation (det +1): the camera looks along
    +z at the points ``P`` projects with a positive third coordinate.

    Args:
        P: (3, 4) projection matrix, world -> homogeneous pixels.

    Returns:
        (K (3, 3) pixels, camera_T_world (4, 4) world -> camera, metres).

    Raises:
        CalibrationError: (field: ``P``) wrong shape, non-finite, or ``P[:, :3]`` singular.
    """
    from scipy.linalg import rq

    P = np.asarray(P, dtype=float)
    if P.shape != (3, 4) or not np.all(np.isfinite(P)):
        raise CalibrationError("P", f"expected a finite 3x4 matrix, got shape {P.shape}")
    M = P[:, :3]
    scale = np.abs(M).max()
    if not scale > 0 or abs(np.linalg.det(M / scale)) < 1e-12:
        raise CalibrationError("P", "singular: its left 3x3 block has no inverse (not a finite camera)")
    if np.linalg.det(M) < 0:  # P is homogeneous: -P is the same camera
        P = -P
        M = P[:, :3]
    K, R = rq(M)
    signs = np.sign(np.diag(K))
    K, R = K * signs, signs[:, None] * R  # K D, D R with D = diag(signs), D^2 = I
    t = np.linalg.solve(K, P[:, 3])
    K = K / K[2, 2]
    K[1, 0] = K[2, 0] = K[2, 1] = 0.0
    u, _, vt = np.linalg.svd(R)
    camera_T_world = np.eye(4)
    camera_T_world[:3, :3] = u @ vt
    camera_T_world[:3, 3] = t
    return K, camera_T_world


# ================================================================ shared helpers
def _checked(where, format, K, dist, model, world_T_camera, image_size, file_name, nodes) -> Calibration:
    """A :class:`Calibration` with every value checked now (errors name the file's node)."""
    try:
        K = _check_K(K)
        dist = _check_dist(dist, model)
    except CalibrationError as exc:
        raise CalibrationError(f"{where}:{nodes.get(exc.field, exc.field)}", exc.problem) from None
    if world_T_camera is not None:
        world_T_camera = check_rigid_transform(world_T_camera, f"{where}:{nodes.get('world_T_camera')}")
    for a in (K, dist) + (() if world_T_camera is None else (world_T_camera,)):
        a.setflags(write=False)
    return Calibration(where, format, K, dist, model, world_T_camera, image_size, file_name, dict(nodes))


def _lens_model(value: str, field: str, names: dict) -> str:
    if value not in names:
        raise CalibrationError(field, f"expected one of {', '.join(names)}, got {_kind(value)}")
    return names[value]


def _read_bytes(path: Path, where: str) -> bytes:
    if not path.is_file():
        raise CalibrationError(where, not_a_file(path))
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise CalibrationError(where, f"too large for a calibration file ({size} bytes; at most {MAX_FILE_BYTES})")
        with path.open("rb") as f:
            return f.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise CalibrationError(where, f"could not read the file ({_one_line(exc)})") from None


def _text(content: bytes, where: str) -> str:
    try:
        return content.decode("utf-8")
    except UnicodeDecodeError:
        raise CalibrationError(where, "not a text file (not UTF-8)") from None


_YAML_LOADER = None


def _yaml_loader():
    """PyYAML's safe loader, reading ``1e-05`` as the number it is (YAML 1.2; 1.1 wants ``1.0e-05``)."""
    global _YAML_LOADER
    if _YAML_LOADER is None:
        import yaml

        class Loader(yaml.SafeLoader):
            pass

        Loader.add_implicit_resolver("tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
                                     list("-+0123456789"))
        _YAML_LOADER = Loader
    return _YAML_LOADER


def _parse_yaml(text: str, where: str):
    """YAML (safe: plain data only) with parse errors as one-line CalibrationErrors."""
    import yaml

    try:
        return yaml.load(text, Loader=_yaml_loader())  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise CalibrationError(where, f"not valid YAML: {_one_line(exc.problem or exc.context or 'parse error')}{at}") from None
    except (yaml.YAMLError, RecursionError, ValueError, OverflowError) as exc:
        raise CalibrationError(where, f"not valid YAML ({_one_line(exc)})") from None


def _parse_json(text: str, where: str):
    from vfactor.jsonio import parse_json

    return parse_json(text, where, CalibrationError)


def _plain_numbers(text: str) -> list[list[float]] | None:
    """Lines of numbers (whitespace or commas between them, ``#`` comments); None when any token is not one."""
    rows = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        try:
            rows.append([float(tok) for tok in re.split(r"[\s,;]+", line.strip(",; ")) if tok])
        except ValueError:
            return None
    return rows or None








def _list(value, field: str) -> list:
    if not isinstance(value, list):
        raise CalibrationError(field, f"expected a list, got {_kind(value)}")
    return value


def _numbers(values, field: str, what: str = "") -> np.ndarray:
    """Finite numbers (not bools or strings) as a float array."""
    prefix = f"{what}: " if what else ""
    out = np.empty(len(values))
    for k, item in enumerate(values):
        if not _is_number(item) or not math.isfinite(float(item)):
            found = repr(float(item)) if _is_number(item) else _kind(item)  # YAML's .nan / .inf read as Python's
            raise CalibrationError(field, f"{prefix}expected finite numbers, got {found} at [{k}]")
        out[k] = float(item)
    return out


def _yaml_size(value, field: str) -> int:
    if not _is_int(value) or not 0 < value <= _MAX_IMAGE_SIDE:
        raise CalibrationError(field, f"expected a positive integer of pixels (at most {_MAX_IMAGE_SIDE}), got "
                                      f"{_kind(value)}")
    return int(value)


def _one_line(exc) -> str:
    """An exception's (or OpenCV error's, ``err``: without its source location) message through
    :func:`vfactor.sanity.one_line`, at most 200 characters."""
    from vfactor.sanity import one_line

    return one_line(getattr(exc, "err", None) or str(exc), limit=200) or "parse error"


