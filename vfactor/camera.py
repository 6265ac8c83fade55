"""Calibrated pinhole cameras with OpenCV distortion, and their projection.

Conventions (docs/conventions.md): the camera frame is OpenCV's (x right, y down,
z forward); ``world_T_camera`` maps camera points to world points; pixels are
``(u, v)`` with the origin at the centre of the top-left pixel; distortion is
OpenCV's ``[k1, k2, p1, p2(, k3)]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import gtsam
import numpy as np

from vfactor.errors import CalibrationError

__all__ = ["Camera", "as_pose3", "check_rigid_transform", "project_pinhole"]

_ROTATION_TOL = 1e-4


def check_rigid_transform(matrix, field_name: str) -> np.ndarray:
    """Validates a 4x4 rigid transform and returns it as a float array.

    Args:
        matrix: array-like 4x4 (rotation with det +1, last row ``[0, 0, 0, 1]``).
        field_name: field path named in the error.

    Raises:
        CalibrationError: wrong shape, non-finite entries, a rotation that is not
            orthonormal with determinant +1, or a wrong last row.
    """
    try:
        T = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationError(field_name, "expected a 4x4 matrix of numbers") from None
    if T.shape != (4, 4):
        raise CalibrationError(field_name, f"expected shape (4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise CalibrationError(field_name, "contains NaN or infinite entries")
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        raise CalibrationError(field_name, f"last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    R = T[:3, :3]
    orth = np.abs(R.T @ R - np.eye(3)).max()
    if orth > _ROTATION_TOL or np.linalg.det(R) < 0:
        raise CalibrationError(
            field_name, f"rotation part is not a rotation (|R^T R - I| = {orth:.2g}, det = {np.linalg.det(R):.3f})"
        )
    return T


def as_pose3(matrix) -> gtsam.Pose3:
    """Returns a ``gtsam.Pose3`` from a 4x4 rigid transform (re-orthonormalised)."""
    T = np.asarray(matrix, dtype=float)
    u, _, vt = np.linalg.svd(T[:3, :3])
    return gtsam.Pose3(gtsam.Rot3(u @ vt), T[:3, 3].copy())


@dataclass(frozen=True)
class Camera:
    """A fixed, calibrated camera.

    Attributes:
        name: unique camera name, as used by detections in scene files.
        K: 3x3 intrinsic matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` (pixels).
        world_T_camera: 4x4 pose of the camera in the world (camera -> world), metres.
        dist: OpenCV distortion ``[k1, k2, p1, p2, k3]`` (5 entries; zeros when none).
        image_size: ``(width, height)`` in pixels, or ``None`` when unknown.
    """

    name: str
    K: np.ndarray
    world_T_camera: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    image_size: tuple[int, int] | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise CalibrationError("name", f"expected a non-empty string, got {self.name!r}")
        object.__setattr__(self, "K", _check_K(self.K))
        object.__setattr__(self, "world_T_camera", check_rigid_transform(self.world_T_camera, "world_T_camera"))
        object.__setattr__(self, "dist", _check_dist(self.dist))
        if self.image_size is not None:
            size = self.image_size
            if (
                not isinstance(size, (list, tuple))
                or len(size) != 2
                or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s > 0 for s in size)
            ):
                raise CalibrationError("image_size", f"expected [width, height] as two positive integers, got {size!r}")
            object.__setattr__(self, "image_size", (int(size[0]), int(size[1])))
        for name in ("K", "world_T_camera", "dist"):
            getattr(self, name).setflags(write=False)
        camera_T_world = np.linalg.inv(self.world_T_camera)
        camera_T_world.setflags(write=False)
        object.__setattr__(self, "_camera_T_world", camera_T_world)

    # ------------------------------------------------------------------ frames
    @property
    def camera_T_world(self) -> np.ndarray:
        """4x4 transform world -> camera."""
        return self._camera_T_world

    @property
    def pose(self) -> gtsam.Pose3:
        """``world_T_camera`` as a ``gtsam.Pose3``."""
        return as_pose3(self.world_T_camera)

    @property
    def center(self) -> np.ndarray:
        """Camera centre in the world frame (metres), shape (3,)."""
        return self.world_T_camera[:3, 3].copy()

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0))

    def to_camera(self, world_p: np.ndarray) -> np.ndarray:
        """Maps world points (N, 3) to the camera frame (N, 3)."""
        world_p = np.asarray(world_p, dtype=float)
        return world_p @ self._camera_T_world[:3, :3].T + self._camera_T_world[:3, 3]

    # -------------------------------------------------------------- projection
    def project(self, world_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Projects world points into the image.

        Args:
            world_p: (N, 3) points in the world frame, metres.

        Returns:
            uv: (N, 2) pixels ``(u, v)``; meaningless where ``depth <= 0``.
            depth: (N,) z of each point in the camera frame, metres.
        """
        camera_p = self.to_camera(world_p)
        uv, _ = self.project_camera_points(camera_p, jacobian=False)
        return uv, camera_p[:, 2]

    def project_camera_points(self, camera_p: np.ndarray, jacobian: bool = True):
        """Projects camera-frame points, with the Jacobian of the pixels.

        Args:
            camera_p: (N, 3) points in the camera frame (z forward), metres.
            jacobian: whether to compute ``d uv / d camera_p``.

        Returns:
            uv: (N, 2) pixels.
            J: (N, 2, 3) Jacobian of ``uv`` with respect to ``camera_p``
            (pixels per metre), or ``None`` when ``jacobian`` is False.
        """
        return project_pinhole(camera_p, self.K[0, 0], self.K[1, 1], self.K[0, 1], self.K[0, 2], self.K[1, 2],
                               self.dist if self.has_distortion else None, jacobian)

    def undistort_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Returns normalised image coordinates ``(x, y)`` (z = 1) of pixels (N, 2)."""
        import cv2

        uv = np.asarray(uv, dtype=float).reshape(-1, 1, 2)
        return cv2.undistortPoints(uv, self.K, self.dist).reshape(-1, 2)

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Boolean mask of pixels inside the image (all True when the size is unknown)."""
        uv = np.asarray(uv, dtype=float)
        if self.image_size is None:
            return np.ones(len(uv), dtype=bool)
        w, h = self.image_size
        return (uv[:, 0] >= -0.5 - margin) & (uv[:, 0] <= w - 0.5 + margin) & (uv[:, 1] >= -0.5 - margin) & (
            uv[:, 1] <= h - 0.5 + margin
        )

    # ------------------------------------------------------------- file I/O
    def to_dict(self) -> dict:
        """The camera as a scene-file entry (see docs/scene-format.md)."""
        out = {
            "name": self.name,
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "world_T_camera": self.world_T_camera.tolist(),
        }
        if self.image_size is not None:
            out["image_size"] = list(self.image_size)
        return out

    @classmethod
    def from_opencv_file(cls, path: str | Path, name: str | None = None) -> "Camera":
        """Loads a camera from an OpenCV ``cv2.FileStorage`` calibration (YAML or XML).

        The file must hold ``camera_matrix`` (3x3) and may hold
        ``distortion_coefficients`` (4 or 5 entries) and ``image_width`` /
        ``image_height``. The extrinsic is read from ``world_T_camera`` (4x4,
        camera -> world), or from ``camera_T_world`` (4x4), or from OpenCV's
        ``rvec`` / ``tvec`` (world -> camera, as ``cv2.solvePnP`` returns them).

        Args:
            path: the calibration file.
            name: camera name; defaults to the file's ``camera_name`` node or its stem.

        Raises:
            CalibrationError: the file is unreadable or a node is missing or invalid;
                the field names the file and the node.
        """
        import cv2

        path = Path(path)
        where = str(path)
        if not path.is_file():
            raise CalibrationError(where, "file not found")
        try:
            fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        except (cv2.error, SystemError) as exc:  # OpenCV 5 wraps parse errors in SystemError
            detail = getattr(exc, "err", None) or getattr(exc.__cause__, "err", None) or "parse error"
            raise CalibrationError(where, f"not a readable OpenCV FileStorage file ({detail})") from None
        if not fs.isOpened():
            raise CalibrationError(where, "not a readable OpenCV FileStorage file")
        try:

            def mat(node_name):
                return _read_matrix(fs.getNode(node_name), f"{where}:{node_name}")

            K = mat("camera_matrix")
            if K is None:
                raise CalibrationError(f"{where}:camera_matrix", "missing")
            dist = mat("distortion_coefficients")
            dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=float).ravel()
            if name is None:
                node = fs.getNode("camera_name")
                if not node.empty() and not node.isString():
                    raise CalibrationError(f"{where}:camera_name", f"expected a string, got {_node_kind(node)}")
                name = node.string() if not node.empty() and node.string() else path.stem
            width, height = fs.getNode("image_width"), fs.getNode("image_height")
            image_size = None
            if not width.empty() and not height.empty():
                image_size = (_read_size(width, f"{where}:image_width"), _read_size(height, f"{where}:image_height"))
            world_T_camera = mat("world_T_camera")
            if world_T_camera is None:
                camera_T_world = mat("camera_T_world")
                if camera_T_world is not None:
                    check_rigid_transform(camera_T_world, f"{where}:camera_T_world")
                    world_T_camera = np.linalg.inv(camera_T_world)
                else:
                    rvec, tvec = mat("rvec"), mat("tvec")
                    if rvec is None or tvec is None:
                        raise CalibrationError(
                            f"{where}:world_T_camera", "missing extrinsic: give world_T_camera, camera_T_world or rvec+tvec"
                        )
                    rvec, tvec = np.asarray(rvec, float).ravel(), np.asarray(tvec, float).ravel()
                    if rvec.size != 3 or tvec.size != 3:
                        raise CalibrationError(f"{where}:rvec", "rvec and tvec must have 3 entries each")
                    camera_T_world = np.eye(4)
                    camera_T_world[:3, :3] = cv2.Rodrigues(rvec)[0]
                    camera_T_world[:3, 3] = tvec
                    world_T_camera = np.linalg.inv(camera_T_world)
        finally:
            fs.release()
        try:
            return cls(name=name, K=K, world_T_camera=world_T_camera, dist=dist, image_size=image_size)
        except CalibrationError as exc:
            raise CalibrationError(f"{where}:{exc.field}", exc.problem) from None

    def to_opencv_file(self, path: str | Path) -> None:
        """Writes the camera as an OpenCV ``FileStorage`` file (``.yaml`` or ``.xml``)."""
        import cv2

        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write("camera_name", self.name)
        if self.image_size is not None:
            fs.write("image_width", self.image_size[0])
            fs.write("image_height", self.image_size[1])
        fs.write("camera_matrix", np.asarray(self.K))
        fs.write("distortion_coefficients", np.asarray(self.dist).reshape(1, -1))
        fs.write("world_T_camera", np.asarray(self.world_T_camera))
        fs.release()


#: Largest rows / cols of a matrix node read from a calibration file (a 4x4 transform is the largest
#: vfactor reads); checked before OpenCV reads the data, as ``rows: 100000`` makes it allocate gigabytes.
_MAX_MATRIX_SIZE = 16
#: Largest image side accepted, pixels.
_MAX_IMAGE_SIDE = 1 << 20


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
    try:
        matrix = node.mat()
    except cv2.error as exc:
        detail = _cv_message(exc)
        raise CalibrationError(field, f"expected {what}, OpenCV cannot read it ({detail})") from None
    if matrix is None:
        raise CalibrationError(field, f"expected {what}, got one OpenCV cannot read")
    return np.asarray(matrix, dtype=float)


def _cv_message(exc) -> str:
    """The message of a ``cv2.error`` without its source location, one line."""
    text = getattr(exc, "err", None) or str(exc)
    return " ".join(str(text).split())[:200] or "parse error"


def _read_size(node, field: str) -> int:
    """An image side (a positive integer of pixels) from a FileStorage node."""
    value = node.real() if (node.isInt() or node.isReal()) else None
    if value is None or not np.isfinite(value) or value != int(value) or not 0 < value <= _MAX_IMAGE_SIDE:
        raise CalibrationError(field, f"expected a positive integer of pixels (at most {_MAX_IMAGE_SIDE}), "
                               f"got {_node_kind(node)}")
    return int(value)


def project_pinhole(camera_p, fx, fy, skew, cx, cy, dist=None, jacobian: bool = True):
    """Pinhole projection with OpenCV distortion, and its Jacobian; parameters broadcast per point.

    ``x = X / Z, y = Y / Z``; ``r2 = x^2 + y^2``;
    ``xd = x (1 + k1 r2 + k2 r2^2 + k3 r2^3) + 2 p1 x y + p2 (r2 + 2 x^2)``,
    ``yd = y (1 + ...) + p1 (r2 + 2 y^2) + 2 p2 x y``; ``u = fx xd + skew yd + cx``, ``v = fy yd + cy``.

    Args:
        camera_p: (N, 3) points in the camera frame, metres (z > 0).
        fx, fy, skew, cx, cy: intrinsics, scalars or (N,) arrays (pixels).
        dist: None, or ``[k1, k2, p1, p2, k3]`` as (5,) or (N, 5).
        jacobian: whether to return ``d uv / d camera_p``.

    Returns:
        uv (N, 2) pixels and J (N, 2, 3) pixels per metre (None when not asked).
    """
    X, Y, Z = camera_p[:, 0], camera_p[:, 1], camera_p[:, 2]
    inv_z = 1.0 / Z
    x, y = X * inv_z, Y * inv_z
    if dist is not None:
        d = np.asarray(dist)
        k1, k2, p1, p2, k3 = (d[..., i] for i in range(5))
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    else:
        xd, yd = x, y
    uv = np.stack([fx * xd + skew * yd + cx, fy * yd + cy], axis=1)
    if not jacobian:
        return uv, None
    n = len(camera_p)
    if dist is not None:
        dradial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2
        d00 = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x
        d01 = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
        d11 = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x
    else:
        d00, d01, d11 = 1.0, 0.0, 1.0
    # d uv / d(x, y) = [[fx, skew], [0, fy]] @ [[d00, d01], [d01, d11]]
    a00 = fx * d00 + skew * d01
    a01 = fx * d01 + skew * d11
    a10 = fy * d01
    a11 = fy * d11
    J = np.empty((n, 2, 3))
    J[:, 0, 0] = a00 * inv_z
    J[:, 0, 1] = a01 * inv_z
    J[:, 0, 2] = -(a00 * x + a01 * y) * inv_z
    J[:, 1, 0] = a10 * inv_z
    J[:, 1, 1] = a11 * inv_z
    J[:, 1, 2] = -(a10 * x + a11 * y) * inv_z
    return uv, J


def _check_K(K) -> np.ndarray:
    try:
        K = np.array(K, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationError("K", "expected a 3x3 matrix of numbers") from None
    if K.shape != (3, 3):
        raise CalibrationError("K", f"expected shape (3, 3), got {K.shape}")
    if not np.all(np.isfinite(K)):
        raise CalibrationError("K", "contains NaN or infinite entries")
    if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
        raise CalibrationError("K", f"expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CalibrationError("K", f"singular or invalid: focal lengths must be > 0, got fx={K[0, 0]}, fy={K[1, 1]}")
    return K


def _check_dist(dist) -> np.ndarray:
    if dist is None:
        return np.zeros(5)
    try:
        d = np.array(dist, dtype=float).ravel()
    except (TypeError, ValueError):
        raise CalibrationError("dist", "expected 4 or 5 numbers [k1, k2, p1, p2(, k3)]") from None
    if d.size not in (4, 5):
        raise CalibrationError("dist", f"expected 4 or 5 entries [k1, k2, p1, p2(, k3)], got {d.size}")
    if not np.all(np.isfinite(d)):
        raise CalibrationError("dist", "contains NaN or infinite entries")
    return np.concatenate([d, np.zeros(5 - d.size)])
