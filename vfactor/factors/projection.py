"""Keypoint projection factor: pose and shape against pixels of several cameras.

One factor holds any number of observations ``(camera, keypoint, uv, noise)``
of one vehicle; the graph builder puts all observations of a vehicle in a
frame into one factor, so that a frame costs one Python call per
linearisation instead of one per keypoint, and the factor's residuals and
Jacobians come from one compiled loop (:func:`kernels.projection.projection_kernel`,
compiled ahead of time into :mod:`vfactor._kernels`; see docs/performance.md).
A single observation is simply a factor with one row. :func:`project_keypoints`
is the same projection in NumPy, for initialisation, diagnostics and the tests.

For observation i of keypoint k from camera c (docs/factors.md)::

    world_p   = world_T_vehicle * vehicle_p_k          (vehicle_p_k from its layer key)
    camera_p  = camera_T_world * world_p
    e_i       = L_i (m_i(pi_c(camera_p)) - uv_i)       (L_i: 2x2 square-root information)
    r_i       = s(|e_i|) e_i                           (robust loss per observation)

``m_i`` is the identity, or, for an observation with a ``window`` (the detector
loses keypoints pushed out of the image), the mean of the Gaussian truncated
to it (:mod:`vfactor.factors.truncation`).

Keys: ``[pose, wheel, light, roof]``, and optionally a fifth: a detector's
pose offset ``vehicle_T_seen`` (``gtsam.Pose3``, near the identity), a rigid
motion of the vehicle as these observations see it (``world_p`` becomes
``world_T_vehicle * vehicle_T_seen * vehicle_p_k``): a track gives each
camera's detector its own error that repeats from frame to frame
(docs/factors.md, "The detector's pose offset in tracks").
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import gtsam
import numpy as np

from vfactor._kernels import projection_kernel, robust_cost_kernel
from vfactor.camera import LENS_FISHEYE, LENS_PLAIN, Camera, project_pinhole
from vfactor.factors.robust import RobustLoss
from vfactor.factors.shape_terms import cross
from vfactor.factors.truncation import truncated_means

__all__ = ["KeypointObservations", "projection_factor", "project_keypoints", "whitened_residuals", "extrinsic_jacobian",
           "whitened_pose_jacobian", "whitened_residuals_numpy", "robust_costs"]

_MIN_DEPTH = 0.05  # metres; points closer to (or behind) a camera are clamped to this depth
_EMPTY = np.empty((0, 0))
_NO_LOSS = RobustLoss("none").id


def _largest_singular_value(L: np.ndarray) -> np.ndarray:
    """(n,) the largest singular value of each 2x2 matrix of ``L`` (n, 2, 2), in closed form (``np.linalg.norm(L,
    2, axis=(1, 2))`` takes an SVD of each): ``sqrt((f + sqrt(f^2 - 4 det^2)) / 2)``, ``f`` the squared Frobenius
    norm."""
    f = np.einsum("nij,nij->n", L, L)
    det = L[:, 0, 0] * L[:, 1, 1] - L[:, 0, 1] * L[:, 1, 0]
    return np.sqrt(0.5 * (f + np.sqrt(np.maximum(f * f - 4.0 * det * det, 0.0))))


@dataclass(frozen=True)
class KeypointObservations:
    """Pixel observations of one vehicle's keypoints.

    Attributes:
        cameras: the cameras, indexed by ``camera_index``.
        camera_index: (n,) index of the observing camera.
        keypoint_index: (n,) keypoint index 0..11.
        uv: (n, 2) measured pixels.
        sqrt_information: (n, 2, 2) ``L`` with ``L^T L`` the inverse pixel
            covariance (1/px).
        window: optional (n, 4) ``[u_lo, v_lo, u_hi, v_hi]`` pixel edges of the
            region outside which the detector loses a keypoint (the image:
            ``[-0.5, -0.5, width - 0.5, height - 0.5]``); NaN rows, or None, for
            measurements that are not truncated.
        min_sigma: no pixel sigma goes below this when the observations are
            :meth:`scaled` (``GraphConfig.min_pixel_sigma``), pixels.
        calibrated: optional (n,) bools: the observation's noise is calibrated against the
            detector's true errors (``Detection.covariance_calibrated``), so the covariances of
            the result are computed at no less than it; None: none is.
        shape_sigma: optional (n,) metres: the detector's error shaped like a change of the
            vehicle's shape, of the observation's detection (``Detection.shape_sigma``; 0: none);
            None: no observation has one.
        cut: optional (n,) bools: the observation's detection box (``Detection.roi``) reaches beyond its camera's
            image or stops at its border, so that view of the vehicle is cut by the image border; None: none is.
    """

    cameras: tuple[Camera, ...]
    camera_index: np.ndarray
    keypoint_index: np.ndarray
    uv: np.ndarray
    sqrt_information: np.ndarray
    window: np.ndarray | None = None
    min_sigma: float = 0.0
    calibrated: np.ndarray | None = None
    shape_sigma: np.ndarray | None = None
    cut: np.ndarray | None = None

    def __post_init__(self):
        n = len(self.camera_index)
        if not (len(self.keypoint_index) == len(self.uv) == len(self.sqrt_information) == n):
            raise ValueError("KeypointObservations: camera_index, keypoint_index, uv and sqrt_information differ in length")
        if self.calibrated is not None:
            if np.shape(self.calibrated) != (n,):
                raise ValueError(f"KeypointObservations.calibrated: expected shape ({n},), got {np.shape(self.calibrated)}")
            object.__setattr__(self, "calibrated", np.asarray(self.calibrated, dtype=bool))
        if self.cut is not None:
            if np.shape(self.cut) != (n,):
                raise ValueError(f"KeypointObservations.cut: expected shape ({n},), got {np.shape(self.cut)}")
            object.__setattr__(self, "cut", np.asarray(self.cut, dtype=bool))
        if self.shape_sigma is not None:
            sigma = np.asarray(self.shape_sigma, dtype=float)
            if sigma.shape != (n,) or not np.all(np.isfinite(sigma)) or np.any(sigma < 0):
                raise ValueError(f"KeypointObservations.shape_sigma: expected ({n},) finite metres >= 0")
            object.__setattr__(self, "shape_sigma", sigma)
        if self.window is not None and np.shape(self.window) != (n, 4):
            raise ValueError(f"KeypointObservations.window: expected shape ({n}, 4), got {np.shape(self.window)}")
        # the compiled kernel reads these as they are: int64 keypoints, float64 pixels and information
        keypoint_index = np.asarray(self.keypoint_index)
        if keypoint_index.size and keypoint_index.dtype.kind not in "iu":
            raise ValueError(f"KeypointObservations.keypoint_index: expected integers, got {keypoint_index.dtype}")
        for name, value, shape in (("keypoint_index", np.asarray(keypoint_index, dtype=np.int64), (n,)),
                                   ("uv", np.asarray(self.uv, dtype=float), (n, 2)),
                                   ("sqrt_information", np.asarray(self.sqrt_information, dtype=float), (n, 2, 2))):
            if value.size == 0:
                value = value.reshape(shape)
            if value.shape != shape:
                raise ValueError(f"KeypointObservations.{name}: expected shape {shape}, got {value.shape}")
            object.__setattr__(self, name, np.ascontiguousarray(value))
        # truncation table for the kernel: window (NaN: none) and the marginal pixel sigmas
        window = np.full((n, 4), np.nan) if self.window is None else np.asarray(self.window, dtype=float)
        truncated = np.isfinite(window[:, 0])
        if not np.all(np.isfinite(window[truncated])) or np.any(window[truncated, 2:] <= window[truncated, :2]):
            raise ValueError("KeypointObservations.window: each row must be all NaN or finite with u_lo < u_hi, v_lo < v_hi")
        object.__setattr__(self, "_window_table", np.ascontiguousarray(window).reshape(n, 4))
        sigma = np.ones((n, 2))
        if truncated.any():
            L = np.asarray(self.sqrt_information, dtype=float)[truncated]
            sigma[truncated] = np.sqrt(np.diagonal(np.linalg.inv(np.einsum("nki,nkj->nij", L, L)), axis1=1, axis2=2))
        object.__setattr__(self, "_sigma_table", sigma)
        # per-observation camera parameters, so that projection is one vectorised pass: each camera's once, then
        # taken by the observations' camera index
        index = np.asarray(self.camera_index, dtype=np.int64)
        if n and (index.min() < 0 or index.max() >= len(self.cameras)):
            raise IndexError(f"KeypointObservations.camera_index: expected 0..{len(self.cameras) - 1}")
        camera_T_world = np.array([c.camera_T_world for c in self.cameras]).reshape(-1, 4, 4)
        K = np.array([c.K for c in self.cameras]).reshape(-1, 3, 3)[index]
        object.__setattr__(self, "_R_cw", np.ascontiguousarray(camera_T_world[index, :3, :3]))
        object.__setattr__(self, "_t_cw", np.ascontiguousarray(camera_T_world[index, :3, 3]))
        object.__setattr__(self, "_intrinsics", (K[:, 0, 0], K[:, 1, 1], K[:, 0, 1], K[:, 0, 2], K[:, 1, 2]))
        # the lens of each camera as the kernel takes it: a code and 14 coefficients (Camera.kernel_lens)
        lenses = [c.kernel_lens() for c in self.cameras]
        codes = np.array([code for code, _ in lenses], dtype=np.int64)[index]
        dist_table = np.array([d for _, d in lenses], dtype=float).reshape(-1, 14)[index]
        fisheye = codes == LENS_FISHEYE
        object.__setattr__(self, "_fisheye", fisheye if fisheye.any() else False)
        # NumPy projection: None without distortion; 5 columns for the common lens (the original formula)
        distorted = any(c.has_distortion for c in self.cameras)
        width = 5 if np.all(codes == LENS_PLAIN) else 14
        object.__setattr__(self, "_dist", np.ascontiguousarray(dist_table[:, :width]) if distorted else None)
        # contiguous tables for the compiled kernel of the projection factor
        object.__setattr__(self, "_intrinsics_table", np.ascontiguousarray(np.stack(self._intrinsics, axis=1)).reshape(n, 5))
        object.__setattr__(self, "_lens_table", np.ascontiguousarray(codes).reshape(n))
        object.__setattr__(self, "_dist_table", dist_table)

    def __len__(self):
        return len(self.camera_index)

    def _with(self, **tables) -> "KeypointObservations":
        """A copy holding these tables in place of its own (every other one shared, nothing validated or made
        again): the derived observations below keep the camera tables that ``__post_init__`` built."""
        out = object.__new__(KeypointObservations)
        out.__dict__.update(self.__dict__)
        out.__dict__.update(tables)
        return out

    def subset(self, mask: np.ndarray) -> "KeypointObservations":
        """The observations selected by ``mask`` (booleans or indices), their tables taken from these rather than
        made again."""
        tables = {name: np.ascontiguousarray(getattr(self, name)[mask])
                  for name in ("camera_index", "keypoint_index", "uv", "sqrt_information", "_window_table",
                               "_sigma_table", "_R_cw", "_t_cw", "_intrinsics_table", "_lens_table", "_dist_table")}
        tables.update({name: getattr(self, name)[mask] for name in ("window", "calibrated", "shape_sigma", "cut")
                       if getattr(self, name) is not None})
        tables["_intrinsics"] = tuple(column[mask] for column in self._intrinsics)
        if self._fisheye is not False:
            fisheye = self._fisheye[mask]
            tables["_fisheye"] = fisheye if fisheye.any() else False
        if self._dist is not None:  # the NumPy projection's columns: 5 for the common lens, as __post_init__ picks them
            width = 5 if np.all(tables["_lens_table"] == LENS_PLAIN) else 14
            tables["_dist"] = np.ascontiguousarray(tables["_dist_table"][:, :width])
        return self._with(**tables)

    def relabelled(self, keypoint_index: np.ndarray) -> "KeypointObservations":
        """The same observations under other keypoint labels (n,), every pixel, sigma and table kept with its row."""
        keypoint_index = np.asarray(keypoint_index)
        if keypoint_index.shape != self.keypoint_index.shape or keypoint_index.dtype.kind not in "iu":
            raise ValueError(f"KeypointObservations.relabelled: expected {len(self)} integer labels")
        return self._with(keypoint_index=np.ascontiguousarray(keypoint_index, dtype=np.int64))

    def scaled(self, noise_scale) -> "KeypointObservations":
        """The same observations with every pixel sigma multiplied by ``noise_scale`` (> 0).

        ``noise_scale`` is one factor, or (n,) factors, one per observation.
        An observation whose smallest sigma would fall below :attr:`min_sigma`
        is scaled only down to it (noise-free keypoints would otherwise make
        the information unbounded).
        """
        L = np.asarray(self.sqrt_information, dtype=float)
        try:
            factor = np.array(np.broadcast_to(np.asarray(noise_scale, dtype=float), (len(L),)))
        except ValueError:
            raise ValueError(f"noise_scale: expected a number or {len(L)} numbers, got shape "
                             f"{np.shape(noise_scale)}") from None
        if not np.all(factor > 0):
            raise ValueError(f"noise_scale: expected > 0, got {noise_scale}")
        if self.min_sigma > 0 and len(L):
            smallest_sigma = 1.0 / _largest_singular_value(L)
            factor = np.maximum(factor, self.min_sigma / smallest_sigma)
        # the camera tables stay; only the noise (and the truncation's marginal sigmas) change
        truncated = np.isfinite(self._window_table[:, 0])
        return self._with(sqrt_information=L / factor[:, None, None],
                          _sigma_table=np.where(truncated[:, None], self._sigma_table * factor[:, None], 1.0))

    def camera_scaled(self, factors: dict | None) -> "KeypointObservations":
        """:meth:`scaled` by each camera's factor (camera name -> factor; a camera not named, or None: 1): a noise
        scale per camera (``extras["camera_noise_factors"]`` of a solve)."""
        if not factors:
            return self
        return self.scaled(np.array([factors.get(self.cameras[int(c)].name, 1.0) for c in self.camera_index]))

    def scaled_above_calibrated(self, noise_scale: float) -> "KeypointObservations":
        """:meth:`scaled` by ``noise_scale``, except that a scale below 1 leaves the calibrated observations
        (:attr:`calibrated`: the detector's covariances calibrated against its true errors) at their sigmas: an
        estimated noise scale never narrows a calibrated covariance (docs/factors.md, "Covariances", item 4)."""
        if self.calibrated is None or noise_scale >= 1.0:
            return self.scaled(noise_scale)
        return self.scaled(np.where(self.calibrated, 1.0, noise_scale))

    def with_min_sigma(self, min_sigma: float) -> "KeypointObservations":
        """The same observations with another :attr:`min_sigma` (the sigmas themselves unchanged)."""
        return self._with(min_sigma=float(min_sigma))

    def expected_pixels(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What the detector is expected to measure for predicted pixels ``uv`` (n, 2), and the slope.

        ``uv`` itself where the observation has no window; else the mean of the
        Gaussian (the observation's marginal sigmas) truncated to the window.

        Returns:
            (n, 2) expected pixels and (n, 2) their derivative per axis (1 without a window).
        """
        m, slope = np.array(uv, dtype=float), np.ones_like(uv, dtype=float)
        rows = np.isfinite(self._window_table[:, 0])
        if rows.any():
            w = self._window_table[rows]
            m[rows], slope[rows] = truncated_means(uv[rows], self._sigma_table[rows], w[:, :2], w[:, 2:])
        return m, slope


def project_keypoints(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p: np.ndarray, jacobians: bool):
    """Predicted pixels of every observation, and their Jacobians.

    Args:
        obs: the observations.
        world_T_vehicle: vehicle pose.
        vehicle_p: (12, 3) body-frame keypoints, metres.
        jacobians: whether to return Jacobians.

    Returns:
        uv: (n, 2) predicted pixels.
        depth: (n,) depth in the observing camera, metres (before clamping).
        J_pose: (n, 2, 6) d uv / d xi (GTSAM's right perturbation, rotation first), or None.
        J_point: (n, 2, 3) d uv / d vehicle_p_k, or None.
    """
    T = world_T_vehicle.matrix()
    R, t = T[:3, :3], T[:3, 3]
    body = vehicle_p[obs.keypoint_index]
    world = body @ R.T + t
    cam_p = np.einsum("nij,nj->ni", obs._R_cw, world) + obs._t_cw
    depth = cam_p[:, 2].copy()
    clamped = depth < _MIN_DEPTH
    cam_p[:, 2] = np.maximum(depth, _MIN_DEPTH)
    uv, J_cam = project_pinhole(cam_p, *obs._intrinsics, obs._dist, jacobians, fisheye=obs._fisheye)
    if not jacobians:
        return uv, depth, None, None
    if clamped.any():
        J_cam[clamped, :, 2] = 0.0  # the clamped depth no longer moves with the point
    J_point = np.einsum("nij,njk->nik", J_cam, obs._R_cw @ R)  # (n, 2, 3)
    J_pose = np.empty((len(obs), 2, 6))
    # d(R p + t)/d xi = [-R [p]x, R]  =>  rows a^T (-R[p]x) = (p x (R^T a))^T with a^T R = J_point rows
    J_pose[:, :, :3] = cross(body[:, None, :], J_point)
    J_pose[:, :, 3:] = J_point
    return uv, depth, J_pose, J_point


def whitened_residuals(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p: np.ndarray) -> np.ndarray:
    """(n, 2) whitened residuals ``L (m(pi(x)) - uv)`` before the robust loss (``m``: :meth:`KeypointObservations.expected_pixels`).

    The projection factor's compiled kernel without its loss and Jacobians (a tenth of the NumPy projection's
    time; the same to about 1e-14 as :func:`whitened_residuals_numpy`: tests/factors/test_projection.py)."""
    T = world_T_vehicle.matrix()
    r = np.empty(2 * len(obs))
    projection_kernel(T[:3, :3], T[:3, 3], np.ascontiguousarray(vehicle_p, dtype=float), obs.keypoint_index, obs._R_cw,
                      obs._t_cw, obs._intrinsics_table, obs._lens_table, obs._dist_table, obs.uv, obs.sqrt_information,
                      obs._window_table, obs._sigma_table, _NO_LOSS, 1.0, _MIN_DEPTH, False, r, _EMPTY, _EMPTY)
    return r.reshape(-1, 2)


def whitened_pose_jacobian(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3,
                           vehicle_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(residuals (n, 2), d residuals / d xi (n, 2, 6)): :func:`whitened_residuals` and their Jacobian with respect to
    the pose (GTSAM's right perturbation, rotation first), from the projection factor's compiled kernel."""
    T = world_T_vehicle.matrix()
    r, H_pose, H_shape = np.empty(2 * len(obs)), np.empty((2 * len(obs), 6)), np.zeros((2 * len(obs), 36))
    projection_kernel(T[:3, :3], T[:3, 3], np.ascontiguousarray(vehicle_p, dtype=float), obs.keypoint_index, obs._R_cw,
                      obs._t_cw, obs._intrinsics_table, obs._lens_table, obs._dist_table, obs.uv, obs.sqrt_information,
                      obs._window_table, obs._sigma_table, _NO_LOSS, 1.0, _MIN_DEPTH, True, r, H_pose, H_shape)
    return r.reshape(-1, 2), H_pose.reshape(-1, 2, 6)


def whitened_residuals_numpy(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p: np.ndarray) -> np.ndarray:
    """:func:`whitened_residuals` in NumPy (:func:`project_keypoints`, :meth:`KeypointObservations.expected_pixels`):
    the reference the compiled kernel is tested against."""
    uv, _, _, _ = project_keypoints(obs, world_T_vehicle, vehicle_p, jacobians=False)
    expected, _ = obs.expected_pixels(uv)
    return np.einsum("nij,nj->ni", obs.sqrt_information, expected - obs.uv)


def robust_costs(obs: KeypointObservations, world_T_vehicle: np.ndarray, vehicle_p: np.ndarray, loss: RobustLoss) -> np.ndarray:
    """Robust costs ``sum_i rho(|e_i|)`` of all observations at each of K poses and shapes, in one compiled pass.

    ``e_i`` are the whitened residuals of :func:`whitened_residuals` (the same
    projection, depth clamp and truncation), ``rho`` the loss; the
    :func:`kernels.projection.robust_cost_kernel` scores all K at once.

    Args:
        obs: the observations.
        world_T_vehicle: (K, 4, 4) vehicle poses (vehicle -> world), metres.
        vehicle_p: (K, 12, 3) body-frame keypoints of each, metres.
        loss: the robust loss.

    Returns:
        (K,) costs (unitless; NaN or inf where a projection is not finite).
    """
    T = np.asarray(world_T_vehicle, dtype=float).reshape(-1, 4, 4)
    points = np.ascontiguousarray(vehicle_p, dtype=float).reshape(len(T), 12, 3)
    costs = np.empty(len(T))
    robust_cost_kernel(np.ascontiguousarray(T[:, :3, :3]), np.ascontiguousarray(T[:, :3, 3]), points, obs.keypoint_index,
                       obs._R_cw, obs._t_cw, obs._intrinsics_table, obs._lens_table, obs._dist_table, obs.uv,
                       obs.sqrt_information, obs._window_table, obs._sigma_table, loss.id, float(loss.threshold), _MIN_DEPTH,
                       costs)
    return costs


def extrinsic_jacobian(pose_jacobian: np.ndarray, world_T_vehicle: gtsam.Pose3,
                       world_T_camera: gtsam.Pose3) -> np.ndarray:
    """(2m, 6) derivative of one camera's whitened residuals with respect to its extrinsic's error.

    With the true camera ``world_T_camera * Exp(xi)``, the keypoints reach it as
    ``Exp(-xi) camera_T_vehicle p``, which is ``camera_T_vehicle Exp(eta) p`` with
    ``eta = -Ad(vehicle_T_camera) xi``: the camera's error acts on its residuals
    as that change of the vehicle's pose, so their derivative is
    ``-J_pose Ad(vehicle_T_camera)``.

    Args:
        pose_jacobian: (2m, 6) the derivative of the camera's m whitened residuals with respect to the vehicle's
            pose (GTSAM's right perturbation of ``world_T_vehicle``, rotation first).
        world_T_vehicle: the vehicle's pose (vehicle -> world), metres.
        world_T_camera: the camera's pose as given (camera -> world), metres.
    """
    vehicle_T_camera = world_T_vehicle.inverse().compose(world_T_camera)
    return -np.asarray(pose_jacobian, dtype=float) @ vehicle_T_camera.AdjointMap()


def _error(obs: KeypointObservations, loss_id: int, threshold: float, keys: tuple, offset: bool,
           world_T_camera: gtsam.Pose3 | None, out: tuple, this: gtsam.CustomFactor, values: gtsam.Values, H):
    """The factor's whitened residuals (and Jacobians into ``H``). What does not change is taken once, when the
    factor is made: the loss's index and threshold, the factor's keys as Python ints (``this.keys()`` builds a new
    list at each call), and ``out``, its (r, H_pose, H_shape) buffers, reused (GTSAM copies ``H[i]`` and the
    returned ``r``; the kernel writes the same entries of ``H_shape`` at each call, the others stay zero).

    With ``offset`` the fifth key is a detector's pose offset ``vehicle_T_seen``; with ``world_T_camera`` (the
    pose the observations' one camera is given at) the last key is that camera's error ``E``, its true pose
    ``world_T_camera * E``. The kernel projects through the given camera, so the vehicle it is handed is the one
    that camera would see at the true camera's view of it: ``world_T_camera E^-1 camera_T_world world_T_seen``."""
    r, H_pose, H_shape = out
    T = values.atPose3(keys[0]).matrix()
    points = np.concatenate((values.atVector(keys[1]), values.atVector(keys[2]),
                             values.atVector(keys[3]))).reshape(12, 3)
    if offset:  # the keypoints as this detector sees them: world_T_seen = world_T_vehicle * vehicle_T_seen
        vehicle_T_seen = values.atPose3(keys[4])
        T = T @ vehicle_T_seen.matrix()
    if world_T_camera is not None:
        moved = world_T_camera.compose(values.atPose3(keys[-1]).inverse()).compose(world_T_camera.inverse())
        T = moved.matrix() @ T
    want = H is not None
    projection_kernel(T[:3, :3], T[:3, 3], points, obs.keypoint_index, obs._R_cw, obs._t_cw, obs._intrinsics_table,
                      obs._lens_table, obs._dist_table, obs.uv, obs.sqrt_information, obs._window_table, obs._sigma_table,
                      loss_id, threshold, _MIN_DEPTH, want, r, H_pose, H_shape)
    if want:  # H_pose is d/d of the pose the kernel projected (T), right perturbation
        H[1] = H_shape[:, :12]
        H[2] = H_shape[:, 12:24]
        H[3] = H_shape[:, 24:]
        if offset:  # world_T_vehicle Exp(xi) vehicle_T_seen = world_T_seen Exp(Ad(seen_T_vehicle) xi)
            H[4] = H_pose
            H[0] = H_pose @ vehicle_T_seen.inverse().AdjointMap()
        else:
            H[0] = H_pose
        if world_T_camera is not None:  # E Exp(d) moves the vehicle the kernel projected as the camera's error does
            H[len(keys) - 1] = extrinsic_jacobian(H_pose, gtsam.Pose3(T), world_T_camera)
    return r


def projection_factor(
    pose_key: int, layer_keys, obs: KeypointObservations, loss: RobustLoss = RobustLoss(),
    offset_key: int | None = None, camera_key: int | None = None,
) -> gtsam.CustomFactor:
    """A factor on ``[pose_key, *layer_keys]`` (and ``offset_key``, ``camera_key``) for all observations in ``obs``.

    Args:
        pose_key: key of ``world_T_vehicle`` (``gtsam.Pose3``).
        layer_keys: keys of the (wheel, light, roof) layer 12-vectors.
        obs: the pixel observations with their square-root information.
        loss: robust loss applied to each observation's whitened 2-vector.
        offset_key: optional key of a detector's pose offset ``vehicle_T_seen`` (``gtsam.Pose3``): the
            rigid motion of the vehicle, in its body frame, as these observations see it (docs/factors.md).
        camera_key: optional key of the error of the one camera all of ``obs`` come from (``gtsam.Pose3``
            ``E``: the camera's true pose is its given ``world_T_camera * E``, as
            :attr:`vfactor.camera.Camera.extrinsic_sigma` states it; :mod:`vfactor.extrinsics_fit`).

    Raises:
        ValueError: no observations; a ``camera_key`` with observations of several cameras.
    """
    if len(obs) == 0:
        raise ValueError("projection_factor: no observations")
    world_T_camera = None
    if camera_key is not None:
        seen = np.unique(obs.camera_index)
        if len(seen) != 1:
            raise ValueError(f"projection_factor: a camera_key needs the observations of one camera, got "
                             f"{len(seen)} cameras'")
        world_T_camera = obs.cameras[int(seen[0])].pose
    noise = gtsam.noiseModel.Unit.Create(2 * len(obs))
    out = (np.empty(2 * len(obs)), np.empty((2 * len(obs), 6)), np.zeros((2 * len(obs), 36)))
    keys = ([pose_key, *layer_keys] + ([] if offset_key is None else [offset_key])
            + ([] if camera_key is None else [camera_key]))
    fixed = (obs, loss.id, float(loss.threshold), tuple(int(k) for k in keys), offset_key is not None, world_T_camera,
             out)
    return gtsam.CustomFactor(noise, keys, partial(_error, *fixed))
