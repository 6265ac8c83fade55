"""Baseline: pose and shape from one image, after Pavlakos et al. (ICRA 2017).

"6-DoF Object Pose from Semantic Keypoints" fits a deformable shape model,
``S = mean + sum_m c_m B_m``, to the keypoints of one image, weighting each
keypoint by its heatmap confidence and keeping the coefficients small. Here:

- the model is the mean and the first ``num_components`` principal components
  of the nine PASCAL3D+ car shapes (symmetrised, wheelbase units,
  :func:`vfactor.wireframe.pascal3d_shapes`), times a wheelbase ``s`` in metres;
- the prior: ``c_m ~ N(0, lambda_m)`` (the PCA variances) and
  ``s ~ N(wheelbase, wheelbase_sigma^2)``; a single view cannot tell size from
  distance, so the wheelbase prior fixes the scale (the paper's point, Fig. 3);
- the fit: ``scipy.optimize.least_squares`` over the pose (6), the
  coefficients and ``log s``, with the camera's full perspective projection
  (distortion included), residuals whitened by the observations'
  square-root information (confidence / sigma) and a Cauchy loss;
- the start: SQPnP of the mean wireframe in that camera (Pavlakos et al.
  start from a weak-perspective fit; a PnP start is the usual substitute when
  the intrinsics are known);
- the camera: every camera is fitted on its own; the one with the smallest RMS
  relative reprojection error over its own keypoints wins (or the one asked for:
  the paper reports "the best result of two images", which
  ``camera=`` lets an evaluation reproduce).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import least_squares

from vfactor.baselines.pnp import box_diagonals, camera_pnp, candidate_cameras, clean_observations, relative_residuals
from vfactor.factors.projection import KeypointObservations, whitened_residuals
from vfactor.keypoints import MIRROR_PERMUTATION
from vfactor.result import Status, VehicleResult
from vfactor.wireframe import Wireframe, pascal3d_shapes

__all__ = ["SingleViewOptions", "DeformableModel", "deformable_model", "single_view"]


@dataclass(frozen=True)
class DeformableModel:
    """A linear shape model in wheelbase units: ``shape(c) = mean + basis^T c`` (12, 3).

    Attributes:
        mean: (12, 3) mean shape, wheelbase units.
        basis: (M, 12, 3) orthonormal principal directions.
        std: (M,) standard deviation of each coefficient (wheelbase units).
    """

    mean: np.ndarray
    basis: np.ndarray
    std: np.ndarray

    def shape(self, coefficients: np.ndarray, wheelbase: float) -> np.ndarray:
        """(12, 3) body-frame keypoints in metres."""
        return wheelbase * (self.mean + np.tensordot(coefficients, self.basis, axes=1))


@lru_cache(maxsize=8)
def deformable_model(num_components: int = 5) -> DeformableModel:
    """PCA of the symmetrised PASCAL3D+ car shapes (at most 8 components from nine cars)."""
    shapes = pascal3d_shapes()
    shapes = 0.5 * (shapes + shapes[:, MIRROR_PERMUTATION] * [1.0, -1.0, 1.0])
    flat = shapes.reshape(len(shapes), 36)
    mean = flat.mean(0)
    _, sing, vt = np.linalg.svd(flat - mean, full_matrices=False)
    std = sing / np.sqrt(len(shapes) - 1)
    keep = min(int(num_components), int(np.sum(std > 1e-9 * max(std.max(), 1e-300))))
    model = DeformableModel(mean.reshape(12, 3), vt[:keep].reshape(keep, 12, 3), std[:keep])
    for a in (model.mean, model.basis, model.std):
        a.setflags(write=False)
    return model


@dataclass(frozen=True)
class SingleViewOptions:
    """Settings of :func:`single_view`.

    Attributes:
        num_components: principal components of the shape model (1-8).
        wheelbase, wheelbase_sigma: prior of the scale, metres.
        coefficient_weight: scales the whitened coefficient prior (1: ``c_m / std_m``).
        loss: ``scipy.optimize.least_squares`` loss (``"cauchy"``, ``"soft_l1"``, ``"huber"``, ``"linear"``).
        loss_scale: the loss's ``f_scale``, in whitened units (sigmas).
        max_evaluations: residual evaluations per camera.
        min_keypoints: a camera seeing fewer keypoints (at least 4) is not fitted.
    """

    num_components: int = 5
    wheelbase: float = 2.75
    wheelbase_sigma: float = 0.20
    coefficient_weight: float = 1.0
    loss: str = "cauchy"
    loss_scale: float = 2.0
    max_evaluations: int = 400
    min_keypoints: int = 4

    def __post_init__(self):
        if not isinstance(self.num_components, (int, np.integer)) or not 1 <= self.num_components <= 8:
            raise ValueError(f"SingleViewOptions.num_components: expected 1..8, got {self.num_components!r}")
        for name in ("wheelbase", "wheelbase_sigma", "coefficient_weight", "loss_scale"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
                raise ValueError(f"SingleViewOptions.{name}: expected a positive number, got {value!r}")
        if self.loss not in ("linear", "soft_l1", "huber", "cauchy", "arctan"):
            raise ValueError(f"SingleViewOptions.loss: expected a scipy least_squares loss, got {self.loss!r}")
        if not isinstance(self.max_evaluations, (int, np.integer)) or self.max_evaluations < 1:
            raise ValueError(f"SingleViewOptions.max_evaluations: expected a positive integer, got {self.max_evaluations!r}")
        if not isinstance(self.min_keypoints, (int, np.integer)) or self.min_keypoints < 4:
            raise ValueError(f"SingleViewOptions.min_keypoints: expected an integer >= 4, got {self.min_keypoints!r}")


def _fit_camera(obs: KeypointObservations, camera: int, model: DeformableModel, options: SingleViewOptions):
    """Fits the deformable model in one camera; returns (pose, shape, rms, nfev, success) or None."""
    one = obs.subset(obs.camera_index == camera)
    start_shape = model.shape(np.zeros(len(model.std)), options.wheelbase)
    start = camera_pnp(one, camera, start_shape)
    if start is None:
        return None
    M = len(model.std)
    prior_c = np.sqrt(options.coefficient_weight) / model.std

    def unpack(x):
        pose = start.retract(x[:6])
        wheelbase = options.wheelbase * np.exp(x[6 + M])
        return pose, model.shape(x[6 : 6 + M], wheelbase), wheelbase

    def residuals(x):
        pose, shape, wheelbase = unpack(x)
        r = whitened_residuals(one, pose, shape).ravel()
        return np.concatenate([r, prior_c * x[6 : 6 + M], [(wheelbase - options.wheelbase) / options.wheelbase_sigma]])

    x0 = np.zeros(7 + M)
    try:
        fit = least_squares(residuals, x0, loss=options.loss, f_scale=options.loss_scale, max_nfev=options.max_evaluations,
                            x_scale="jac", method="trf")
    except (ValueError, np.linalg.LinAlgError):
        return None
    if not np.all(np.isfinite(fit.x)):
        return None
    pose, shape, _ = unpack(fit.x)
    rel = relative_residuals(one, pose, shape, box_diagonals(one))
    rms = float(np.sqrt(np.mean(np.sum(rel * rel, axis=1))))
    return pose, shape, rms, int(fit.nfev), bool(fit.success)


def single_view(
    obs: KeypointObservations,
    options: SingleViewOptions = SingleViewOptions(),
    camera: int | str | None = None,
    vehicle_id: str = "vehicle",
) -> VehicleResult:
    """Pose and shape from one camera's keypoints with a deformable PASCAL3D+ model.

    Args:
        obs: the vehicle's observations (only one camera's are used).
        options: the model, prior and fit settings.
        camera: fit only this camera (index or name); default: every camera, the
            one with the smallest RMS relative reprojection error over its own keypoints wins.
        vehicle_id: id for the result.

    Returns:
        ``converged`` (or ``max_iterations`` when the fit ran out of evaluations),
        with ``extras["camera"]`` and ``extras["rms_relative_error"]`` (per fitted
        camera); ``final_error``: 0.5 * sum of squared whitened residuals over all
        cameras. ``degenerate`` when no camera sees ``options.min_keypoints``
        keypoints, ``failed`` when every fit fails. Never raises on bad observations.
    """
    model = deformable_model(options.num_components)
    obs, dropped = clean_observations(obs)
    candidates, problem = candidate_cameras(obs, camera, options.min_keypoints, "single_view", vehicle_id)
    if problem is not None:
        return problem
    fits, tried = {}, {}
    for c in candidates:
        fit = _fit_camera(obs, c, model, options)
        if fit is not None and np.isfinite(fit[2]):
            fits[c] = fit
            tried[obs.cameras[c].name] = fit[2]
    if not fits:
        return VehicleResult(vehicle_id, Status.FAILED, message="single_view: no camera gave a pose (PnP start or fit failed)")
    best = min(fits, key=lambda c: fits[c][2])
    pose, shape, _, nfev, success = fits[best]
    e = whitened_residuals(obs, pose, shape)
    return VehicleResult(
        vehicle_id, Status.CONVERGED if success else Status.MAX_ITERATIONS, world_T_vehicle=pose, wireframe=Wireframe(shape),
        iterations=nfev, final_error=0.5 * float(np.sum(e * e)),
        message=f"dropped {dropped} non-finite observations" if dropped else "",
        extras={"camera": obs.cameras[best].name, "rms_relative_error": tried},
    )
