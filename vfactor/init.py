"""Initial pose (and scale) of a vehicle with no pose guess.

Candidates, all scored by the robust cross-projection cost over every camera
in one compiled pass (:func:`vfactor.factors.projection.robust_costs`):

* per camera, PnP of the mean wireframe with the labels as given and with
  left/right swapped, each also turned by 180 degrees about the body z axis:
  SQPnP on all the camera's keypoints, and OpenCV's RANSAC (EPnP) only when
  some keypoint is beyond the threshold from SQPnP's pose (with every
  keypoint within it, RANSAC would keep them all: the same fit), and only for
  the labelling whose SQPnP pose keeps the most keypoints within it;
* multi-view: keypoints seen by two or more cameras are triangulated and the
  mean wireframe is aligned to them (Umeyama, with scale).

The best few distinct upright candidates start the Levenberg-Marquardt solves:
the world's z is up (docs/conventions.md), and a candidate turned over (its
body's z axis more than 90 degrees from the world's) is no vehicle in traffic;
a few keypoints with outliers and swapped labels can fit one best (a Honda
Accord of ``library_2cam`` seed 27 at hard noise, solved 179 degrees off from
it; :mod:`vfactor.sanity` fails any solution still upside down).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass

import cv2
import gtsam
import numpy as np

from vfactor.factors.body_frame import upright
from vfactor.factors.projection import KeypointObservations, robust_costs
from vfactor.factors.robust import RobustLoss
from vfactor.keypoints import MIRROR_PERMUTATION
from vfactor.wireframe import Wireframe

__all__ = ["Candidate", "StartSearch", "umeyama", "triangulate_keypoints", "pose_candidates", "best_candidates",
           "cross_projection_cost", "distinct_poses", "own_pose", "OWN_POSE_MEMO"]


@dataclass(frozen=True)
class Candidate:
    """A starting point: pose, wireframe, its robust cost and where it came from."""

    world_T_vehicle: gtsam.Pose3
    wireframe: Wireframe
    cost: float
    source: str


def umeyama(src: np.ndarray, dst: np.ndarray, weights=None, with_scale: bool = True):
    """Similarity ``dst ~ s R src + t`` minimising weighted squared distances (Umeyama 1991).

    Args:
        src, dst: (n, 3) corresponding points, n >= 3.
        weights: optional (n,) non-negative weights.
        with_scale: estimate ``s`` (else ``s = 1``).

    Returns:
        (R (3, 3), t (3,), s).
    """
    w = np.ones(len(src)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    mu_s, mu_d = w @ src, w @ dst
    xs, xd = src - mu_s, dst - mu_d
    cov = (xd * w[:, None]).T @ xs
    U, S, Vt = np.linalg.svd(cov)
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    var_s = np.sum(w * np.sum(xs * xs, axis=1))
    s = float(np.trace(np.diag(S) @ D) / var_s) if with_scale and var_s > 0 else 1.0
    t = mu_d - s * R @ mu_s
    return R, t, s


def triangulate_keypoints(obs: KeypointObservations, min_views: int = 2):
    """Linear (DLT) triangulation of keypoints seen by ``min_views`` or more cameras.

    Each observation gives two rows ``w (x P_3 - P_1)``, ``w (y P_3 - P_2)`` (``x, y`` its
    undistorted normalised coordinates, ``P`` its camera's ``camera_T_world[:3]``, ``w``
    its square-root information); the keypoint is the smallest right singular vector
    of its rows. The pixels are undistorted once per camera and the keypoints with the
    same number of rows solved in one batched SVD.

    Returns:
        (indices (m,), world points (m, 3)) of the keypoints that triangulate in
        front of all their cameras.
    """
    normalised = np.empty((len(obs), 2))
    for c, camera in enumerate(obs.cameras):
        rows = obs.camera_index == c
        if rows.any():
            normalised[rows] = camera.undistort_pixels(obs.uv[rows])
    P = np.concatenate([obs._R_cw, obs._t_cw[:, :, None]], axis=2)  # (n, 3, 4) camera_T_world[:3] of each observation
    w = obs.sqrt_information[:, 0, 0, None]
    A = np.stack([w * (normalised[:, :1] * P[:, 2] - P[:, 0]), w * (normalised[:, 1:] * P[:, 2] - P[:, 1])], axis=1)
    groups: dict[int, list] = {}
    for k in np.unique(obs.keypoint_index):
        rows = np.flatnonzero(obs.keypoint_index == k)
        if len(set(obs.camera_index[rows])) >= min_views:
            groups.setdefault(len(rows), []).append((k, rows))
    indices, points = [], []
    for count, members in sorted(groups.items()):
        rows = np.array([r for _, r in members])  # (m, count)
        _, _, Vt = np.linalg.svd(A[rows].reshape(len(members), 2 * count, 4))
        X = Vt[:, -1]
        for (k, r), x in zip(members, X):
            if abs(x[3]) < 1e-12:
                continue
            x = x[:3] / x[3]
            if np.all(obs._R_cw[r, 2] @ x + obs._t_cw[r, 2] > 0):  # in front of each of its cameras
                indices.append(k)
                points.append(x)
    order = np.argsort(indices, kind="stable")
    return np.array(indices, dtype=int)[order], np.array(points).reshape(-1, 3)[order]


def cross_projection_cost(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, wireframe: Wireframe, loss: RobustLoss) -> float:
    """Robust cost ``sum rho(|e_i|)`` of the projections of ``wireframe`` at a pose in every camera."""
    return float(robust_costs(obs, world_T_vehicle.matrix()[None], wireframe.vehicle_p_keypoints[None], loss)[0])


def _world_pose(world_T_camera: gtsam.Pose3, rvec, tvec) -> gtsam.Pose3 | None:
    """world_T_vehicle from OpenCV's camera_T_vehicle (``rvec``, ``tvec``); None when not finite or not in front."""
    camera_T_vehicle = np.eye(4)
    camera_T_vehicle[:3, :3] = cv2.Rodrigues(rvec)[0]
    camera_T_vehicle[:3, 3] = np.ravel(tvec)
    if not np.all(np.isfinite(camera_T_vehicle)) or camera_T_vehicle[2, 3] <= 0:
        return None
    return world_T_camera.compose(gtsam.Pose3(camera_T_vehicle))


@dataclass(frozen=True)
class _PnPFits:
    """One camera's SQPnP fits (:func:`_sqpnp`) and what RANSAC (:func:`_ransac_pnp`) needs of them.

    Attributes:
        poses: per labelling its SQPnP pose (world_T_vehicle; none where it failed).
        within: per labelling the points its fit keeps within the threshold (-1 without a fit).
        labellings: per labelling the (n, 3) body-frame points its labels name.
        img, K, dist: :meth:`vfactor.camera.Camera.pnp_inputs` of the keypoints.
        threshold: the inlier threshold in the units of ``img``.
        world_T_camera: the camera's pose.
    """

    poses: list
    within: list
    labellings: tuple
    img: np.ndarray
    K: np.ndarray
    dist: np.ndarray | None
    threshold: float
    world_T_camera: gtsam.Pose3


def _sqpnp(camera, world_T_camera: gtsam.Pose3, labellings, image_uv, threshold_px) -> _PnPFits:
    """SQPnP poses (world_T_vehicle) of one camera's keypoints under each labelling of them, each fitted on every
    point. Each labelling is the (n, 3) body-frame points its labels name, seen at ``image_uv`` (n, 2 pixels)."""
    img, K, dist, px_per_unit = camera.pnp_inputs(image_uv)  # a fisheye lens: normalised points, identity K
    threshold = threshold_px / px_per_unit
    poses, within = [], []
    for object_p in labellings:
        obj = object_p.astype(np.float64)
        found, kept = [], -1
        try:
            ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_SQPNP)
            pose = _world_pose(world_T_camera, rvec, tvec) if ok else None
            if pose is not None:
                found.append(pose)
                projected, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
                kept = int(np.sum(np.linalg.norm(projected.reshape(-1, 2) - img, axis=1) <= threshold))
        except cv2.error:
            pass
        poses.append(found)
        within.append(kept)
    return _PnPFits(poses, within, labellings, img, K, dist, threshold, world_T_camera)


def _ransac_pnp(fits: _PnPFits, every_labelling: bool = False) -> list[list[gtsam.Pose3]]:
    """RANSAC PnP poses (EPnP, the threshold of the SQPnP ``fits``; 6 points or more) per labelling.

    RANSAC runs only where the SQPnP fit leaves some point beyond the threshold (with every point within it RANSAC
    would keep them all: the same fit), and only for the labellings whose SQPnP fit keeps the most points within
    it: RANSAC looks for the outliers of the labelling the keypoints favour, the others keep their SQPnP pose
    (``every_labelling``: RANSAC for each labelling whose fit leaves a point out).
    """
    out = []
    for object_p, kept in zip(fits.labellings, fits.within):
        found = []
        if len(object_p) >= 6 and kept < len(object_p) and (every_labelling or kept == max(fits.within)):
            ok, rvec, tvec, _ = cv2.solvePnPRansac(
                object_p.astype(np.float64), fits.img, fits.K, fits.dist, iterationsCount=200,
                reprojectionError=fits.threshold, confidence=0.999, flags=cv2.SOLVEPNP_EPNP,
            )
            pose = _world_pose(fits.world_T_camera, rvec, tvec) if ok else None
            if pose is not None:
                found.append(pose)
        out.append(found)
    return out


class StartSearch:
    """The pose starts of one vehicle's keypoints (:func:`best_candidates`), each kind made once.

    PnP runs on every camera that sees at least ``min_keypoints_in_one_view`` keypoints (4 at the least), with the
    labels as given and mirrored, each pose also turned by half a turn; triangulation needs 4 keypoints seen twice.
    SQPnP and triangulation are made with the search; RANSAC PnP (:func:`_ransac_pnp`) when a call first asks for
    it, so that a caller that tries the cheap starts first and RANSAC's only where they do not do pays for the
    cheap ones once (the one-frame solve's further starts, the tracker's prediction check).
    """

    def __init__(self, obs: KeypointObservations, wireframe: Wireframe, loss: RobustLoss,
                 min_keypoints_in_one_view: int = 4, ransac_every_labelling: bool = False):
        self.obs, self.wireframe, self.loss, self.every_labelling = obs, wireframe, loss, ransac_every_labelling
        points = wireframe.vehicle_p_keypoints
        sigma = 1.0 / np.abs(obs.sqrt_information[:, 0, 0])
        self._cameras = []  # (camera name, its SQPnP fits)
        for c, camera in enumerate(obs.cameras):
            rows = np.flatnonzero(obs.camera_index == c)
            if len(rows) < max(4, min_keypoints_in_one_view):
                continue
            labels = obs.keypoint_index[rows]
            labellings = (points[labels], points[MIRROR_PERMUTATION[labels]])
            self._cameras.append((camera.name, _sqpnp(camera, camera.pose, labellings, obs.uv[rows],
                                                      float(3.0 * np.median(sigma[rows])))))
        self._ransac: list | None = None  # per camera, per labelling: RANSAC's poses, once made
        self._triangulated = None
        idx, world = triangulate_keypoints(obs)
        if len(idx) >= 4:
            R, t, s = umeyama(points[idx], world, with_scale=True)
            if 0.6 < s < 1.6:
                self._triangulated = (gtsam.Pose3(gtsam.Rot3(R), t), wireframe.scaled(s), "triangulation")

    def candidates(self, ransac: bool = True) -> list[tuple[gtsam.Pose3, Wireframe, str]]:
        """Every (pose, wireframe, source) start, unscored: per camera and labelling SQPnP's pose, then RANSAC's
        (``ransac``), each also turned; then the triangulation's."""
        if ransac and self._ransac is None:
            self._ransac = [_ransac_pnp(fits, self.every_labelling) for _, fits in self._cameras]
        out = []
        flip = gtsam.Pose3(gtsam.Rot3.Yaw(np.pi), np.zeros(3))
        for c, (name, fits) in enumerate(self._cameras):
            for j, tag in enumerate(("pnp", "pnp-mirrored")):
                for pose in fits.poses[j] + (self._ransac[c][j] if ransac else []):
                    out.append((pose, self.wireframe, f"{tag}:{name}"))
                    out.append((pose.compose(flip), self.wireframe, f"{tag}-turned:{name}"))
        if self._triangulated is not None:
            out.append(self._triangulated)
        return out

    def best(self, count: int | None = 2, ransac: bool = True, min_angle_rad: float = 0.35,
             min_distance_m: float = 1.0) -> list[Candidate]:
        """The ``count`` lowest-cost upright candidates (None: all) that differ by at least the given angle or
        distance, best first (upright: the body's z axis within 90 degrees of the world's); ``ransac=False``:
        without the RANSAC PnP poses, a fraction of the cost."""
        found = self.candidates(ransac)
        if not found:
            return []
        T = np.array([pose.matrix() for pose, _, _ in found])
        costs = robust_costs(self.obs, T, np.array([w.vehicle_p_keypoints for _, w, _ in found]), self.loss)
        chosen: list[Candidate] = []
        finite = np.isfinite(costs) & upright(T)
        keep = finite.copy()  # finite and distinct from every candidate chosen so far
        for i in np.argsort(np.where(finite, costs, np.inf), kind="stable"):
            if not finite[i]:
                break
            if not keep[i]:
                continue
            pose, w, source = found[i]
            chosen.append(Candidate(pose, w, float(costs[i]), source))
            if len(chosen) == count:
                break
            keep &= _distinct(T[:, :3, :3], T[:, :3, 3], T[i, :3, :3], T[i, :3, 3], min_angle_rad, min_distance_m)
        return chosen


def pose_candidates(
    obs: KeypointObservations, wireframe: Wireframe, min_keypoints_in_one_view: int = 4, ransac: bool = True,
    ransac_every_labelling: bool = False,
) -> list[tuple[gtsam.Pose3, Wireframe, str]]:
    """All candidate (pose, wireframe, source) starts for one vehicle, unscored (:meth:`StartSearch.candidates`).
    ``ransac=False``: SQPnP alone; ``ransac_every_labelling``: RANSAC for both labellings, not only the one the
    keypoints favour."""
    search = StartSearch(obs, wireframe, RobustLoss(), min_keypoints_in_one_view, ransac_every_labelling)
    return search.candidates(ransac)


def distinct_poses(a: gtsam.Pose3, b: gtsam.Pose3, min_angle_rad: float = 0.35, min_distance_m: float = 1.0) -> bool:
    """Whether two vehicle poses differ by more than ``min_angle_rad`` (rotation) or ``min_distance_m`` (translation)."""
    return bool(_distinct(a.rotation().matrix()[None], a.translation()[None], b.rotation().matrix(), b.translation(),
                          min_angle_rad, min_distance_m)[0])


def _distinct(R, t, R_other, t_other, min_angle_rad, min_distance_m) -> np.ndarray:
    """(K,) whether each of K poses (rotations (K, 3, 3), translations (K, 3)) differs from one other pose."""
    cos_angle = 0.5 * (np.einsum("kij,ij->k", R, R_other) - 1.0)  # cos of the angle of R^T R_other
    angle = np.arccos(np.clip(cos_angle, -1.0, 1.0))
    return (angle > min_angle_rad) | (np.linalg.norm(t - t_other, axis=1) > min_distance_m)


def best_candidates(
    obs: KeypointObservations, wireframe: Wireframe, loss: RobustLoss, count: int | None = 2,
    min_angle_rad: float = 0.35, min_distance_m: float = 1.0, min_keypoints_in_one_view: int = 4, ransac: bool = True,
    ransac_every_labelling: bool = False,
) -> list[Candidate]:
    """The ``count`` lowest-cost upright starts (None: all) that differ by at least the given angle or distance, best
    first (:meth:`StartSearch.best`; a caller that may ask twice, without RANSAC and then with it, keeps one
    :class:`StartSearch`).

    ``ransac=False``: without the RANSAC PnP poses, a fraction of the cost;
    ``ransac_every_labelling``: RANSAC for both labellings of each camera.
    """
    return StartSearch(obs, wireframe, loss, min_keypoints_in_one_view, ransac_every_labelling).best(
        count, ransac, min_angle_rad, min_distance_m)


#: :func:`own_pose` keeps the poses of the last this many views it fitted. One detection is fitted again in every
#: hypothesis the association solves it in (its pairs, groups and joins): in three frames of 30 vehicles seen by three
#: cameras (``benchmarks/association_time.py``), 1,414 fits of 194 distinct views, a fifth of the association's time.
OWN_POSE_MEMO = 4096
_own_poses: OrderedDict[bytes, gtsam.Pose3 | None] = OrderedDict()
_own_poses_lock = threading.Lock()


def own_pose(obs: KeypointObservations, camera: int, wireframe: Wireframe, loss: RobustLoss) -> gtsam.Pose3 | None:
    """A camera's own pose of ``wireframe`` from its keypoints alone (world_T_vehicle; None where no upright one is
    found): the best start of :func:`best_candidates` with RANSAC under both labellings, as the check of cameras at
    odds fits each camera (:func:`vfactor.solve.solve_observations`). Both labellings, as before issue 14: with only
    the one its plain fit favours, a wrong camera's own fit kept fewer of its keypoints and the check caught 88 % of
    cameras rotated by 20 degrees instead of 98 % (benchmarks/disagreement_check.py).

    The fit is deterministic (OpenCV's RANSAC draws from a fixed seed), so it is kept by its inputs (the camera, its
    keypoints, their sigmas and truncation windows, the wireframe and the loss; :data:`OWN_POSE_MEMO`) and the same
    view is fitted once however many solves check it.

    Args:
        obs: the vehicle's observations (every camera's; those of ``camera`` are fitted).
        camera: index of the camera in ``obs.cameras``.
        wireframe: the shape to place (body frame, metres).
        loss: the robust loss that scores the starts.
    """
    rows = obs.camera_index == camera
    mine, cam = obs.subset(rows), obs.cameras[camera]
    digest = hashlib.blake2b(digest_size=20)
    digest.update(f"{cam.name}|{cam.model}|{loss.name}|{loss.threshold!r}|".encode())
    for array in (cam.K, cam.world_T_camera, cam.dist, mine.uv, mine.keypoint_index, mine.sqrt_information,
                  mine._window_table, mine._sigma_table, wireframe.vehicle_p_keypoints):  # all the fit reads
        digest.update(b"-" if array is None else np.ascontiguousarray(array).tobytes() + b"|")
    key = digest.digest()
    with _own_poses_lock:
        if key in _own_poses:
            _own_poses.move_to_end(key)
            return _own_poses[key]
    found = best_candidates(mine, wireframe, loss, 1, ransac_every_labelling=True)
    pose = found[0].world_T_vehicle if found else None
    with _own_poses_lock:
        _own_poses[key] = pose
        while len(_own_poses) > OWN_POSE_MEMO:
            _own_poses.popitem(last=False)
    return pose
