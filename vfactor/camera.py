"""Calibrated cameras (OpenCV's pinhole and fisheye lens models), and their projection.

Conventions (docs/conventions.md): the camera frame is OpenCV's (x right, y down,
z forward); ``world_T_camera`` maps camera points to world points; pixels are
``(u, v)`` with the origin at the centre of the top-left pixel. Lens models
(``Camera.model``):

* ``"pinhole"``: OpenCV's distortion of ``cv2.projectPoints`` with 4, 5, 8, 12
  or 14 coefficients ``[k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4, tauX, tauY]``
  (radial, rational radial, tangential, thin prism, tilted sensor);
* ``"fisheye"``: OpenCV's equidistant model of ``cv2.fisheye``, ``[k1, k2, k3, k4]``.

:func:`project_pinhole` is the one projection (with its analytic Jacobian) of
every model; the projection factor's compiled kernel computes the same.
Calibration files are read by :mod:`vfactor.calibration`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import gtsam
import numpy as np

from vfactor.errors import CalibrationError

__all__ = ["Camera", "DIST_SIZES", "LENS_FISHEYE", "LENS_FULL", "LENS_MODELS", "LENS_PLAIN", "SAME_PLACE", "as_pose3",
           "check_rigid_transform", "extrinsic_sigma", "moved", "project_pinhole", "tilt_matrix"]

_ROTATION_TOL = 1e-4

#: Lens models of :attr:`Camera.model`.
LENS_MODELS = ("pinhole", "fisheye")
#: Numbers of distortion coefficients each lens model takes (OpenCV's).
DIST_SIZES = {"pinhole": (4, 5, 8, 12, 14), "fisheye": (4,)}
#: Codes of the lens models in the projection kernel's per-observation table (see :meth:`Camera.kernel_lens`).
LENS_PLAIN, LENS_FULL, LENS_FISHEYE = 0, 1, 2
#: Termination of the iterative undistortion (``cv2.undistortPoints``, ``cv2.fisheye.undistortPoints``):
#: normalised units (1e-12 is about 1e-9 px at a 1000 px focal length).
_UNDISTORT_CRITERIA = (3, 50, 1e-12)  # cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS


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


def extrinsic_sigma(rotation_deg, translation_m, field_name: str = "extrinsic_sigma") -> np.ndarray:
    """The (6,) :attr:`Camera.extrinsic_sigma` of a survey's accuracy: rotation (radians) then translation (metres).

    Args:
        rotation_deg: standard deviation of the camera's orientation error about each of its axes, degrees: one
            number for all three, or three (about x, y, z of the camera frame: OpenCV's x right, y down, z forward).
        translation_m: standard deviation of its position error along each axis, metres: one number or three.
        field_name: field path named in the error.

    Raises:
        CalibrationError: not one or three finite numbers >= 0.
    """
    parts = []
    for name, value, unit in (("rotation_deg", rotation_deg, np.pi / 180.0), ("translation_m", translation_m, 1.0)):
        try:
            x = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            x = np.array([np.nan])
        if x.ndim > 1 or x.size not in (1, 3) or not np.all(np.isfinite(x)) or np.any(x < 0):
            raise CalibrationError(f"{field_name}.{name}", f"expected one or three finite numbers >= 0, got {value!r}")
        parts.append(np.broadcast_to(x.ravel() * unit, (3,)))
    return np.concatenate(parts)


#: Largest difference of two ``world_T_camera`` matrices' entries (rotation, metres) at which they are one camera's
#: pose: a rig's cameras in several scene files (the traffic ``vfactor fit-extrinsics`` and ``fit-ground`` pool).
SAME_PLACE = 1e-3


def moved(camera: "Camera", other: "Camera") -> float:
    """The largest difference of the two cameras' ``world_T_camera`` entries (compare with :data:`SAME_PLACE`)."""
    return float(np.abs(np.asarray(camera.world_T_camera) - np.asarray(other.world_T_camera)).max())


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
        dist: distortion coefficients of the lens model (OpenCV's order). ``"pinhole"``:
            5, 8, 12 or 14 entries ``[k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4, tauX, tauY]``
            (4 given are padded with ``k3 = 0``; None: five zeros). ``"fisheye"``: 4 entries
            ``[k1, k2, k3, k4]`` (None: four zeros). Tilt angles ``tauX, tauY`` in radians.
        image_size: ``(width, height)`` in pixels, or ``None`` when unknown.
        model: lens model, one of :data:`LENS_MODELS` (``"pinhole"`` or ``"fisheye"``).
        extrinsic_sigma: how well ``world_T_camera`` is known: (6,) standard deviations of its error as a right
            perturbation (the true pose is ``world_T_camera * Exp(xi)``, GTSAM's ``Pose3`` tangent), rotation about
            the camera's x, y, z axes (radians), then translation along them (metres) (:func:`extrinsic_sigma` from
            degrees and metres); None: taken as exact. The one-frame solve's covariances carry what this error
            gives the estimate (docs/factors.md, "Covariances", item 7).
    """

    name: str
    K: np.ndarray
    world_T_camera: np.ndarray
    dist: np.ndarray | None = None
    image_size: tuple[int, int] | None = None
    model: str = "pinhole"
    extrinsic_sigma: np.ndarray | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise CalibrationError("name", f"expected a non-empty string, got {self.name!r}")
        if not isinstance(self.model, str) or self.model not in LENS_MODELS:
            raise CalibrationError("model", f"expected one of {', '.join(LENS_MODELS)}, got {self.model!r}")
        object.__setattr__(self, "K", _check_K(self.K))
        object.__setattr__(self, "world_T_camera", check_rigid_transform(self.world_T_camera, "world_T_camera"))
        object.__setattr__(self, "dist", _check_dist(self.dist, self.model))
        if self.image_size is not None:
            size = self.image_size
            if (
                not isinstance(size, (list, tuple))
                or len(size) != 2
                or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s > 0 for s in size)
            ):
                raise CalibrationError("image_size", f"expected [width, height] as two positive integers, got {size!r}")
            object.__setattr__(self, "image_size", (int(size[0]), int(size[1])))
        if self.extrinsic_sigma is not None:
            try:
                sigma = np.array(self.extrinsic_sigma, dtype=float)
            except (TypeError, ValueError):
                sigma = np.array([np.nan])
            if sigma.shape != (6,) or not np.all(np.isfinite(sigma)) or np.any(sigma < 0):
                raise CalibrationError("extrinsic_sigma", "expected 6 finite numbers >= 0 (rotation about x, y, z in "
                                       f"radians, translation along them in metres), got {self.extrinsic_sigma!r}")
            sigma.setflags(write=False)
            object.__setattr__(self, "extrinsic_sigma", sigma)
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
        """Whether pixels differ from the ideal pinhole ``K [x, y, 1]`` (always for the fisheye model)."""
        return self.model == "fisheye" or bool(np.any(self.dist != 0))

    def kernel_lens(self) -> tuple[int, np.ndarray]:
        """The lens as the projection kernel takes it: a model code and 14 coefficients.

        Returns:
            (code, (14,) coefficients): :data:`LENS_PLAIN` for a pinhole lens with at most
            ``[k1, k2, p1, p2, k3]`` non-zero (the common, fastest case), :data:`LENS_FULL`
            for one with rational, thin-prism or tilt terms, :data:`LENS_FISHEYE` (the first
            four coefficients ``k1..k4``, the rest zeros).
        """
        d = np.zeros(14)
        d[: self.dist.size] = self.dist
        if self.model == "fisheye":
            return LENS_FISHEYE, d
        return (LENS_FULL if np.any(d[5:] != 0) else LENS_PLAIN), d

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
        fisheye = self.model == "fisheye"
        return project_pinhole(camera_p, self.K[0, 0], self.K[1, 1], self.K[0, 1], self.K[0, 2], self.K[1, 2],
                               self.dist if self.has_distortion else None, jacobian, fisheye=fisheye)

    def normalised_pixels(self, uv: np.ndarray) -> np.ndarray:
        """``K^-1`` applied to pixels (N, 2): the distorted normalised coordinates (no undistortion)."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        fx, s, cx = self.K[0]
        fy, cy = self.K[1, 1], self.K[1, 2]
        y = (uv[:, 1] - cy) / fy
        return np.stack([(uv[:, 0] - cx - s * y) / fx, y], axis=1)

    def undistort_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Returns normalised image coordinates ``(x, y)`` (z = 1) of pixels (N, 2).

        The inverse of the projection (iterative, OpenCV's ``cv2.undistortPoints`` or
        ``cv2.fisheye.undistortPoints``, to 1e-12 in normalised units where it converges);
        the skew of ``K`` is honoured (OpenCV's functions ignore it).
        """
        import cv2

        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        if not len(uv):
            return np.zeros((0, 2))
        if self.model == "pinhole" and self.K[0, 1] == 0:
            return cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, self.dist, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)
        xy = self.normalised_pixels(uv)
        if not self.has_distortion:
            return xy
        undistort = cv2.fisheye.undistortPoints if self.model == "fisheye" else cv2.undistortPoints
        return undistort(xy.reshape(-1, 1, 2), np.eye(3), self.dist, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)

    def pnp_inputs(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, float]:
        """Image points, camera matrix and distortion as ``cv2.solvePnP`` takes them, for this lens.

        A pinhole lens is OpenCV's own: the pixels, ``K`` and ``dist``. ``cv2.solvePnP``
        has no fisheye model, so a fisheye camera's pixels are undistorted to
        normalised coordinates, solved with an identity camera matrix and no distortion.

        Args:
            uv: (N, 2) pixels.

        Returns:
            (points (N, 2), camera matrix (3, 3), distortion or None, pixels per unit of
            the points: multiply a pixel threshold by its inverse).
        """
        uv = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
        if self.model == "fisheye":
            scale = 0.5 * float(self.K[0, 0] + self.K[1, 1])
            return np.ascontiguousarray(self.undistort_pixels(uv)), np.eye(3), None, scale
        return uv, np.asarray(self.K, dtype=np.float64), np.asarray(self.dist, dtype=np.float64), 1.0

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
        """The camera as a scene-file entry, inline (see docs/scene-format.md)."""
        out = {
            "name": self.name,
            "model": self.model,
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "world_T_camera": self.world_T_camera.tolist(),
        }
        if self.image_size is not None:
            out["image_size"] = list(self.image_size)
        if self.extrinsic_sigma is not None:
            out["extrinsic_sigma"] = {"rotation_deg": np.degrees(self.extrinsic_sigma[:3]).tolist(),
                                      "translation_m": self.extrinsic_sigma[3:].tolist()}
        return out

    @classmethod
    def from_opencv_file(cls, path: str | Path, name: str | None = None) -> "Camera":
        """Loads a camera from an OpenCV ``cv2.FileStorage`` calibration (YAML or XML).

        :func:`vfactor.calibration.load_calibration` with ``format="opencv"`` (see
        docs/calibration.md for the nodes read); the file must give its extrinsic.

        Args:
            path: the calibration file.
            name: camera name; defaults to the file's ``camera_name`` node. Never the file's
                name: ``cam0_calib.yml`` would become a camera no detection names.

        Raises:
            CalibrationError: the file is unreadable or a node is missing or invalid;
                the field names the file and the node; no ``name`` and no ``camera_name`` node.
        """
        from vfactor.calibration import read_calibration

        calibration = read_calibration(path, format="opencv")
        if name is None:
            name = calibration.file_camera_name
            if not name:
                raise CalibrationError(f"{path}:camera_name", "missing: the file names no camera; give name=")
        return calibration.camera(name)

    def to_opencv_file(self, path: str | Path) -> None:
        """Writes the camera as an OpenCV ``FileStorage`` file (``.yaml`` or ``.xml``).

        Nodes: ``camera_name``, ``image_width`` / ``image_height`` (when known),
        ``camera_matrix``, ``distortion_model`` (``fisheye`` only), ``distortion_coefficients``,
        ``world_T_camera``.
        """
        import cv2

        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write("camera_name", self.name)
        if self.image_size is not None:
            fs.write("image_width", self.image_size[0])
            fs.write("image_height", self.image_size[1])
        fs.write("camera_matrix", np.asarray(self.K))
        if self.model != "pinhole":
            fs.write("distortion_model", self.model)
        fs.write("distortion_coefficients", np.asarray(self.dist).reshape(1, -1))
        fs.write("world_T_camera", np.asarray(self.world_T_camera))
        fs.release()


def project_pinhole(camera_p, fx, fy, skew, cx, cy, dist=None, jacobian: bool = True, fisheye=False):
    """Projection of every lens model (:data:`LENS_MODELS`), and its Jacobian; parameters broadcast per point.

    ``x = X / Z, y = Y / Z``, then the lens maps ``(x, y)`` to distorted normalised
    coordinates ``(xd, yd)``, and ``u = fx xd + skew yd + cx``, ``v = fy yd + cy``. The lens
    (docs/conventions.md gives the formulas): OpenCV's pinhole distortion
    (``cv2.projectPoints``: radial, rational, tangential, thin prism, tilted sensor) or,
    on ``fisheye`` rows, OpenCV's equidistant model (``cv2.fisheye.projectPoints``).
    Points must lie in front of the camera (callers clamp the depth).

    Args:
        camera_p: (N, 3) points in the camera frame, metres (z > 0).
        fx, fy, skew, cx, cy: intrinsics, scalars or (N,) arrays (pixels).
        dist: None (no distortion: the ideal pinhole), or coefficients as (k,) or (N, k) in
            OpenCV's order. Pinhole rows: k = 5, 8, 12 or 14 ``[k1, k2, p1, p2, k3, k4, k5, k6,
            s1, s2, s3, s4, tauX, tauY]`` (absent terms are zero). Fisheye rows: the first four
            entries ``[k1, k2, k3, k4]`` (further entries are ignored).
        jacobian: whether to return ``d uv / d camera_p``.
        fisheye: whether the points' lens is the fisheye model: a bool, or (N,) bools.

    Returns:
        uv (N, 2) pixels and J (N, 2, 3) pixels per metre (None when not asked).
    """
    X, Y, Z = camera_p[:, 0], camera_p[:, 1], camera_p[:, 2]
    n = len(camera_p)
    inv_z = 1.0 / Z
    x, y = X * inv_z, Y * inv_z
    if fisheye is False:  # the common case, without the per-row checks
        some_fisheye = all_fisheye = False
    else:
        fish = np.broadcast_to(np.asarray(fisheye, dtype=bool), (n,))
        some_fisheye, all_fisheye = bool(fish.any()), bool(fish.all())
    if dist is None and not some_fisheye:
        xd, yd, D = x, y, (1.0, 0.0, 0.0, 1.0)
    else:
        d = np.zeros(5) if dist is None else np.asarray(dist, dtype=float)
        if all_fisheye:
            xd, yd, D = _fisheye_lens(x, y, d, jacobian)
        elif not some_fisheye:
            xd, yd, D = _pinhole_lens(x, y, d, jacobian)
        else:  # cameras of both models: each on its own rows
            rows = np.broadcast_to(d, (n, d.shape[-1]))
            parts = [(fish, _fisheye_lens(x[fish], y[fish], rows[fish], jacobian)),
                     (~fish, _pinhole_lens(x[~fish], y[~fish], rows[~fish], jacobian))]
            xd, yd = np.empty(n), np.empty(n)
            D = tuple(np.empty(n) for _ in range(4)) if jacobian else None
            for mask, (pxd, pyd, pD) in parts:
                xd[mask], yd[mask] = pxd, pyd
                if jacobian:
                    for whole, part in zip(D, pD, strict=True):
                        whole[mask] = part
    uv = np.stack([fx * xd + skew * yd + cx, fy * yd + cy], axis=1)
    if not jacobian:
        return uv, None
    d00, d01, d10, d11 = D
    # d uv / d(x, y) = [[fx, skew], [0, fy]] @ [[d00, d01], [d10, d11]]
    a00 = fx * d00 + skew * d10
    a01 = fx * d01 + skew * d11
    a10 = fy * d10
    a11 = fy * d11
    J = np.empty((n, 2, 3))
    J[:, 0, 0] = a00 * inv_z
    J[:, 0, 1] = a01 * inv_z
    J[:, 0, 2] = -(a00 * x + a01 * y) * inv_z
    J[:, 1, 0] = a10 * inv_z
    J[:, 1, 1] = a11 * inv_z
    J[:, 1, 2] = -(a10 * x + a11 * y) * inv_z
    return uv, J


def tilt_matrix(tau_x, tau_y) -> np.ndarray:
    """OpenCV's tilted-sensor matrix (``cv::detail::computeTiltProjectionMatrix``), shape (..., 3, 3).

    ``R = Ry(tau_y) Rx(tau_x)`` with ``Rx = [[1, 0, 0], [0, cos tx, sin tx], [0, -sin tx, cos tx]]``,
    ``Ry = [[cos ty, 0, -sin ty], [0, 1, 0], [sin ty, 0, cos ty]]``; the matrix is
    ``[[R22, 0, -R02], [0, R22, -R12], [0, 0, 1]] R``, applied to ``(xd, yd, 1)`` before ``K``
    (then divided by the third coordinate).

    Args:
        tau_x, tau_y: tilt angles, radians (scalars or arrays of one shape).
    """
    cx, sx = np.cos(tau_x), np.sin(tau_x)
    cy, sy = np.cos(tau_y), np.sin(tau_y)
    one, zero = np.ones_like(cx), np.zeros_like(cx)
    R = np.stack([np.stack([cy, sy * sx, -sy * cx], -1), np.stack([zero, cx, sx], -1),
                  np.stack([sy, -cy * sx, cy * cx], -1)], -2)
    P = np.stack([np.stack([R[..., 2, 2], zero, -R[..., 0, 2]], -1), np.stack([zero, R[..., 2, 2], -R[..., 1, 2]], -1),
                  np.stack([zero, zero, one], -1)], -2)
    return P @ R


def _pinhole_lens(x, y, d, jacobian):
    """OpenCV's pinhole distortion of normalised ``(x, y)``: ``(xd, yd)`` and ``d(xd, yd)/d(x, y)`` entries.

    ``d``: (k,) or (N, k), k >= 5. The rational, thin-prism and tilt terms are computed only
    when present and non-zero (the 5-coefficient case is the original, fastest formula).
    """
    width = d.shape[-1]
    k1, k2, p1, p2, k3 = (d[..., i] for i in range(5))
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    rational = width >= 8 and bool(np.any(d[..., 5:8] != 0))
    if rational:
        k4, k5, k6 = d[..., 5], d[..., 6], d[..., 7]
        denominator = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        radial = radial / denominator
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    prism = width >= 12 and bool(np.any(d[..., 8:12] != 0))
    if prism:
        s1, s2, s3, s4 = (d[..., i] for i in range(8, 12))
        xd = xd + r2 * (s1 + r2 * s2)
        yd = yd + r2 * (s3 + r2 * s4)
    tilted = width >= 14 and bool(np.any(d[..., 12:14] != 0))
    if tilted:
        M = tilt_matrix(d[..., 12], d[..., 13])
        w = M[..., 2, 0] * xd + M[..., 2, 1] * yd + M[..., 2, 2]
        xt = (M[..., 0, 0] * xd + M[..., 0, 1] * yd + M[..., 0, 2]) / w
        yt = (M[..., 1, 0] * xd + M[..., 1, 1] * yd + M[..., 1, 2]) / w
    if not jacobian:
        return (xt, yt, None) if tilted else (xd, yd, None)
    dradial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2 (of the numerator)
    if rational:
        dradial = (dradial - radial * (k4 + r2 * (2 * k5 + 3 * k6 * r2))) / denominator
    d00 = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x
    d01 = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
    d10 = d01
    d11 = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x
    if prism:
        gx, gy = 2 * (s1 + 2 * s2 * r2), 2 * (s3 + 2 * s4 * r2)
        d00, d01, d10, d11 = d00 + gx * x, d01 + gx * y, d10 + gy * x, d11 + gy * y
    if tilted:  # d(xt, yt)/d(xd, yd) @ the above
        t00, t01 = (M[..., 0, 0] - xt * M[..., 2, 0]) / w, (M[..., 0, 1] - xt * M[..., 2, 1]) / w
        t10, t11 = (M[..., 1, 0] - yt * M[..., 2, 0]) / w, (M[..., 1, 1] - yt * M[..., 2, 1]) / w
        d00, d01, d10, d11 = t00 * d00 + t01 * d10, t00 * d01 + t01 * d11, t10 * d00 + t11 * d10, t10 * d01 + t11 * d11
        return xt, yt, (d00, d01, d10, d11)
    return xd, yd, (d00, d01, d10, d11)


#: Below this squared normalised radius the fisheye scale is its limit 1 (OpenCV: r < 1e-8).
_FISHEYE_MIN_R2 = 1e-16


def _fisheye_lens(x, y, d, jacobian):
    """OpenCV's equidistant fisheye model of normalised ``(x, y)``; ``d``: (k,) or (N, k), k >= 4.

    ``theta = atan(r)``, ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``,
    ``(xd, yd) = (theta_d / r) (x, y)``.
    """
    k1, k2, k3, k4 = (d[..., i] for i in range(4))
    r2 = x * x + y * y
    small = r2 < _FISHEYE_MIN_R2
    r2_safe = np.where(small, 1.0, r2)
    r = np.sqrt(r2_safe)
    theta = np.arctan(r)
    t2 = theta * theta
    g = np.where(small, 1.0, theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) / r)
    xd, yd = g * x, g * y
    if not jacobian:
        return xd, yd, None
    dtheta_d = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))  # d theta_d / d theta
    h = np.where(small, 2 * (k1 - 1.0 / 3.0), (dtheta_d / (1 + r2_safe) - g) / r2_safe)  # (dg/dr) / r
    d01 = h * x * y
    return xd, yd, (g + h * x * x, d01, d01, g + h * y * y)


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


def _check_dist(dist, model: str = "pinhole") -> np.ndarray:
    """The distortion of a lens model as stored: pinhole 4 entries padded to 5; None: zeros (5 or 4)."""
    sizes = DIST_SIZES[model]
    if model == "fisheye":
        expected = "4 numbers [k1, k2, k3, k4] (fisheye model)"
    else:
        expected = "4, 5, 8, 12 or 14 numbers [k1, k2, p1, p2(, k3(, k4, k5, k6(, s1, s2, s3, s4(, tauX, tauY))))]"
    if dist is None:
        return np.zeros(4 if model == "fisheye" else 5)
    try:
        d = np.array(dist, dtype=float).ravel()
    except (TypeError, ValueError):
        raise CalibrationError("dist", f"expected {expected}") from None
    if d.size not in sizes:
        raise CalibrationError("dist", f"expected {expected}, got {d.size} entries")
    if not np.all(np.isfinite(d)):
        raise CalibrationError("dist", "contains NaN or infinite entries")
    if model == "pinhole" and d.size == 4:
        d = np.concatenate([d, [0.0]])
    return d
