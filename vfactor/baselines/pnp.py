"""Baseline: PnP of the mean wireframe in one camera (the paper's "PnP" row, Table II).

In every camera that sees enough keypoints, the pose of a fixed wireframe (the
prior's mean shape by default) is found by OpenCV's SQPnP (a global solver of
the object-space error) refined by Levenberg-Marquardt on the reprojection
error; the camera whose pose reprojects its own keypoints best wins. The shape
is never changed.

The reprojection error that ranks the cameras is *relative*: pixels divided by
the diagonal of the box around that camera's observed keypoints (the vehicle's
size in the image), so that a camera far from the vehicle does not win merely
because its pixels are few. :func:`relative_residuals` computes it; the CPO and
single-view baselines use the same measure.
"""

from __future__ import annotations

import cv2
import gtsam
import numpy as np

from vfactor.factors.projection import KeypointObservations, project_keypoints, whitened_residuals
from vfactor.result import Status, VehicleResult
from vfactor.shape_model import default_shape_prior
from vfactor.wireframe import Wireframe

__all__ = ["pnp", "camera_pnp", "box_diagonals", "relative_residuals", "usable", "clean_observations", "select_camera",
           "candidate_cameras"]

_MIN_BOX_PX = 1.0


def usable(obs: KeypointObservations) -> np.ndarray:
    """(n,) mask of observations with finite pixels and a finite, non-zero square-root information."""
    L = obs.sqrt_information.reshape(len(obs), 4)
    return np.all(np.isfinite(obs.uv), axis=1) & np.all(np.isfinite(L), axis=1) & (np.abs(obs.sqrt_information[:, 0, 0]) > 0)


def clean_observations(obs: KeypointObservations) -> tuple[KeypointObservations, int]:
    """The :func:`usable` observations.

    Returns:
        (the kept observations, how many were dropped).
    """
    keep = usable(obs)
    if keep.all():
        return obs, 0
    return obs.subset(keep), int((~keep).sum())


def box_diagonals(obs: KeypointObservations) -> np.ndarray:
    """(num_cameras,) diagonal of the box around each camera's observed pixels (the vehicle's image size), px.

    At least 1 px; 1 px for a camera with fewer than two observations.
    """
    out = np.full(len(obs.cameras), _MIN_BOX_PX)
    for c in range(len(obs.cameras)):
        uv = obs.uv[obs.camera_index == c]
        if len(uv) >= 2:
            out[c] = max(_MIN_BOX_PX, float(np.linalg.norm(uv.max(0) - uv.min(0))))
    return out


def relative_residuals(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p: np.ndarray,
                       boxes: np.ndarray | None = None) -> np.ndarray:
    """(n, 2) reprojection errors in units of the vehicle's image size: ``(pi(x) - uv) / box_diagonal``.

    A point behind (or within 5 cm of) a camera is clamped to that depth by
    :func:`vfactor.factors.projection.project_keypoints`, so its error is large but finite.
    """
    boxes = box_diagonals(obs) if boxes is None else boxes
    uv, _, _, _ = project_keypoints(obs, world_T_vehicle, vehicle_p, jacobians=False)
    return (uv - obs.uv) / boxes[obs.camera_index][:, None]


def camera_pnp(obs: KeypointObservations, camera: int, vehicle_p: np.ndarray, refine: bool = True) -> gtsam.Pose3 | None:
    """``world_T_vehicle`` of a fixed shape from one camera's keypoints (SQPnP, then LM refinement).

    Args:
        obs: the observations (only camera ``camera``'s rows are used).
        camera: index of the camera in ``obs.cameras``.
        vehicle_p: (12, 3) body-frame keypoints, metres.
        refine: refine SQPnP's pose by ``cv2.solvePnPRefineLM`` (reprojection error; in
            normalised coordinates for a fisheye lens, :meth:`~vfactor.camera.Camera.pnp_inputs`).

    Returns:
        The pose, or ``None`` when the camera sees fewer than 4 keypoints, OpenCV
        fails, or the vehicle would lie behind the camera.
    """
    rows = np.flatnonzero(obs.camera_index == camera)
    if len(rows) < 4:
        return None
    cam = obs.cameras[camera]
    obj = np.ascontiguousarray(vehicle_p[obs.keypoint_index[rows]], dtype=np.float64)
    img, K, dist, _ = cam.pnp_inputs(obs.uv[rows])  # a fisheye lens: normalised points, identity K
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_SQPNP)
        if not ok:
            return None
        if refine:
            rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    except cv2.error:
        return None
    camera_T_vehicle = np.eye(4)
    camera_T_vehicle[:3, :3] = cv2.Rodrigues(rvec)[0]
    camera_T_vehicle[:3, 3] = np.ravel(tvec)
    if not np.all(np.isfinite(camera_T_vehicle)):
        return None
    depth = obj @ camera_T_vehicle[:3, :3].T + camera_T_vehicle[:3, 3]
    if np.median(depth[:, 2]) <= 0:
        return None
    return cam.pose.compose(gtsam.Pose3(camera_T_vehicle))


def select_camera(obs: KeypointObservations, camera) -> int | None:
    """Index of a camera given by index or name (``None`` when it is not one of ``obs.cameras``)."""
    if isinstance(camera, (int, np.integer)) and not isinstance(camera, bool):
        return int(camera) if 0 <= camera < len(obs.cameras) else None
    names = [c.name for c in obs.cameras]
    return names.index(camera) if camera in names else None


def candidate_cameras(obs: KeypointObservations, camera, min_keypoints: int, method: str,
                      vehicle_id: str) -> tuple[list[int], VehicleResult | None]:
    """Cameras a one-view method may use: the given one (index or name), or every camera, seeing enough keypoints.

    Returns:
        (camera indices, None), or ([], a FAILED/DEGENERATE result saying why).
    """
    if len(obs) == 0:
        return [], VehicleResult(vehicle_id, Status.DEGENERATE, message=f"{method}: no observations")
    if camera is not None:
        chosen = select_camera(obs, camera)
        if chosen is None:
            return [], VehicleResult(vehicle_id, Status.FAILED, message=f"{method}: unknown camera {camera!r}")
        candidates = [chosen]
    else:
        candidates = list(range(len(obs.cameras)))
    counts = np.bincount(obs.camera_index, minlength=len(obs.cameras))
    candidates = [c for c in candidates if counts[c] >= min_keypoints]
    if not candidates:
        return [], VehicleResult(vehicle_id, Status.DEGENERATE,
                                 message=f"{method}: no camera sees {min_keypoints} keypoints (most: {int(counts.max())})")
    return candidates, None


def pnp(
    obs: KeypointObservations,
    wireframe: Wireframe | None = None,
    camera: int | str | None = None,
    vehicle_id: str = "vehicle",
    min_keypoints: int = 4,
    refine: bool = True,
) -> VehicleResult:
    """Pose of a fixed wireframe by PnP in the single camera that fits its own keypoints best.

    Args:
        obs: the vehicle's observations in all cameras.
        wireframe: the shape (default: the prior's mean, 2.75 m wheelbase); returned unchanged.
        camera: use only this camera (index or name); default: every camera, the
            one with the smallest RMS relative reprojection error over its own keypoints wins.
        vehicle_id: id for the result.
        min_keypoints: fewer keypoints in a camera (at least 4) skip it.
        refine: refine each PnP pose by Levenberg-Marquardt on the reprojection error.

    Returns:
        ``converged`` with ``extras["camera"]`` (the winning camera's name) and
        ``extras["rms_relative_error"]`` (per tried camera name); ``final_error``
        is 0.5 * the sum of squared whitened residuals over *all* cameras.
        ``degenerate`` when no camera sees ``min_keypoints`` keypoints, ``failed``
        when PnP fails in every camera. Never raises on bad observations.
    """
    wireframe = wireframe or Wireframe(default_shape_prior().mean)
    obs, dropped = clean_observations(obs)
    candidates, problem = candidate_cameras(obs, camera, max(4, int(min_keypoints)), "pnp", vehicle_id)
    if problem is not None:
        return problem
    points = wireframe.vehicle_p_keypoints
    boxes = box_diagonals(obs)
    tried, best = {}, None
    for c in candidates:
        pose = camera_pnp(obs, c, points, refine)
        if pose is None:
            continue
        own = obs.camera_index == c
        rms = float(np.sqrt(np.mean(np.sum(relative_residuals(obs, pose, points, boxes)[own] ** 2, axis=1))))
        tried[obs.cameras[c].name] = rms
        if np.isfinite(rms) and (best is None or rms < best[0]):
            best = (rms, c, pose)
    if best is None:
        return VehicleResult(vehicle_id, Status.FAILED, message="pnp: OpenCV found no pose in front of any camera")
    _, c, pose = best
    e = whitened_residuals(obs, pose, points)
    message = f"dropped {dropped} non-finite observations" if dropped else ""
    return VehicleResult(
        vehicle_id, Status.CONVERGED, world_T_vehicle=pose, wireframe=wireframe, iterations=1,
        final_error=0.5 * float(np.sum(e * e)), message=message,
        extras={"camera": obs.cameras[c].name, "rms_relative_error": tried},
    )
