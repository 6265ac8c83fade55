"""Baseline: the paper's "stereo triangulation" (Section II-C, Tables I and II).

Every keypoint seen in both images of one camera pair is triangulated on its
own from its two pixels and the calibrations, with no confidence weighting
(the paper's "stereoscopic formula" uses pixels and camera parameters only);
the triangulated points, connected, are the wireframe, asymmetric as they
come. The pose is the body frame of that wireframe: the origin at the
centroid of the triangulated wheel hubs and the axes of the mean wireframe
rigidly aligned (Umeyama) to the triangulated points.

It differs from :func:`vfactor.baselines.triangulation` (any number of views,
confidence-weighted rows, origin from the scaled mean) only where the paper's
two-image method does; docs/baselines.md compares them.
"""

from __future__ import annotations

import gtsam
import numpy as np

from vfactor.baselines.pnp import clean_observations, select_camera
from vfactor.factors.projection import KeypointObservations, whitened_residuals
from vfactor.init import triangulate_keypoints, umeyama
from vfactor.keypoints import LAYERS
from vfactor.result import Status, VehicleResult
from vfactor.shape_model import default_shape_prior
from vfactor.wireframe import Wireframe

__all__ = ["stereo", "stereo_pair"]


def stereo_pair(obs: KeypointObservations) -> tuple[int, int] | None:
    """The two cameras that see the most keypoints in common (ties: the larger summed sqrt-information).

    Returns ``None`` when fewer than two cameras see anything.
    """
    cams = [c for c in range(len(obs.cameras)) if np.any(obs.camera_index == c)]
    best, best_score = None, None
    weight = np.abs(obs.sqrt_information[:, 0, 0])
    for a_pos, a in enumerate(cams):
        for b in cams[a_pos + 1 :]:
            ka = set(obs.keypoint_index[obs.camera_index == a].tolist())
            kb = set(obs.keypoint_index[obs.camera_index == b].tolist())
            common = ka & kb
            rows = np.isin(obs.camera_index, [a, b]) & np.isin(obs.keypoint_index, list(common))
            score = (len(common), float(weight[rows].sum()))
            if best_score is None or score > best_score:
                best, best_score = (a, b), score
    return best


def stereo(
    obs: KeypointObservations,
    cameras: tuple[int | str, int | str] | None = None,
    vehicle_id: str = "vehicle",
    mean: Wireframe | None = None,
    min_keypoints: int = 3,
) -> VehicleResult:
    """Pose and wireframe from two-view triangulation of each keypoint.

    Args:
        obs: the vehicle's observations.
        cameras: the two cameras (indices or names); default :func:`stereo_pair`.
        vehicle_id: id for the result.
        mean: the shape aligned to the triangulated points for the axes and for
            keypoints that do not triangulate (default: the prior's mean).
        min_keypoints: fewer triangulated keypoints (at least 3) make the result ``degenerate``.

    Returns:
        ``converged`` with ``extras["cameras"]`` (the pair's names) and
        ``extras["triangulated"]`` (keypoint indices); a keypoint not seen in
        both images takes the aligned mean shape's position (scaled by the
        Umeyama similarity). ``final_error``: 0.5 * sum of squared whitened
        residuals over all cameras. ``degenerate`` with fewer than two cameras
        or too few triangulated keypoints. Never raises on bad observations.
    """
    mean = mean or Wireframe(default_shape_prior().mean)
    obs, _ = clean_observations(obs)
    if len(obs) == 0:
        return VehicleResult(vehicle_id, Status.DEGENERATE, message="stereo: no observations")
    if cameras is None:
        pair = stereo_pair(obs)
        if pair is None:
            return VehicleResult(vehicle_id, Status.DEGENERATE, message="stereo: needs keypoints seen by two cameras, got one camera")
    else:
        if len(cameras) != 2:
            return VehicleResult(vehicle_id, Status.FAILED, message=f"stereo: cameras must name two cameras, got {cameras!r}")
        pair = tuple(select_camera(obs, c) for c in cameras)
        if None in pair or pair[0] == pair[1]:
            return VehicleResult(vehicle_id, Status.FAILED, message=f"stereo: cameras must name two distinct cameras, got {cameras!r}")
    rows = np.isin(obs.camera_index, pair)
    two = obs.subset(rows)
    # unweighted: the paper's stereo formula uses no confidence
    unit = KeypointObservations(two.cameras, two.camera_index, two.keypoint_index, two.uv, np.broadcast_to(np.eye(2), (len(two), 2, 2)).copy())
    try:
        idx, world = triangulate_keypoints(unit)
    except np.linalg.LinAlgError as exc:  # pragma: no cover - SVD of a finite matrix does not fail in practice
        return VehicleResult(vehicle_id, Status.FAILED, message=f"stereo: triangulation failed ({exc})")
    need = max(3, int(min_keypoints))
    names = [obs.cameras[c].name for c in pair]
    if len(idx) < need:
        return VehicleResult(vehicle_id, Status.DEGENERATE,
                             message=f"stereo: only {len(idx)} keypoints triangulate from cameras {names} (need {need})")
    spread = np.linalg.svd(world - world.mean(0), compute_uv=False)
    if spread[1] < 1e-3:
        return VehicleResult(vehicle_id, Status.DEGENERATE,
                             message="stereo: the triangulated keypoints are (nearly) collinear; no orientation")
    R, t, s = umeyama(mean.vehicle_p_keypoints[idx], world, with_scale=True)
    wheels = [k for k in LAYERS["wheel"] if k in set(idx.tolist())]
    if len(wheels) == 4:
        origin = world[np.isin(idx, wheels)].mean(0)  # the body origin is the hub centroid (docs/conventions.md)
    else:
        origin = t  # the aligned mean's hub centroid
    world_T_vehicle = gtsam.Pose3(gtsam.Rot3(R), origin)
    body = ((mean.vehicle_p_keypoints * s) @ R.T + t - origin) @ R  # aligned mean, for what does not triangulate
    body[idx] = (world - origin) @ R
    wireframe = Wireframe(body)
    e = whitened_residuals(obs, world_T_vehicle, wireframe.vehicle_p_keypoints)
    return VehicleResult(
        vehicle_id, Status.CONVERGED, world_T_vehicle=world_T_vehicle, wireframe=wireframe, iterations=1,
        final_error=0.5 * float(np.sum(e * e)),
        extras={"cameras": names, "triangulated": idx.tolist()},
    )
