"""Results of a solve: one :class:`VehicleResult` per vehicle per frame."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import gtsam
import numpy as np

from vfactor.box import Box
from vfactor.wireframe import Wireframe

__all__ = ["Status", "VehicleResult", "FrameResult", "COVARIANCE_KINDS", "ESTIMATE_STATUSES"]

#: What a track result's pose covariance comes from (``VehicleResult.extras["covariance"]``, the result file's
#: ``pose_covariance_kind``): the frames up to its own, every frame of the track, or the fixed-lag window as it left it.
COVARIANCE_KINDS = ("filtered", "smoothed", "fixed_lag")


class Status(str, enum.Enum):
    """How a solve ended (the ``status`` field of the result file).

    ``converged`` and ``max_iterations`` (the optimiser's iteration limit) carry an estimate; so does ``poor_fit``:
    the one-frame solve converged, but its keypoints fit far worse than their sigmas say (the estimated noise scale
    at least :data:`vfactor.solve.POOR_FIT_SCALE`), so the estimate may be grossly wrong (a pose turned by tens of
    degrees, a shape unlike the vehicle) and its covariance too narrow. ``degenerate`` and ``failed`` carry none.
    """

    CONVERGED = "converged"
    MAX_ITERATIONS = "max_iterations"
    POOR_FIT = "poor_fit"
    DEGENERATE = "degenerate"
    FAILED = "failed"


#: The statuses that carry an estimate (a pose and a wireframe): :attr:`VehicleResult.ok`.
ESTIMATE_STATUSES = (Status.CONVERGED, Status.MAX_ITERATIONS, Status.POOR_FIT)


@dataclass
class VehicleResult:
    """Estimate of one vehicle in one frame.

    Attributes:
        id: track id.
        status: see :class:`Status`; when DEGENERATE or FAILED, the pose and the
            wireframe are ``None`` and ``message`` says why.
        world_T_vehicle: pose of the body frame in the world.
        wireframe: the estimated shape, body frame, metres.
        pose_covariance: (6, 6) covariance of ``world_T_vehicle`` in GTSAM's
            tangent convention: rotation (rad) then translation (m), both in the
            body frame (right perturbation ``T exp(xi)``).
        keypoint_covariances_world: (12, 3, 3) covariances of the world keypoints, m^2.
        iterations: optimiser iterations.
        final_error: final value of the graph's cost (0.5 * sum of squared whitened residuals, robust).
        message: human-readable detail (always set for DEGENERATE and FAILED).
        body_type: the body type whose shape prior the solve chose (one of
            :data:`vfactor.vehicle_library.BODY_TYPES`), None when a single
            prior was given.
        body_type_probability: its posterior probability, in [0, 1].
        box: the vehicle's 3D box (:mod:`vfactor.box`), with the standard
            deviations of its size, heading and centre where covariances were computed.
        extras: solver diagnostics; ``"body_type_posterior"``: body type ->
            probability; ``"noise_scale"``: the estimated pixel-noise scale
            (multiplies the detector's sigmas); ``"inlier_weights"``: (n,) robust-loss weight in
            [0, 1] of each observation, in the order of
            :func:`vfactor.graph.observations_from_detections` (near 0: rejected; 0: left out of the fit);
            ``"outliers_left_out"``: indices of the observations the one-frame solve left out as gross outliers
            (docs/factors.md); ``"fit_noise_scale"``: the noise scale over every observation before that;
            ``"resized"``: where the one-frame solve sized its keypoints' sigmas by the vehicle it found, the
            largest relative change of a sigma (docs/factors.md, "Keypoint noise sized by the vehicle");
            ``"disagreeing_cameras"``: on a ``failed`` vehicle, the cameras whose keypoints the joint solve
            rejected while they agree among themselves (docs/reliability.md); ``"disagreeing_cut_cameras"``: on
            a solved vehicle, such cameras whose box of the vehicle reaches beyond their image (not blamed: the
            vehicle is solved, those keypoints left to the robust loss); ``"cut_cameras_left_out"``: on a solved
            vehicle, the cameras whose cut view the joint solve had followed against another camera's keypoints,
            and without which the vehicle was solved (docs/reliability.md);
            ``"detections"``: the indices, in the frame's ``detections``, of the detections the vehicle was
            solved from (the result file's ``detections``);
            ``"covariance_inflation"``: the factor the one-frame covariances carry
            for an estimated noise scale (docs/factors.md); ``"covariance_noise_scale"``: the inliers' noise
            scale the one-frame covariances are computed at (times the nominal sigmas; calibrated sigmas are
            not narrowed by it); ``"covariance_widening"``: how much
            wider, at most, the residuals' own (sandwich) covariance made them than that model
            (1: not at all; docs/factors.md); for tracks,
            ``"covariance"``: which covariance ``pose_covariance`` is,
            ``"filtered"`` (from the frames up to its own: the tracker's online
            result), ``"smoothed"`` (from every frame of the track) or
            ``"fixed_lag"`` (from the frames of the window, as the pose left it); ``"hub_height"``: for tracks
            with a road plane, the height of the wheel hubs above it (the wheel radius, metres) that the track's
            poses share (docs/factors.md, "The hub height of a track").
    """

    id: str
    status: Status
    world_T_vehicle: gtsam.Pose3 | None = None
    wireframe: Wireframe | None = None
    pose_covariance: np.ndarray | None = None
    keypoint_covariances_world: np.ndarray | None = None
    iterations: int = 0
    final_error: float = float("nan")
    message: str = ""
    body_type: str | None = None
    body_type_probability: float | None = None
    box: Box | None = None
    extras: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Whether the result carries an estimate (status ``converged``, ``max_iterations`` or ``poor_fit``)."""
        return self.status in ESTIMATE_STATUSES

    @property
    def keypoints_world(self) -> np.ndarray | None:
        """(12, 3) keypoints in the world frame, metres."""
        if self.world_T_vehicle is None or self.wireframe is None:
            return None
        return self.wireframe.in_world(self.world_T_vehicle)

    @property
    def keypoints_vehicle(self) -> np.ndarray | None:
        """(12, 3) keypoints in the body frame, metres."""
        return None if self.wireframe is None else self.wireframe.vehicle_p_keypoints


@dataclass
class FrameResult:
    """All vehicles of one frame, in the order of their first detection."""

    t: float
    vehicles: list[VehicleResult]
