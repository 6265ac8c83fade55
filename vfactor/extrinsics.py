"""What the cameras' calibration error gives an estimate: the solve's covariance from uncertain extrinsics.

A camera's ``world_T_camera`` comes from a survey or a calibration that errs
by a fraction of a degree and a few centimetres; every keypoint that camera
sees then errs together. At 30 m, 0.3 degrees moves a vehicle by 16 cm, more
than the pixel noise of a good detector does, and an estimate whose
covariance knows only the pixel noise claims more than it knows. Where a
camera gives :attr:`vfactor.camera.Camera.extrinsic_sigma`, the one-frame
solve adds the covariance its extrinsic's error gives the solution, as a
"consider" parameter: not estimated (one vehicle's keypoints do not tell a
camera's error from the vehicle's pose), but propagated through the fit
(docs/factors.md, "Covariances", item 7).
"""

from __future__ import annotations

import gtsam
import numpy as np

from vfactor.factors.projection import KeypointObservations, extrinsic_jacobian, whitened_pose_jacobian
from vfactor.factors.robust import RobustLoss
from vfactor.shape_evidence import Linearisation, considered_covariance
from vfactor.stats import chi2_quantile

__all__ = ["declares_extrinsics", "extrinsic_jacobian", "extrinsic_covariance", "extrinsic_pose_covariance",
           "explained_residuals", "with_extrinsics", "without_camera_errors", "PLAUSIBLE_ERROR"]

#: A camera's error estimated from its residuals is its declared error's within this quantile of chi2 (its
#: Mahalanobis norm under ``extrinsic_sigma``); beyond it the camera is off by more than it says
#: (:func:`without_camera_errors`).
PLAUSIBLE_ERROR = 0.999


def declares_extrinsics(cameras) -> bool:
    """Whether any of the cameras (:class:`vfactor.camera.Camera`) gives an ``extrinsic_sigma``."""
    return any(camera.extrinsic_sigma is not None for camera in cameras)


def _declared(cameras, camera_index: np.ndarray):
    """(camera index, its rows among the 2n whitened residuals, its sigma, the components whose sigma is not 0) of
    each camera of ``cameras`` that sees one of the n observations (``camera_index``) and declares an error other
    than 0."""
    rows = np.repeat(camera_index, 2)
    for c in np.unique(camera_index):
        sigma = cameras[c].extrinsic_sigma
        if sigma is not None and np.any(sigma > 0):
            yield c, rows == c, sigma, sigma > 0


def extrinsic_covariance(covariance: np.ndarray, jacobian: np.ndarray, observations: KeypointObservations,
                         world_T_vehicle: gtsam.Pose3) -> np.ndarray:
    """(n, n) covariance of the solution that the cameras' extrinsic errors give it, through the fit.

    Camera ``c``'s extrinsic errs by ``xi_c`` (covariance ``S_c = diag(extrinsic_sigma_c^2)``, independent between
    cameras); its whitened residuals then move by ``B_c xi_c`` (:func:`extrinsic_jacobian`) and the least-squares
    solution by ``-P A_c^T B_c xi_c``, so that

    ``C_extrinsic = sum_c G_c S_c G_c^T``, ``G_c = P A_c^T B_c``

    (``P = H^-1`` the covariance graph's covariance, ``A_c`` camera c's rows of its projection factor's whitened
    Jacobian). Zero where no camera of ``observations`` has an ``extrinsic_sigma``.

    Args:
        covariance: (n, n) ``P``, the covariance of the variables whose columns ``jacobian`` has, pose first.
        jacobian: (2m, n) the projection factor's whitened Jacobian, two rows per observation, the pose's
            6 columns first (GTSAM's right perturbation of ``world_T_vehicle``).
        observations: the m observations of those rows (their cameras).
        world_T_vehicle: the solution's pose (vehicle -> world), metres.
    """
    A = np.asarray(jacobian, dtype=float)
    return considered_covariance(covariance, A, (
        (rows, extrinsic_jacobian(A[rows, :6], world_T_vehicle, observations.cameras[c].pose), sigma ** 2)
        for c, rows, sigma, _ in _declared(observations.cameras, observations.camera_index)))


def explained_residuals(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p: np.ndarray,
                        loss: RobustLoss | None = None) -> np.ndarray:
    """(n, 2) whitened residuals of ``obs`` at a solution, each camera's keypoints less what its extrinsic's error
    most likely makes of them (:func:`without_camera_errors`).

    Args:
        obs: the observations (the sigmas the residuals are whitened by).
        world_T_vehicle: the solution's pose (vehicle -> world), metres.
        vehicle_p: (12, 3) its body-frame keypoints, metres.
        loss: the robust loss whose weights the cameras' fits take (None: least squares).
    """
    residuals, pose_jacobian = whitened_pose_jacobian(obs, world_T_vehicle, vehicle_p)
    return without_camera_errors(residuals.ravel(), pose_jacobian.reshape(-1, 6), obs, world_T_vehicle,
                                 loss).reshape(-1, 2)


def without_camera_errors(residuals: np.ndarray, pose_jacobian: np.ndarray, obs: KeypointObservations,
                          world_T_vehicle: gtsam.Pose3, loss: RobustLoss | None = None,
                          iterations: int = 5) -> np.ndarray:
    """(2n,) whitened residuals, each camera's less what its extrinsic's error most likely makes of them.

    For a camera with an ``extrinsic_sigma``, its residuals ``e_c`` are those of the camera moved by the robust
    ridge estimate ``xi_c = -(B_c^T W B_c + S_c^-1)^-1 B_c^T W e_c`` (:func:`extrinsic_jacobian`; ``W`` first 1,
    then the robust loss's weights of the moved camera's residuals, iterated; components whose sigma is 0 stay 0;
    from the raw residuals' weights a camera off by far more than its error stalled half explained), linearly:
    ``e_c + B_c xi_c``, where ``xi_c`` is a plausible draw of the declared error (``xi_c^T S_c^-1 xi_c`` within
    the :data:`PLAUSIBLE_ERROR` quantile of chi2): a camera off by about its declared error then agrees with the
    others; one off by many times more (a wrong ``world_T_camera``) keeps its residuals, and its outliers do not
    move it. The other cameras' residuals as they are. Minus the residuals give minus the result (the weights
    depend on their norms alone).

    Args:
        residuals: (2n,) whitened residuals of ``obs``, two per observation.
        pose_jacobian: (2n, 6) their derivative with respect to the vehicle's pose (GTSAM's right perturbation).
        obs: the observations (their cameras).
        world_T_vehicle: the solution's pose (vehicle -> world), metres.
        loss: the robust loss whose weights the ridge takes (None: least squares).
        iterations: reweightings of the ridge (with a loss).
    """
    out = np.array(residuals, dtype=float)
    for c, mine, sigma, free in _declared(obs.cameras, obs.camera_index):
        B = extrinsic_jacobian(pose_jacobian[mine], world_T_vehicle, obs.cameras[c].pose)[:, free]
        e = out[mine]
        w = np.ones(len(e))  # least squares first: a camera off by far more than its error is then seen so
        for k in range(1 + (iterations if loss is not None else 0)):
            if k:  # the robust loss's weights of the moved camera's residuals
                w = np.repeat(loss.weight(np.linalg.norm(moved.reshape(-1, 2), axis=1)), 2)
            xi = -np.linalg.solve((B.T * w) @ B + np.diag(sigma[free] ** -2.0), (B.T * w) @ e)
            moved = e + B @ xi
        if np.sum((xi / sigma[free]) ** 2) <= chi2_quantile(int(free.sum()), PLAUSIBLE_ERROR):
            out[mine] = moved  # else the camera is off by more than its declared error: its residuals as they are
    return out


def with_extrinsics(lin: Linearisation, obs: KeypointObservations, world_T_vehicle: gtsam.Pose3) -> Linearisation:
    """``lin`` with each camera's extrinsic error as further variables under their priors: the system the noise of
    the keypoints is read off where the cameras' errors are declared (``lin`` itself where none is).

    A camera's error moves all its keypoints together, and where cameras see a vehicle from different sides their
    disagreement shows in the residuals; read as pixel noise it widened the covariances a second time, beside what
    :func:`extrinsic_covariance` adds. With the errors ``xi_c`` (their nonzero components) as variables, prior
    ``S_c^-1``, the projection's Jacobian is ``[A, B]`` (:func:`extrinsic_jacobian`) and

    ``H' = [[H, A^T B], [B^T A, B^T B + S^-1]]``, ``H'_proj = [A, B]^T [A, B]``, ``eta' = [eta, B^T b]``,
    ``eta'_proj = [A, B]^T b``:

    the prior on the errors is no projection information, so a noise scale multiplies all of ``H'_proj`` but not
    it, and the residuals' degrees of freedom count the errors' share of the fit.

    Args:
        lin: the linearisation of the graph with its projection factor without the robust loss, at ``obs``'
            sigmas (its ``jacobian`` and ``rhs`` that factor's, ``obs``' rows).
        obs: the observations of ``lin``'s projection factor.
        world_T_vehicle: the solution's pose (vehicle -> world), metres.
    """
    A, b = lin.jacobian, lin.rhs
    if A is None or A.shape[0] != 2 * len(obs):
        return lin
    columns, precision = [], []
    for c, rows, sigma, free in _declared(obs.cameras, obs.camera_index):
        B_c = np.zeros((len(A), int(free.sum())))
        B_c[rows] = extrinsic_jacobian(A[rows, :6], world_T_vehicle, obs.cameras[c].pose)[:, free]
        columns.append(B_c)
        precision.append(sigma[free] ** -2.0)
    if not columns:
        return lin
    B = np.hstack(columns)
    AB = np.hstack([A, B])
    projection = AB.T @ AB
    total = projection.copy()
    m = len(lin.total)
    total[:m, :m] = lin.total
    total[m:, m:] += np.diag(np.concatenate(precision))
    return Linearisation(total, np.concatenate([lin.total_eta, B.T @ b]), projection, AB.T @ b, lin.prior,
                         lin.prior_eta, lin.shape, AB, b)


def extrinsic_pose_covariance(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p: np.ndarray,
                              inlier_bound: float, loss: RobustLoss | None = None) -> np.ndarray:
    """(6, 6) what the cameras' extrinsic errors give a pose through its own frame's keypoints: a track's poses.

    A camera's error is the same in every frame, so neither the motion model that joins a track's frames nor their
    number averages it away; to first order, with the shape held, it moves each pose by ``G_c xi_c``,
    ``G_c = H^-1 A_c^T B_c`` (``A`` the frame's inliers' whitened pose Jacobian, ``H = A^T A``, ``A_c`` camera c's
    rows, :func:`extrinsic_jacobian`): the term is ``sum_c G_c S_c G_c^T`` (one camera alone: its whole error, seen
    from the vehicle). The inliers are the observations whose residuals, less each camera's plausible error
    (:func:`without_camera_errors`), are within ``inlier_bound`` (squared, whitened). Zero where no camera declares
    an error or the frame's pose information is singular.

    Args:
        obs: the frame's observations (its sigmas: those the track weighs them with).
        world_T_vehicle: the frame's pose (vehicle -> world), metres.
        vehicle_p: (12, 3) the track's body-frame keypoints, metres.
        inlier_bound: the squared whitened residual an inlier stays within.
        loss: the robust loss of :func:`without_camera_errors`.
    """
    out = np.zeros((6, 6))
    if not declares_extrinsics(obs.cameras[c] for c in np.unique(obs.camera_index)):
        return out
    residuals, pose_jacobian = whitened_pose_jacobian(obs, world_T_vehicle, vehicle_p)
    explained = without_camera_errors(residuals.ravel(), pose_jacobian.reshape(-1, 6), obs, world_T_vehicle, loss)
    inlier = np.sum(explained.reshape(-1, 2) ** 2, axis=1) < inlier_bound
    A = pose_jacobian[inlier].reshape(-1, 6)
    try:
        H_inv = np.linalg.inv(A.T @ A)
    except np.linalg.LinAlgError:
        return out
    out = considered_covariance(H_inv, A, (
        (rows, extrinsic_jacobian(A[rows], world_T_vehicle, obs.cameras[c].pose), sigma ** 2)
        for c, rows, sigma, _ in _declared(obs.cameras, obs.camera_index[inlier])))
    return out if np.all(np.isfinite(out)) else np.zeros((6, 6))
