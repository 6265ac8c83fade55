"""Pose and shape errors as the paper reports them.

- Rotation error: ``|| log(R1^T R2) ||_F / sqrt(2)``, degrees; ``log`` is the
  matrix logarithm (a skew matrix), so this is the geodesic angle between the
  two rotations.
- Translation error: distance between the centroids of the two 12-keypoint
  sets, cm.
- Keypoint error: per-keypoint 3D Euclidean distance, cm, and its mean.

And the consistency of the covariances (:func:`pose_nees`, :func:`keypoint_nees`):
the NEES, the error's squared Mahalanobis norm under the estimate's
covariance, which a consistent estimator averages at the dimension (6 for a
pose, 3 for a keypoint), with :data:`CHI2_95` of the cases under the chi2 95 %
bound.

Inputs are in metres and radians (vfactor's internal units); outputs in cm and
degrees.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np

from vfactor.keypoints import NUM_KEYPOINTS

__all__ = [
    "rotation_error_deg",
    "translation_error_cm",
    "keypoint_errors_cm",
    "pose_errors",
    "summarise",
    "evaluate",
    "CHI2_95",
    "pose_tangent_error",
    "pose_nees",
    "pose_nees_components",
    "keypoint_nees",
    "ray_nees",
    "nees_summary",
]

#: The 95 % points of chi2 by degrees of freedom: the NEES bound of a pose (6), a keypoint (3), and of a position
#: across (2) and along (1) a camera's ray (:func:`ray_nees`).
CHI2_95 = {1: 3.841458820694124, 2: 5.991464547107979, 3: 7.814727903251178, 6: 12.591587243743977}


def _rotation_matrix(R, name: str) -> np.ndarray:
    if isinstance(R, gtsam.Pose3):
        return R.rotation().matrix()
    if isinstance(R, gtsam.Rot3):
        return R.matrix()
    M = np.asarray(R, dtype=float)
    if M.shape == (4, 4):
        M = M[:3, :3]
    if M.shape != (3, 3):
        raise ValueError(f"{name}: expected a gtsam.Rot3, gtsam.Pose3, 3x3 or 4x4 matrix, got shape {M.shape}")
    return M


def rotation_error_deg(R1, R2) -> float:
    """Geodesic angle between two rotations, degrees: ``|| log(R1^T R2) ||_F / sqrt(2)``.

    Args:
        R1, R2: ``gtsam.Rot3``, ``gtsam.Pose3`` (its rotation), or 3x3 / 4x4 arrays.

    Example:
        >>> round(rotation_error_deg(gtsam.Rot3.Yaw(0.0), gtsam.Rot3.Yaw(math.radians(10))), 9)
        10.0
    """
    A, B = _rotation_matrix(R1, "R1"), _rotation_matrix(R2, "R2")
    # ||log(R)||_F / sqrt(2) = |theta| with cos(theta) = (trace(R) - 1) / 2; the
    # axis-angle form via Logmap is exact near 0 and pi, unlike arccos of the trace.
    u, _, vt = np.linalg.svd(A.T @ B)
    R = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    return math.degrees(float(np.linalg.norm(gtsam.Rot3.Logmap(gtsam.Rot3(R)))))


def _points(p, name: str) -> np.ndarray:
    p = np.asarray(p, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"{name}: expected shape (N, 3), got {p.shape}")
    return p


def translation_error_cm(kp_est, kp_true) -> float:
    """Distance between the centroids of two keypoint sets (N, 3) in metres, in cm."""
    a, b = _points(kp_est, "kp_est"), _points(kp_true, "kp_true")
    if a.shape != b.shape:
        raise ValueError(f"kp_est and kp_true: shapes differ, {a.shape} vs {b.shape}")
    return 100.0 * float(np.linalg.norm(a.mean(0) - b.mean(0)))


def keypoint_errors_cm(kp_est, kp_true) -> np.ndarray:
    """(N,) Euclidean distance between corresponding keypoints (N, 3) in metres, in cm."""
    a, b = _points(kp_est, "kp_est"), _points(kp_true, "kp_true")
    if a.shape != b.shape:
        raise ValueError(f"kp_est and kp_true: shapes differ, {a.shape} vs {b.shape}")
    return 100.0 * np.linalg.norm(a - b, axis=1)


def pose_errors(world_T_vehicle_est, kp_world_est, world_T_vehicle_true, kp_world_true) -> dict:
    """All the paper's errors of one vehicle estimate.

    Args:
        world_T_vehicle_est, world_T_vehicle_true: poses (``gtsam.Pose3``, 4x4) or rotations.
        kp_world_est, kp_world_true: (12, 3) world keypoints, metres.

    Returns:
        ``{"rotation_deg": float, "translation_cm": float, "keypoint_cm": (12,) array,
        "mean_keypoint_cm": float}``.
    """
    errors = keypoint_errors_cm(kp_world_est, kp_world_true)
    return {
        "rotation_deg": rotation_error_deg(world_T_vehicle_est, world_T_vehicle_true),
        "translation_cm": translation_error_cm(kp_world_est, kp_world_true),
        "keypoint_cm": errors,
        "mean_keypoint_cm": float(errors.mean()),
    }


def summarise(errors: list[dict]) -> dict:
    """Means and medians over many :func:`pose_errors` results.

    Entries without errors (rows of :func:`evaluate` for vehicles that were
    not estimated) are counted under ``skipped`` and left out of the statistics.

    Returns:
        ``{"count": n, "skipped": m, "rotation_deg": {"mean", "median"}, "translation_cm": {...},
        "mean_keypoint_cm": {...}, "keypoint_cm": {"mean": (12,) list, "median": (12,) list}}``;
        NaN statistics when nothing is left.
    """
    kept = [e for e in errors if "rotation_deg" in e]
    out: dict = {"count": len(kept), "skipped": len(errors) - len(kept)}
    errors = kept
    for key in ("rotation_deg", "translation_cm", "mean_keypoint_cm"):
        values = np.array([e[key] for e in errors], dtype=float)
        out[key] = _stats(values)
    per_kp = np.array([e["keypoint_cm"] for e in errors], dtype=float).reshape(-1, NUM_KEYPOINTS)
    if len(per_kp):
        out["keypoint_cm"] = {"mean": per_kp.mean(0).tolist(), "median": np.median(per_kp, 0).tolist()}
    else:
        out["keypoint_cm"] = {"mean": [math.nan] * NUM_KEYPOINTS, "median": [math.nan] * NUM_KEYPOINTS}
    return out


def _stats(values: np.ndarray) -> dict:
    if len(values) == 0:
        return {"mean": math.nan, "median": math.nan}
    return {"mean": float(values.mean()), "median": float(np.median(values))}


def evaluate(frame_results, truth) -> list[dict]:
    """Errors of every estimated vehicle against the ground truth, frame by frame.

    Args:
        frame_results: list of :class:`vfactor.result.FrameResult`, one per frame.
        truth: per frame, vehicle id -> an object with ``world_T_vehicle`` and
            ``keypoints_world`` (e.g. :class:`vfactor.sim.VehicleTruth`).

    Returns:
        One dict per vehicle result with a true counterpart: ``frame``, ``id``,
        ``status``, and, for results with a pose and shape, the keys of :func:`pose_errors`.
        Vehicles without a pose (degenerate, failed) carry only the first three.
    """
    if len(frame_results) != len(truth):
        raise ValueError(f"frame_results and truth: {len(frame_results)} vs {len(truth)} frames")
    rows = []
    for f, (frame, true_vehicles) in enumerate(zip(frame_results, truth)):
        for v in frame.vehicles:
            if v.id not in true_vehicles:
                continue
            row = {"frame": f, "id": v.id, "status": getattr(v.status, "value", v.status)}
            if v.world_T_vehicle is not None and v.wireframe is not None:
                t = true_vehicles[v.id]
                row.update(pose_errors(v.world_T_vehicle, v.keypoints_world, t.world_T_vehicle, t.keypoints_world))
            rows.append(row)
    return rows


def pose_tangent_error(world_T_vehicle_est: gtsam.Pose3, world_T_vehicle_true: gtsam.Pose3) -> np.ndarray:
    """(6,) ``xi = Logmap(est^-1 true)``: rotation (rad) then translation (m) in the estimate's body frame, the
    tangent convention of :attr:`vfactor.result.VehicleResult.pose_covariance` (``true = est exp(xi)``)."""
    return gtsam.Pose3.Logmap(world_T_vehicle_est.between(world_T_vehicle_true))


def pose_nees(world_T_vehicle_est: gtsam.Pose3, pose_covariance, world_T_vehicle_true: gtsam.Pose3) -> float:
    """Squared Mahalanobis norm of a pose error under the estimate's (6, 6) covariance.

    The error is ``xi = Logmap(est^-1 true)``, rotation (rad) then translation
    (m) in the estimate's body frame: the tangent convention of
    :attr:`vfactor.result.VehicleResult.pose_covariance` (``true = est exp(xi)``).
    """
    P = np.asarray(pose_covariance, dtype=float)
    if P.shape != (6, 6):
        raise ValueError(f"pose_covariance: expected shape (6, 6), got {P.shape}")
    xi = pose_tangent_error(world_T_vehicle_est, world_T_vehicle_true)
    return float(xi @ np.linalg.solve(P, xi))


def pose_nees_components(world_T_vehicle_est: gtsam.Pose3, pose_covariance, world_T_vehicle_true: gtsam.Pose3
                         ) -> np.ndarray:
    """(6,) each tangent coordinate's squared error over its own variance: roll, pitch, yaw (rad) and x, y, z (m) of
    the error ``xi = Logmap(est^-1 true)`` in the estimate's body frame (as :func:`pose_nees`), each over the
    covariance's diagonal entry. Averaged over many cases each is 1 for a consistent covariance: where the pose NEES
    is off, they say along which axes (a width in one direction can hide a narrowness in another)."""
    P = np.asarray(pose_covariance, dtype=float)
    if P.shape != (6, 6):
        raise ValueError(f"pose_covariance: expected shape (6, 6), got {P.shape}")
    xi = pose_tangent_error(world_T_vehicle_est, world_T_vehicle_true)
    return xi**2 / np.diag(P)


def keypoint_nees(kp_world_est, keypoint_covariances_world, kp_world_true) -> np.ndarray:
    """(N,) squared Mahalanobis norms of the world keypoint errors (N, 3) under their (N, 3, 3) covariances (m, m^2)."""
    a, b = _points(kp_world_est, "kp_world_est"), _points(kp_world_true, "kp_world_true")
    C = np.asarray(keypoint_covariances_world, dtype=float)
    if a.shape != b.shape or C.shape != (len(a), 3, 3):
        raise ValueError(f"keypoints and covariances: shapes {a.shape}, {b.shape}, {C.shape} do not match")
    e = a - b
    return np.einsum("ni,ni->n", e, np.linalg.solve(C, e[..., None])[..., 0])


def ray_nees(world_T_vehicle_est: gtsam.Pose3, pose_covariance, world_T_vehicle_true: gtsam.Pose3,
             world_p_camera) -> tuple[float, float, float]:
    """A pose's translation error along one camera's ray (its depth) and across it, each under its covariance.

    The error is the translation part of ``Logmap(est^-1 true)`` (body frame, the tangent convention of
    :func:`pose_nees`); the ray runs from the camera centre to the estimated vehicle origin. A single view fixes
    a vehicle's position across its ray far better than along it, so the two are judged apart.

    Args:
        world_T_vehicle_est, world_T_vehicle_true: the estimate and the truth (metres).
        pose_covariance: the estimate's (6, 6) covariance (rotation first, then translation; rad, m).
        world_p_camera: (3,) the camera centre, world frame, metres.

    Returns:
        (the error along the ray, m, positive away from the camera; its squared Mahalanobis norm, 1 dof, bound
        ``CHI2_95[1]``; the squared Mahalanobis norm of the error across the ray, 2 dof, bound ``CHI2_95[2]``).
    """
    P = np.asarray(pose_covariance, dtype=float)
    if P.shape != (6, 6):
        raise ValueError(f"pose_covariance: expected shape (6, 6), got {P.shape}")
    ray_world = world_T_vehicle_est.translation() - np.asarray(world_p_camera, dtype=float).reshape(3)
    distance = np.linalg.norm(ray_world)
    if not distance > 0:
        raise ValueError("world_p_camera: the camera centre is at the vehicle origin")
    ray = world_T_vehicle_est.rotation().matrix().T @ (ray_world / distance)
    error = pose_tangent_error(world_T_vehicle_est, world_T_vehicle_true)[3:]
    P = P[3:, 3:]
    along = float(error @ ray)
    across = np.linalg.svd(np.eye(3) - np.outer(ray, ray))[0][:, :2]  # an orthonormal basis of the plane across
    e = across.T @ error
    return along, along**2 / float(ray @ P @ ray), float(e @ np.linalg.solve(across.T @ P @ across, e))


def nees_summary(values, dim: int) -> dict:
    """Mean NEES, its ratio to ``dim`` and the share under the chi2 95 % bound of ``dim`` (3 or 6); NaN when empty."""
    v = np.asarray([x for x in np.ravel(values) if np.isfinite(x)], dtype=float)
    if not len(v):
        return {"count": 0, "mean": math.nan, "ratio": math.nan, "under_95": math.nan}
    return {"count": int(len(v)), "mean": float(v.mean()), "ratio": float(v.mean() / dim),
            "under_95": float(np.mean(v < CHI2_95[dim]))}
