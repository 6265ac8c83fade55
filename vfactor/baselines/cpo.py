"""Baseline: the paper's Cross Projection Optimisation with the Hierarchical Wireframe Constraint.

Section III-B of Ding et al., implemented as written, for two or more cameras
(the paper writes it for two, camera ``i`` and the other camera ``j``; with
more, the ``j`` terms are averaged over the other cameras). Equation numbers
are those of paper.tex. Every choice where the paper is silent or ambiguous is
listed in docs/baselines.md. In brief:

1. **Initial weights** (Eq. 2-3): ``psi_i^k = mu1 w_i^k + mu2 (w_i^k - w_j^k)``
   from the keypoints' confidences (the heatmap peaks), floored and normalised
   over the keypoints camera ``i`` sees: the diagonal ``W_i``, the weights of
   camera ``i``'s detections.
2. **Models.** Each camera ``i`` that sees 4 or more keypoints keeps its own
   model pose ``P_i``, started by PnP (SQPnP) of the mean wireframe in that
   camera alone; the wireframe is shared.
3. **One iteration.** (a) Single-camera step (Eq. 4), a few times: ``q_k`` is
   the point of keypoint ``k``'s viewing ray in camera ``i`` closest to the
   model point ``P_i p_k``, and ``P_i`` becomes the weighted rigid alignment
   (Umeyama, no scale) of ``p_k`` to ``q_k`` with weights ``W_i`` (the
   object-space iteration of Lu, Hager and Mjolsness). (b) Cross projection
   (Eq. 5): ``f_i = 1/2 sum_j ||L_ij||^2_W`` is decreased by
   Levenberg-Marquardt steps on ``P_i``; ``L_ij`` is model ``i``'s reprojection
   error in image ``j`` in units of the vehicle's size in that image, each
   detection weighed by its own weight (image ``j``'s rows by ``W_j``; the
   literal ``W_i`` on all of model ``i``'s rows is ``weighting="model"``).
   (c) Weight update (Eq. 6), on the weights ``w`` whose normalised values
   ``w_nor`` fill ``W``: ``w_j^k <- mu1 w_j^k + mu2 ||L_ij^k||^2 +
   mu3 (w_j,nor^k - w_i,nor^k)`` with ``L_ij^k`` the cross projection error
   of keypoint ``k`` into image ``j`` (of the other camera's model ``i``),
   ``mu1 = 1``, ``mu2 < 0``, clipped at 0, normalised and floored: a
   detection the models keep projecting badly (an outlier, a swapped label)
   loses its weight, the paper's only outlier handling.
4. **Pure pose first**, until the energy ``f = sum_i f_i`` changes by less
   than ``smooth_tol`` (relative) between iterations; then an HWC step after
   every iteration.
5. **HWC** (Eq. 7 and the four rules of Section III-B): every keypoint moves
   toward the point that minimises Eq. (4) over the point itself, i.e. the
   point nearest to all its viewing rays, the rays weighted by keypoint weight
   over projection error (Eq. 7's weights, ``i, j`` the cameras); each layer is
   then made symmetric by the weighted average of its left and right points
   (Eq. 7 read with ``i, j`` the two sides), which also makes it planar,
   perpendicular to the medial plane and a trapezoid (front and back edges
   parallel); the wheel layer is made a rectangle and the light and roof width
   ratios are clipped to the HWC ranges; no point moves more than
   ``max_step_m``, and a layer step that would break a point-to-point distance
   or layer-offset bound is halved (up to 4 times) or dropped. The body frame
   is then re-centred on the wheel hubs, hubs level (poses compensated).
6. **Stop** at ``max_iterations`` or when, in the shape phase, the energy
   changes by less than ``tol`` and no point moved more than ``shape_tol``.
   The model with the smaller projection error over all images (each
   detection weighed by its final weight) wins; with the detections' weights
   in every model's energy the models agree (the paper: "in most instances,
   optimized results from two cameras are almost the same").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from vfactor.baselines.pnp import box_diagonals, camera_pnp, clean_observations, usable
from vfactor.errors import check_numbers
from vfactor.factors.projection import KeypointObservations, project_keypoints, whitened_residuals
from vfactor.graph import GraphConfig
from vfactor.init import umeyama
from vfactor.keypoints import LAYER_NAMES, LAYERS, NUM_KEYPOINTS
from vfactor.result import Status, VehicleResult
from vfactor.shape_model import DISTANCE_PAIRS, HwcBounds, car_hwc_bounds, default_shape_prior
from vfactor.wireframe import Wireframe

__all__ = ["CpoOptions", "cpo", "observation_confidence", "hwc_projection"]

_MIN_RAY_DEPTH = 0.1  # metres; q_k is never placed closer to a camera than this
_MIN_HALF_WIDTH = 0.1  # metres; a layer's half width never drops below this
_RAY_REGULARISER = 1e-3  # pull toward the current point along a single ray (or nearly parallel rays)


@dataclass(frozen=True)
class CpoOptions:
    """Settings of :func:`cpo` (the paper gives no values; these are ours, docs/baselines.md).

    Attributes:
        mu_init: ``(mu1, mu2)`` of the initial weights, Eq. (2).
        mu_update: ``(mu1, mu2, mu3)`` of the weight update, Eq. (6); ``mu2 < 0``
            lowers the weight of a keypoint that is projected badly (the sign is
            not given in the paper).
        weighting: ``"image"``: image ``j``'s residuals are weighed by ``W_j``,
            the weights of the keypoints detected in image ``j``, in every
            model's energy (Eq. 5), and ``w_j^k`` is updated from the cross
            projection error of keypoint ``k`` into image ``j`` (Eq. 6).
            ``"model"``: Eq. (5)'s subscript taken literally, ``W_i`` weighs all
            of model ``i``'s residuals and ``w_i^k`` is updated from model
            ``i``'s errors in the other images (the reading used before; its
            two models disagree and the worse one is often picked).
        weight_state: ``"raw"``: Eq. (6) updates the weights ``w`` and ``W`` holds
            their normalised values ``w_nor`` (the equation names both);
            ``"normalised"``: the update acts on ``w_nor`` itself, renormalised
            every iteration (with ``mu2 < 0`` a winner-take-all dynamic).
        weight_floor: no weight drops below this fraction of the uniform weight ``1/K``.
        max_iterations: iteration limit (pose and shape phases together).
        min_pose_iterations, max_pose_iterations: length of the pure-pose phase.
        smooth_tol: relative change of the energy that ends the pure-pose phase.
        tol: relative change of the energy that, with ``shape_tol``, stops the process.
        abs_tol: energy below which it counts as unchanged (noise-free data).
        shape_tol: largest keypoint move (m) in an iteration that counts as unchanged.
        single_camera_steps: object-space alignment steps per camera per iteration, Eq. (4).
        cross_steps: Levenberg-Marquardt steps on each model's cross energy per
            iteration, Eq. (5) (0: the models are coupled only through the weights and the shape).
        hwc: adjust the shape (False: CPO with the mean wireframe only).
        max_step_m: largest move of a keypoint per iteration, metres.
        projection_eps: added to the projection error in the HWC merge weights
            ``w / (eps + |L|)``, in units of the vehicle's image size.
        min_keypoints_per_camera: a camera seeing fewer keypoints gets no model of
            its own (its keypoints still enter the energy and the shape).
        min_observations: fewer observations in all make the result ``degenerate``.
        mean: starting wireframe (default: the prior's mean).
        bounds: HWC ranges (default :func:`vfactor.shape_model.car_hwc_bounds`: the paper's car-learnt bounds).
        graph: the noise settings the observations were made with; used only to
            recover the confidences from the square-root information.
    """

    mu_init: tuple[float, float] = (1.0, 0.5)
    mu_update: tuple[float, float, float] = (1.0, -0.1, 0.01)
    weighting: str = "image"
    weight_state: str = "raw"
    weight_floor: float = 0.05
    max_iterations: int = 30
    min_pose_iterations: int = 3
    max_pose_iterations: int = 15
    smooth_tol: float = 0.01
    tol: float = 1e-6
    abs_tol: float = 1e-14
    shape_tol: float = 1e-5
    single_camera_steps: int = 2
    cross_steps: int = 3
    hwc: bool = True
    max_step_m: float = 0.02
    projection_eps: float = 0.01
    min_keypoints_per_camera: int = 4
    min_observations: int = 6
    mean: Wireframe | None = None
    bounds: HwcBounds | None = None
    graph: GraphConfig = field(default_factory=GraphConfig)

    def __post_init__(self):
        if len(self.mu_init) != 2 or len(self.mu_update) != 3:
            raise ValueError(f"CpoOptions.mu_init / mu_update: expected 2 and 3 numbers, got {self.mu_init!r}, {self.mu_update!r}")
        if not all(np.isfinite(v) for v in (*self.mu_init, *self.mu_update)):
            raise ValueError("CpoOptions.mu_init / mu_update: expected finite numbers")
        if self.mu_init[0] <= 0 or self.mu_update[0] < 0:
            raise ValueError(f"CpoOptions.mu_init / mu_update: mu1 must be positive (mu_update's may be 0), "
                             f"got mu_init={self.mu_init!r}, mu_update={self.mu_update!r}")
        check_numbers("CpoOptions", self,
                      ("weight_floor", "smooth_tol", "tol", "abs_tol", "shape_tol", "max_step_m", "projection_eps"))
        for name in ("max_iterations", "min_pose_iterations", "max_pose_iterations", "single_camera_steps", "cross_steps",
                     "min_keypoints_per_camera", "min_observations"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 0:
                raise ValueError(f"CpoOptions.{name}: expected a non-negative integer, got {value!r}")
        if self.weighting not in ("image", "model"):
            raise ValueError(f"CpoOptions.weighting: expected 'image' or 'model', got {self.weighting!r}")
        if self.weight_state not in ("raw", "normalised"):
            raise ValueError(f"CpoOptions.weight_state: expected 'raw' or 'normalised', got {self.weight_state!r}")
        if self.max_iterations < 1:
            raise ValueError(f"CpoOptions.max_iterations: expected at least 1, got {self.max_iterations}")
        if self.min_keypoints_per_camera < 3:
            raise ValueError(f"CpoOptions.min_keypoints_per_camera: expected at least 3, got {self.min_keypoints_per_camera}")


def observation_confidence(obs: KeypointObservations, graph: GraphConfig = GraphConfig()) -> np.ndarray:
    """(n,) confidence of every observation, recovered from its square-root information.

    :func:`vfactor.graph.observations_from_detections` sets ``L = conf / sigma``
    with ``sigma = max(min_pixel_sigma, relative_pixel_sigma * box_diagonal)``
    and the box around the detection's seen keypoints, which are that camera's
    rows here; so ``conf = L[0, 0] * sigma`` exactly for detections without a
    ROI or covariance (otherwise approximately), clipped to ``(0, 1]``.
    """
    sigma = np.maximum(graph.min_pixel_sigma, graph.relative_pixel_sigma * box_diagonals(obs))
    conf = np.abs(obs.sqrt_information[:, 0, 0]) * sigma[obs.camera_index]
    return np.clip(conf, 1e-6, 1.0)


# --------------------------------------------------------------------------- geometry helpers
def _rays(obs: KeypointObservations) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres (n, 3) and unit viewing directions (n, 3) of every observation, world frame."""
    origins = np.empty((len(obs), 3))
    dirs = np.empty((len(obs), 3))
    for c, cam in enumerate(obs.cameras):
        rows = np.flatnonzero(obs.camera_index == c)
        if len(rows) == 0:
            continue
        xy = cam.undistort_pixels(obs.uv[rows])
        d = np.column_stack([xy, np.ones(len(rows))]) @ cam.world_T_camera[:3, :3].T
        dirs[rows] = d / np.linalg.norm(d, axis=1, keepdims=True)
        origins[rows] = cam.center
    return origins, dirs


def _closest_on_rays(points: np.ndarray, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """The point of each ray closest to each point (never nearer the camera than ``_MIN_RAY_DEPTH``)."""
    s = np.maximum(np.einsum("ni,ni->n", points - origins, dirs), _MIN_RAY_DEPTH)
    return origins + s[:, None] * dirs


def _transform(pose: gtsam.Pose3, p: np.ndarray) -> np.ndarray:
    T = pose.matrix()
    return p @ T[:3, :3].T + T[:3, 3]


def _inverse_transform(pose: gtsam.Pose3, p: np.ndarray) -> np.ndarray:
    T = pose.matrix()
    return (p - T[:3, 3]) @ T[:3, :3]


# --------------------------------------------------------------------------- the algorithm
class _Problem:
    """Observations in the form the iterations use."""

    def __init__(self, obs: KeypointObservations, confidence: np.ndarray):
        self.obs = obs
        self.num_cameras = len(obs.cameras)
        self.boxes = box_diagonals(obs)
        self.scale = self.boxes[obs.camera_index]
        self.origins, self.dirs = _rays(obs)
        C = self.num_cameras
        self.conf = np.zeros((C, NUM_KEYPOINTS))  # w_cnn of (camera, keypoint); 0 where unseen
        self.seen = np.zeros((C, NUM_KEYPOINTS), dtype=bool)
        self.conf[obs.camera_index, obs.keypoint_index] = confidence
        self.seen[obs.camera_index, obs.keypoint_index] = True

    def residuals(self, pose: gtsam.Pose3, shape: np.ndarray, jacobians: bool = False):
        """Relative reprojection errors (n, 2) of a model in every image (and d/d pose, (n, 2, 6))."""
        uv, _, J_pose, _ = project_keypoints(self.obs, pose, shape, jacobians)
        r = (uv - self.obs.uv) / self.scale[:, None]
        return (r, J_pose / self.scale[:, None, None]) if jacobians else (r, None)

    def others_mean(self, table: np.ndarray) -> np.ndarray:
        """Per camera i and keypoint k, the mean of ``table[j, k]`` over the other cameras j."""
        C = self.num_cameras
        return (table.sum(0, keepdims=True) - table) / max(C - 1, 1)


def _normalise(w: np.ndarray, seen: np.ndarray, floor: float) -> np.ndarray:
    """Floors the weights of seen keypoints at ``floor / K`` (of the total) and normalises each row."""
    w = np.where(seen, w, 0.0)
    out = np.zeros_like(w)
    for i in range(len(w)):
        if not seen[i].any():
            continue
        row = np.where(seen[i], np.maximum(w[i], 0.0), 0.0)
        total = row.sum()
        row = row / total if total > 0 else seen[i] / seen[i].sum()
        row = np.where(seen[i], np.maximum(row, floor / NUM_KEYPOINTS), 0.0)
        out[i] = row / row.sum()
    return out


def _row_weights(problem: _Problem, w_nor: np.ndarray, i: int, weighting: str = "image") -> np.ndarray:
    """Weight of every observation (camera j, keypoint k) in model i's cross energy, Eq. (5).

    ``"image"``: ``W_j[k]``, the weight of that detection (the same for every
    model). ``"model"``: ``W_i[k]``; a keypoint camera ``i`` does not see has
    no entry in ``W_i``, and its rows take the weight of the camera that
    observed them (``W_j[k]``).
    """
    c, k = problem.obs.camera_index, problem.obs.keypoint_index
    if weighting == "image":
        return w_nor[c, k]
    own = w_nor[i, k]
    return np.where(problem.seen[i, k], own, w_nor[c, k])


def _single_camera_step(problem: _Problem, pose: gtsam.Pose3, shape: np.ndarray, w_nor: np.ndarray, i: int) -> gtsam.Pose3:
    """Eq. (4): rigid alignment of the model points to their closest points on camera i's rays."""
    rows = np.flatnonzero(problem.obs.camera_index == i)
    k = problem.obs.keypoint_index[rows]
    q = _closest_on_rays(_transform(pose, shape[k]), problem.origins[rows], problem.dirs[rows])
    R, t, _ = umeyama(shape[k], q, weights=w_nor[i, k], with_scale=False)
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        return pose
    return gtsam.Pose3(gtsam.Rot3(R), t)


def _cross_energy(r: np.ndarray, weights: np.ndarray) -> float:
    return 0.5 * float(np.sum(weights * np.sum(r * r, axis=1)))


def _projection_error(problem: _Problem, r: np.ndarray, w_nor: np.ndarray) -> float:
    """A model's projection error over all images: the RMS relative error, each detection weighed by its ``W_j[k]``.

    The weights are those of the detections (the same for every model), so the
    models' errors are comparable, and a keypoint the weights have given up on
    (an outlier, a swapped label) does not decide which model wins.
    """
    w = w_nor[problem.obs.camera_index, problem.obs.keypoint_index]
    total = float(w.sum())
    if not total > 0:
        return float(np.sqrt(np.mean(np.sum(r * r, axis=1))))
    return float(np.sqrt(np.sum(w * np.sum(r * r, axis=1)) / total))


def _weight_update_errors(problem: _Problem, residuals: dict, model_cams: list[int], weighting: str) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (6)'s ``||L||^2`` term per (camera, keypoint), and which rows get updated.

    ``"image"``: for camera ``j``'s detection of keypoint ``k``, the squared
    relative error of the cross projection into image ``j``: the mean over the
    other cameras' models (over all models where ``j`` has none of the others';
    with two cameras, ``||L_ij^k||^2`` of the other model ``i``). Every camera's
    row is updated, with or without a model of its own. ``"model"``: for model
    ``i``, the mean over the other images ``j`` that see ``k`` of ``||L_ij^k||^2``;
    only model cameras' rows are updated.
    """
    obs = problem.obs
    C = problem.num_cameras
    tables = {}
    for i in model_cams:
        table = np.zeros((C, NUM_KEYPOINTS))
        table[obs.camera_index, obs.keypoint_index] = np.sum(residuals[i] ** 2, axis=1)
        tables[i] = table
    cross = np.zeros((C, NUM_KEYPOINTS))
    if weighting == "image":
        for j in range(C):
            models = [i for i in model_cams if i != j] or list(model_cams)
            cross[j] = np.mean([tables[i][j] for i in models], axis=0)
        return cross, np.ones(C, dtype=bool)
    for i in model_cams:
        other = problem.seen & (np.arange(C)[:, None] != i)
        n_other = other.sum(0)
        cross[i] = np.where(n_other > 0, (tables[i] * other).sum(0) / np.maximum(n_other, 1), 0.0)
    return cross, np.isin(np.arange(C), model_cams)


def _cross_steps(problem: _Problem, pose: gtsam.Pose3, shape: np.ndarray, weights: np.ndarray, steps: int) -> gtsam.Pose3:
    """Eq. (5): Levenberg-Marquardt steps on one model's cross energy ``1/2 sum_j ||L_ij||^2_W`` (``weights`` per row)."""
    lam = 1e-3
    r, J = problem.residuals(pose, shape, jacobians=True)
    cost = _cross_energy(r, weights)
    for _ in range(steps):
        Jw = J * np.sqrt(weights)[:, None, None]
        rw = r * np.sqrt(weights)[:, None]
        A = np.einsum("nai,naj->ij", Jw, Jw)
        g = np.einsum("nai,na->i", Jw, rw)
        accepted = False
        for _ in range(8):
            try:
                xi = -np.linalg.solve(A + lam * (np.diag(np.diag(A)) + 1e-12 * np.eye(6)), g)
            except np.linalg.LinAlgError:
                return pose
            candidate = pose.retract(xi)
            r_new, J_new = problem.residuals(candidate, shape, jacobians=True)
            cost_new = _cross_energy(r_new, weights)
            if np.isfinite(cost_new) and cost_new <= cost:
                pose, r, J, cost = candidate, r_new, J_new, cost_new
                lam = max(lam / 10, 1e-9)
                accepted = True
                break
            lam *= 10
        if not accepted:
            break
    return pose


def _layer_points(front, back) -> np.ndarray:
    (xf, zf, hf), (xb, zb, hb) = front, back
    return np.array([[xf, hf, zf], [xf, -hf, zf], [xb, hb, zb], [xb, -hb, zb]])


def _bounds_ok(candidate: np.ndarray, current: np.ndarray, bounds: HwcBounds) -> bool:
    """True when ``candidate`` breaks no distance or layer-offset bound that ``current`` keeps (and worsens none it breaks).

    The offsets are measured in the hub-centred, level body frame the shape is put in after the step.
    """
    def violations(p):
        p = _inverse_transform(_body_frame(p), p)
        d = np.linalg.norm(p[DISTANCE_PAIRS[:, 0]] - p[DISTANCE_PAIRS[:, 1]], axis=1)
        v = [np.maximum(bounds.distance[:, 0] - d, 0) + np.maximum(d - bounds.distance[:, 1], 0)]
        wheel = p[list(LAYERS["wheel"])].mean(0)
        for name, box in bounds.layer_offset.items():
            off = (p[list(LAYERS[name])].mean(0) - wheel)[[0, 2]]
            v.append(np.maximum(box[:, 0] - off, 0) + np.maximum(off - box[:, 1], 0))
        return np.concatenate(v)

    return bool(np.all(violations(candidate) <= violations(current) + 1e-9))


def _hwc_layer(name: str, target: np.ndarray, weight: np.ndarray, fallback: np.ndarray, bounds: HwcBounds) -> np.ndarray:
    """A layer's four points (lf, rf, lb, rb) made to obey the HWC rules.

    Each left/right pair becomes symmetric by Eq. (7) with ``i, j`` the two
    sides: ``x`` and ``z`` are the weighted averages of the two points', the half
    width the weighted average of ``y_left`` and ``-y_right`` (a pair with no
    weight keeps ``fallback``). Both edges are then parallel to the body y axis,
    so the layer is planar, perpendicular to the medial plane and a trapezoid;
    the wheel layer gets one width (a rectangle), the others a front/back width
    ratio clipped to ``bounds.width_ratio``.
    """
    edges, edge_weights = [], []
    for left, right in ((0, 1), (2, 3)):
        total = weight[left] + weight[right]
        if total > 0:
            wl, wr = weight[left] / total, weight[right] / total
            tl, tr = target[left], target[right]
        else:
            wl = wr = 0.5
            tl, tr = fallback[left], fallback[right]
        x = wl * tl[0] + wr * tr[0]
        z = wl * tl[2] + wr * tr[2]
        h = max(wl * tl[1] - wr * tr[1], _MIN_HALF_WIDTH)
        edges.append(np.array([x, z, h]))
        edge_weights.append(total)
    (front, back), (bf, bb) = edges, edge_weights
    if name == "wheel":  # a rectangle: equal widths
        h = (bf * front[2] + bb * back[2]) / (bf + bb) if bf + bb > 0 else 0.5 * (front[2] + back[2])
        front[2] = back[2] = h
    else:  # a trapezoid whose width ratio stays in range
        lo, hi = bounds.width_ratio[name]
        ratio = front[2] / back[2]
        if not lo <= ratio <= hi:
            g = np.sqrt(front[2] * back[2])
            clipped = float(np.clip(ratio, lo * (1 + 1e-9), hi * (1 - 1e-9)))  # strictly inside, despite rounding
            front[2], back[2] = g * np.sqrt(clipped), g / np.sqrt(clipped)
    return _layer_points(front, back)


def hwc_projection(shape: np.ndarray, bounds: HwcBounds | None = None) -> np.ndarray:
    """(12, 3) ``shape`` made to obey the HWC rules layer by layer (equal left/right weights), hub-centred and level."""
    bounds = bounds or car_hwc_bounds()
    out = np.array(shape, dtype=float)
    for name in LAYER_NAMES:
        idx = list(LAYERS[name])
        out[idx] = _hwc_layer(name, out[idx], np.ones(4), out[idx], bounds)
    return _inverse_transform(_body_frame(out), out)


def _hwc_step(problem: _Problem, poses: dict, shape: np.ndarray, w_nor: np.ndarray, residuals: dict,
              options: CpoOptions, bounds: HwcBounds) -> np.ndarray:
    """One HWC shape adjustment; returns the new (symmetric) shape, not yet re-centred."""
    obs = problem.obs
    best_model = min(residuals, key=lambda i: _projection_error(problem, residuals[i], w_nor))
    pose = poses[best_model]
    current = _transform(pose, shape)
    # Eq. (4) minimised over each point, the cameras' rays merged with the Eq. (7) weights
    # (keypoint weight / projection error): argmin_x sum_c a_c |(I - d_c d_c^T)(x - o_c)|^2
    err = np.linalg.norm(residuals[best_model], axis=1)
    k = obs.keypoint_index
    a = w_nor[obs.camera_index, k] / (options.projection_eps + err)
    M = np.eye(3)[None] - problem.dirs[:, :, None] * problem.dirs[:, None, :]
    A = np.zeros((NUM_KEYPOINTS, 3, 3))
    b = np.zeros((NUM_KEYPOINTS, 3))
    weight = np.zeros(NUM_KEYPOINTS)
    np.add.at(A, k, a[:, None, None] * M)
    np.add.at(b, k, a[:, None] * np.einsum("nij,nj->ni", M, problem.origins))
    np.add.at(weight, k, a)
    seen = weight > 0
    target = shape.copy()
    if seen.any():
        reg = _RAY_REGULARISER * weight[seen]
        A_s = A[seen] + reg[:, None, None] * np.eye(3)[None]
        b_s = b[seen] + reg[:, None] * current[seen]
        target[seen] = _inverse_transform(pose, np.linalg.solve(A_s, b_s[:, :, None])[:, :, 0])

    new = shape.copy()
    for name in LAYER_NAMES:
        idx = list(LAYERS[name])
        current = shape[idx]
        if not seen[idx].any():
            continue
        proposed = _hwc_layer(name, target[idx], weight[idx], shape[idx], bounds)
        move = np.linalg.norm(proposed - current, axis=1).max()
        alpha = min(1.0, options.max_step_m / move) if move > 0 else 1.0
        for _ in range(5):
            layer = current + alpha * (proposed - current)
            candidate = new.copy()
            candidate[idx] = layer
            if _bounds_ok(candidate, new, bounds):
                new = candidate
                break
            alpha *= 0.5
    return new


def _body_frame(shape: np.ndarray) -> gtsam.Pose3:
    """``old_T_new``: the frame with its origin at the hub centroid and the hubs level (x forward)."""
    hubs = shape[list(LAYERS["wheel"])]
    centre = hubs.mean(0)
    forward = 0.5 * (hubs[0] + hubs[1]) - 0.5 * (hubs[2] + hubs[3])
    forward[1] = 0.0  # the shape is symmetric about y = 0: only pitch remains
    norm = np.linalg.norm(forward)
    if norm < 1e-9:
        return gtsam.Pose3(gtsam.Rot3(), centre)
    x = forward / norm
    y = np.array([0.0, 1.0, 0.0])
    z = np.cross(x, y)
    return gtsam.Pose3(gtsam.Rot3(np.column_stack([x, y, z])), centre)


def cpo(
    obs: KeypointObservations,
    options: CpoOptions = CpoOptions(),
    confidence: np.ndarray | None = None,
    vehicle_id: str = "vehicle",
) -> VehicleResult:
    """Pose and wireframe by Cross Projection Optimisation with the Hierarchical Wireframe Constraint.

    Args:
        obs: the vehicle's observations in all cameras (two or more needed).
        options: the algorithm's settings.
        confidence: (n,) heatmap peak value of every observation, in ``obs``'s
            order; default :func:`observation_confidence` (recovered from the
            square-root information with ``options.graph``).
        vehicle_id: id for the result.

    Returns:
        ``converged`` (stopped on small change) or ``max_iterations``, with
        ``iterations``, ``final_error`` (0.5 * sum of squared whitened residuals
        of the result over all cameras) and ``extras``: ``"camera"`` (whose model
        won), ``"energy"`` (the energy ``f`` after every iteration),
        ``"pose_iterations"``, ``"projection_error"`` (per model camera: RMS
        relative reprojection error over all images, each detection weighed by
        its final weight), ``"poses"`` (per model camera: its model's pose) and
        ``"weights"`` (per camera: the final normalised weights ``W``, (12,),
        0 where unseen). ``degenerate`` when fewer
        than two cameras see the vehicle, too few keypoints are seen, or no
        camera sees 4; ``failed`` when PnP finds no starting pose. Never raises
        on bad observations (bad ``confidence`` gives ``failed``).
    """
    mean = options.mean if options.mean is not None else Wireframe(default_shape_prior().mean)
    bounds = options.bounds or car_hwc_bounds()
    if confidence is not None:
        try:
            confidence = np.asarray(confidence, dtype=float).ravel()
        except (TypeError, ValueError):
            return VehicleResult(vehicle_id, Status.FAILED, message="cpo: confidence must be an array of numbers")
        if confidence.shape != (len(obs),) or not np.all(np.isfinite(confidence)) or np.any(confidence < 0):
            return VehicleResult(vehicle_id, Status.FAILED, message=(
                f"cpo: confidence must be {len(obs)} finite non-negative numbers, got shape {confidence.shape}"))
        confidence = confidence[usable(obs)]
    obs, dropped = clean_observations(obs)
    if len(obs) == 0:
        return VehicleResult(vehicle_id, Status.DEGENERATE, message="cpo: no observations")
    if len(obs) < options.min_observations:
        return VehicleResult(vehicle_id, Status.DEGENERATE,
                             message=f"cpo: {len(obs)} keypoint observations, need {options.min_observations}")
    counts = np.bincount(obs.camera_index, minlength=len(obs.cameras))
    if np.count_nonzero(counts) < 2:
        return VehicleResult(vehicle_id, Status.DEGENERATE,
                             message="cpo: cross projection needs keypoints from two or more cameras, got one camera")
    if confidence is None:
        confidence = observation_confidence(obs, options.graph)
    confidence = np.maximum(confidence, 1e-6)
    problem = _Problem(obs, confidence)
    model_cams = [c for c in range(len(obs.cameras)) if counts[c] >= options.min_keypoints_per_camera]
    if not model_cams:
        return VehicleResult(vehicle_id, Status.DEGENERATE,
                             message=f"cpo: no camera sees {options.min_keypoints_per_camera} keypoints (most: {int(counts.max())})")

    try:
        return _run(problem, model_cams, mean, options, bounds, vehicle_id, dropped)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:  # numerically hopeless input
        return VehicleResult(vehicle_id, Status.FAILED, message=f"cpo: {type(exc).__name__}: {exc}")


def _run(problem: _Problem, model_cams: list[int], mean: Wireframe, options: CpoOptions, bounds: HwcBounds,
         vehicle_id: str, dropped: int) -> VehicleResult:
    """The iterations of :func:`cpo` on validated input."""
    obs = problem.obs
    # Eq. (2)-(3): initial weights from the heatmap peaks
    mu1, mu2 = options.mu_init
    psi = mu1 * problem.conf + mu2 * (problem.conf - problem.others_mean(problem.conf))
    w_nor = _normalise(psi, problem.seen, options.weight_floor)
    w = w_nor.copy()  # Eq. (6)'s weights, started at the normalised Eq. (2) values; W holds their normalised values

    # Initial poses: per-camera PnP of the mean wireframe (a camera whose PnP fails takes another's);
    # the mean is first put into the hub-centred, level body frame and, with HWC, made to obey its rules
    shape = mean.vehicle_p_keypoints.copy()
    shape = hwc_projection(shape, bounds) if options.hwc else _inverse_transform(_body_frame(shape), shape)
    starts = {c: camera_pnp(obs, c, shape) for c in model_cams}
    found = [p for p in starts.values() if p is not None]
    if not found:
        return VehicleResult(vehicle_id, Status.FAILED, message="cpo: PnP found no starting pose in any camera")
    fallback = min(found, key=lambda p: float(np.sum(problem.residuals(p, shape)[0] ** 2)))
    poses = {c: (p if p is not None else fallback) for c, p in starts.items()}

    energies: list[float] = []
    pose_iterations = None
    status = Status.MAX_ITERATIONS
    iteration = 0
    residuals: dict = {}
    for iteration in range(1, options.max_iterations + 1):
        shape_phase = pose_iterations is not None
        residuals = {}
        energy = 0.0
        for i in model_cams:
            for _ in range(options.single_camera_steps):
                poses[i] = _single_camera_step(problem, poses[i], shape, w_nor, i)
            weights = _row_weights(problem, w_nor, i, options.weighting)
            if options.cross_steps:
                poses[i] = _cross_steps(problem, poses[i], shape, weights, options.cross_steps)
            residuals[i] = problem.residuals(poses[i], shape)[0]
            energy += _cross_energy(residuals[i], weights)
        energies.append(energy)

        # Eq. (6): weight update from the cross projection errors and the visibility term
        cross, rows = _weight_update_errors(problem, residuals, model_cams, options.weighting)
        m1, m2, m3 = options.mu_update
        visibility = w_nor - problem.others_mean(w_nor)
        if options.weight_state == "raw":
            w = np.where(rows[:, None], np.maximum(m1 * w + m2 * cross + m3 * visibility, 0.0), w)
            w = np.where(problem.seen, w, 0.0)
            new_w = _normalise(w, problem.seen, options.weight_floor)
        else:
            new_w = _normalise(m1 * w_nor + m2 * cross + m3 * visibility, problem.seen, options.weight_floor)
        w_nor = np.where(rows[:, None], new_w, w_nor)

        change = abs(energies[-2] - energy) if len(energies) > 1 else np.inf
        small = energy < options.abs_tol or (len(energies) > 1 and change <= options.tol * energies[-2])
        if not shape_phase:
            smooth = len(energies) > 1 and change <= options.smooth_tol * max(energies[-2], 1e-300)
            if iteration >= options.max_pose_iterations or (iteration >= options.min_pose_iterations and (smooth or energy < options.abs_tol)):
                pose_iterations = iteration
                if not options.hwc and small:
                    status = Status.CONVERGED
                    break
            continue
        if not options.hwc:
            if small:
                status = Status.CONVERGED
                break
            continue

        new_shape = _hwc_step(problem, poses, shape, w_nor, residuals, options, bounds)
        frame = _body_frame(new_shape)
        new_shape = _inverse_transform(frame, new_shape)
        poses = {c: p.compose(frame) for c, p in poses.items()}
        moved = float(np.linalg.norm(new_shape - shape, axis=1).max())
        shape = new_shape
        if small and moved <= options.shape_tol:
            status = Status.CONVERGED
            break

    # the model with the smaller projection error over all images wins (each detection weighed by its final weight)
    errors = {i: _projection_error(problem, problem.residuals(poses[i], shape)[0], w_nor) for i in model_cams}
    errors = {i: e for i, e in errors.items() if np.isfinite(e)}
    if not errors or not np.all(np.isfinite(shape)):
        return VehicleResult(vehicle_id, Status.FAILED, message="cpo: the iterations left the finite numbers")
    best = min(errors, key=errors.get)
    wireframe = Wireframe(shape)
    e = whitened_residuals(obs, poses[best], shape)
    return VehicleResult(
        vehicle_id, status, world_T_vehicle=poses[best], wireframe=wireframe, iterations=iteration,
        final_error=0.5 * float(np.sum(e * e)),
        message=f"dropped {dropped} non-finite observations" if dropped else "",
        extras={
            "camera": obs.cameras[best].name,
            "energy": energies,
            "pose_iterations": pose_iterations,
            "projection_error": {obs.cameras[i].name: e for i, e in errors.items()},
            "poses": {obs.cameras[i].name: poses[i] for i in model_cams},
            "weights": {cam.name: w_nor[c].copy() for c, cam in enumerate(obs.cameras)},
        },
    )
