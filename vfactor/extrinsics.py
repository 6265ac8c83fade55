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

from vfactor.factors.projection import KeypointObservations

__all__ = ["extrinsic_jacobian", "extrinsic_covariance"]


def extrinsic_jacobian(pose_jacobian: np.ndarray, world_T_vehicle: gtsam.Pose3, world_T_camera: gtsam.Pose3) -> np.ndarray:
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
    out = np.zeros((A.shape[1], A.shape[1]))
    rows = np.repeat(observations.camera_index, 2)
    for c in np.unique(observations.camera_index):
        camera = observations.cameras[c]
        if camera.extrinsic_sigma is None or not np.any(camera.extrinsic_sigma > 0):
            continue
        A_c = A[rows == c]
        G = covariance @ (A_c.T @ extrinsic_jacobian(A_c[:, :6], world_T_vehicle, camera.pose))  # (n, 6)
        out += (G * camera.extrinsic_sigma ** 2) @ G.T
    return 0.5 * (out + out.T)
