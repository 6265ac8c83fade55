"""Builds vfactor's factor graph and initial values from observations.

The functions here are also the API for adding vehicles to a graph of your own
(a SLAM or mapping graph): :func:`add_shape_factors` once per vehicle,
:func:`add_observation_factor` once per vehicle per frame, and
:func:`insert_vehicle_values` for the initial estimates, all under a
:class:`vfactor.keys.KeyScheme` you choose.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import gtsam
import numpy as np

from vfactor.camera import Camera
from vfactor.errors import InputError, check_numbers
from vfactor.factors.body_frame import body_frame_factor
from vfactor.factors.distance_bounds import distance_bounds_term
from vfactor.factors.ground_plane import GroundPlane, ground_plane_factor, hub_height_prior
from vfactor.factors.layer_offset import layer_offset_term
from vfactor.factors.planarity import layer_plane_term
from vfactor.factors.projection import KeypointObservations, projection_factor
from vfactor.factors.rectangle import rectangle_factor
from vfactor.factors.robust import RobustLoss
from vfactor.factors.shape_prior import shape_prior_factor
from vfactor.factors.shape_terms import cross, evaluate_terms, shape_terms_factor
from vfactor.factors.symmetry import symmetry_factor
from vfactor.factors.trapezoid import trapezoid_term
from vfactor.heatmaps import clipped_by_border
from vfactor.keypoints import LAYER_NAMES
from vfactor.keys import KeyScheme
from vfactor.observations import Detection
from vfactor.shape_model import HwcBounds, ShapePrior, default_hwc_bounds, default_shape_prior
from vfactor.wireframe import Wireframe

__all__ = [
    "GraphConfig",
    "observations_from_detections",
    "roi_cut_by_border",
    "vehicle_image_sizes",
    "sized_observations",
    "resized_observations",
    "sigma_change",
    "MAX_SIZE_IN_IMAGES",
    "RESIZE_SHARE",
    "add_shape_factors",
    "add_observation_factor",
    "detector_shape_sigmas",
    "shape_sigma_at_size",
    "SHAPE_SIGMA_REFERENCE_VOLUME",
    "SHAPE_SIGMA_RANGE",
    "detector_offset_prior",
    "detector_offset_information",
    "detector_bias_sigma",
    "detector_bias_prior",
    "COMMON_OFFSET",
    "add_ground_factor",
    "ground_factor",
    "hub_height",
    "hub_prior",
    "DEFAULT_HUB_HEIGHT",
    "insert_vehicle_values",
    "build_vehicle_graph",
    "copy_graph",
    "wireframe_from_values",
    "hwc_terms",
    "hwc_factor",
    "hwc_residuals",
    "hwc_violation",
]


@dataclass(frozen=True)
class GraphConfig:
    """Noise and constraint settings of the vehicle graph.

    Attributes:
        relative_pixel_sigma: keypoint pixel sigma at confidence 1, as a fraction
            of the detection's box diagonal (the sigma is divided by the confidence).
        min_pixel_sigma: lower bound of that sigma, pixels, also when the solver
            scales the sigmas by the estimated noise scale (a detection cut by the
            image border has a small box of seen keypoints that understates its noise).
        covariance_min_pixel_sigma: lower bound of the sigmas the covariances are
            computed at, pixels: they follow the noise the residuals show below
            ``min_pixel_sigma`` (docs/factors.md, "Covariances").
        covariance_sandwich_weight: the residuals' own (sandwich) covariance, times this, widens the
            covariances where it is wider than theirs (docs/factors.md, "Covariances", item 5); 0: off.
            2 / 3 was chosen on ``library_2cam`` seeds 10-19 at three noise levels among 1, 2 / 3 and 1 / 2
            (from about 20 keypoints the sandwich is noisy, and the larger of a noisy and a sound covariance
            is wider than either on average): the pose's share under the chi2 95 % bound (clean / paper /
            hard) went from 93.1 / 93.2 / 92.0 % to 94.5 / 94.6 / 93.8 %, its NEES from 0.98x / 0.98x /
            1.04x to 0.91x / 0.93x / 0.97x (1 / 2: 0.94x / 0.96x / 1.01x, 93.9 / 94.0 / 93.1 %; 1: 0.84x /
            0.85x / 0.89x). With the solution's residuals in place of the covariance graph's own, 1 / 2
            (chosen so until 2026-12-06) left clean cars 0.70x-0.75x.
        loss: robust loss per keypoint observation.
        symmetry_sigma: left/right asymmetry allowed per coordinate, metres.
        body_frame_sigma: gauge tightness (hub centroid at the origin, hubs level), metres.
        shape_prior_weight: scales the information of the mean-shape prior.
        hwc: the nonlinear HWC factor (layer planes, trapezoids, distance and
            layer-offset bounds; the wheel-layer factor is linear and always in): ``"always"`` in the graph from the start;
            ``"lazy"`` (default) added by the solver only when the solution
            without it breaks an HWC condition by more than ``hwc_tolerance``
            sigmas, then solved again with it (an active-set strategy: the HWC
            terms are hinges or nearly implied by symmetry, so they are rarely
            active and the Python factor is rarely paid for); ``"off"`` never.
        hwc_tolerance: whitened HWC residual (sigmas) beyond which ``"lazy"`` adds the factor.
        plane_sigma_m, plane_sigma_rad: layer planarity (m) and perpendicularity (rad).
        rectangle_sigma: wheel layer: parallel axles (x and z of the axle-vector difference), metres.
        trapezoid_sigma_rad, width_ratio_sigma: trapezoid parallel sides and width-ratio hinge.
        hinge_sigma: distance and layer-offset hinges beyond their bounds, metres.
        hub_height: height of the wheel hubs above the road (the ground-plane
            factor, when a road plane is given), metres; None (the default): the shape prior's
            (:attr:`vfactor.shape_model.ShapePrior.hub_height`: in the default model each body type's mean wheel
            radius, and the solve's mixture of them), or :data:`DEFAULT_HUB_HEIGHT` for a prior without one.
        ground_sigma_height: that height's sigma (it also covers the unknown wheel radius), metres.
        ground_sigma_road: the part of ``ground_sigma_height`` that is each pose's own (the road's unevenness, the
            body's bounce), metres; the rest, ``sqrt(ground_sigma_height^2 - ground_sigma_road^2)``, is the
            vehicle's wheel radius, which a track's poses share: a track gives its hub height one variable with
            that prior (:func:`hub_prior`) and each pose's factor ``ground_sigma_road`` (:func:`ground_factor`).
            One pose alone gets ``ground_sigma_height`` as before.
        ground_sigma_tilt: roll and pitch against the road plane's, radians.
        truncation: the detector loses keypoints whose pixel falls outside the
            image, so those it keeps near the border are biased inwards: compare
            each with the mean of a Gaussian truncated to the image
            (:mod:`vfactor.factors.truncation`). Applies to detections from
            cameras with a known ``image_size`` whose seen keypoints all lie in
            the image (a detector that reports a keypoint outside, as the
            keypoint network does for vehicles cut by the border, does not
            truncate).
        shape_sigma_size_exponent: a detection's ``shape_sigma`` (the detector's error shaped like a change of
            shape) holds for a vehicle whose keypoints span :data:`SHAPE_SIGMA_REFERENCE_VOLUME`; the solve takes
            it times ``(V / V0) ** exponent`` for a vehicle whose keypoints span ``V``
            (:func:`shape_sigma_at_size`; docs/factors.md, "Covariances", item 6); 0 takes it as given.
            1.5 was chosen on the shipped keypoint network's frames of ``library_2cam`` seeds 0, 1 and 254 and
            ``accuracy_2cam`` 0 and 6 (the network's error on vans and pickups is two to three times its
            error on hatchbacks and sedans: docs/results.md, "The network's error of the shape grows with the
            vehicle").
        shape_error_through_fit: a detection's ``shape_sigma`` (at the vehicle's size) times this is also
            propagated through the fit (:func:`vfactor.solve.detector_shape_covariance`): each camera's error of the
            shape moves the pose as well as the shape, as the least squares passes it on (docs/factors.md,
            "Covariances", item 6); 0: the shape block alone.
        cut_view_sigma_factor: where every detection of a vehicle is cut by its image's border (its ``roi``
            reaches beyond the image or stops at its border), the sigmas of the keypoints whose covariance is
            calibrated (``Detection.covariance_calibrated``: the keypoint network's) are taken times this. A
            learnt detector draws the part of a vehicle it cannot see, and its errors there are larger than its
            calibration says and alike from frame to frame; where no whole view anchors the vehicle they moved
            tracks of high-roof vans by 0.5-0.7 m (docs/factors.md, "Cut views alone"). 1: as calibrated.
        shape_prior_loss: robust loss on the shape prior's Mahalanobis norm:
            ``"none"`` (default) is the native Gaussian; a heavy tail (tracking
            uses ``RobustLoss("cauchy", 6.0)``) lets many frames overrule the
            prior for a vehicle far from it (docs/factors.md).
    """

    relative_pixel_sigma: float = 0.03
    min_pixel_sigma: float = 1.0
    covariance_min_pixel_sigma: float = 0.25
    covariance_sandwich_weight: float = 2.0 / 3.0
    loss: RobustLoss = field(default_factory=RobustLoss)
    symmetry_sigma: float = 0.01
    body_frame_sigma: float = 1e-3
    shape_prior_weight: float = 1.0
    hwc: str = "lazy"
    hwc_tolerance: float = 1.0
    plane_sigma_m: float = 0.02
    plane_sigma_rad: float = 0.05
    rectangle_sigma: float = 0.02
    trapezoid_sigma_rad: float = 0.05
    width_ratio_sigma: float = 0.02
    hinge_sigma: float = 0.01
    hub_height: float | None = None
    ground_sigma_height: float = 0.06
    ground_sigma_road: float = 0.02
    ground_sigma_tilt: float = 0.03
    truncation: bool = True
    shape_prior_loss: RobustLoss = field(default_factory=lambda: RobustLoss("none"))
    shape_sigma_size_exponent: float = 1.5
    shape_error_through_fit: float = 1.0
    cut_view_sigma_factor: float = 3.0

    def __post_init__(self):
        check_numbers("GraphConfig", self, (
            "relative_pixel_sigma", "min_pixel_sigma", "covariance_min_pixel_sigma", "symmetry_sigma", "body_frame_sigma", "shape_prior_weight",
            "plane_sigma_m", "plane_sigma_rad", "rectangle_sigma", "trapezoid_sigma_rad", "width_ratio_sigma",
            "hinge_sigma", "hwc_tolerance", "ground_sigma_height", "ground_sigma_road", "ground_sigma_tilt",
            "cut_view_sigma_factor",
        ))
        if self.hub_height is not None:
            check_numbers("GraphConfig", self, ("hub_height",))
        if self.ground_sigma_road >= self.ground_sigma_height:
            raise ValueError(f"GraphConfig.ground_sigma_road: expected less than ground_sigma_height "
                             f"({self.ground_sigma_height:g} m), got {self.ground_sigma_road!r}")
        check_numbers("GraphConfig", self, ("covariance_sandwich_weight", "shape_sigma_size_exponent",
                                             "shape_error_through_fit"), strict=False)
        if self.hwc not in ("always", "lazy", "off"):
            raise ValueError(f"GraphConfig.hwc: expected 'always', 'lazy' or 'off', got {self.hwc!r}")
        if not isinstance(self.truncation, bool):
            raise ValueError(f"GraphConfig.truncation: expected True or False, got {self.truncation!r}")
        for name in ("loss", "shape_prior_loss"):
            if not isinstance(getattr(self, name), RobustLoss):
                raise ValueError(f"GraphConfig.{name}: expected a RobustLoss, e.g. RobustLoss('cauchy', 2.5), "
                                 f"got {getattr(self, name)!r}")


def observations_from_detections(
    detections: list[Detection], cameras: dict[str, Camera], config: GraphConfig = GraphConfig(),
    vehicle_sizes: dict[str, float] | None = None,
) -> KeypointObservations:
    """Stacks the seen keypoints of one vehicle's detections, with their noise.

    The pixel noise of keypoint k is the detection's 2x2 covariance where one is
    given (marked ``calibrated`` when the detection says it is,
    ``Detection.covariance_calibrated``), else isotropic with sigma ``max(min_pixel_sigma, relative_pixel_sigma *
    size) / confidence``: ``size`` the diagonal of the detection's ``roi`` where it has one, else of the box
    around its seen keypoints, or the vehicle's size in that camera's image (``vehicle_sizes``) where that is
    larger; each observation keeps its detection's ``shape_sigma``, and is marked ``cut``
    where its detection's ``roi`` reaches beyond its camera's image (``image_size``). Where every observation is
    cut, those with a calibrated covariance get their sigmas times ``config.cut_view_sigma_factor``. With
    ``config.truncation``, a detection whose camera has an ``image_size`` and whose seen keypoints all lie in
    the image gets the image as its truncation window.

    Args:
        vehicle_sizes: camera name -> the diagonal (pixels) of the box around the vehicle's 12 keypoints projected
            at an estimate of it (:func:`vehicle_image_sizes`). A detector's keypoint error follows the vehicle's
            size in the image, and the few keypoints a detector keeps of a vehicle the image border cuts (or
            another vehicle hides) span a box far smaller than the vehicle: sized by that box, they were weighed
            as if several times more precise than they are (docs/factors.md, "Keypoint noise sized by the
            vehicle"). Detections with an ``roi`` keep the ``roi``'s size.

    Raises:
        InputError: a detection names a camera that is not in ``cameras``.
    """
    names = list(cameras)
    cam_idx, kp_idx, uv, sqrt_info, window, calibrated, shape_sigma, cut = [], [], [], [], [], [], [], []
    for d in detections:  # each detection's seen keypoints as arrays (one NumPy pass per detection, not per keypoint)
        if d.camera not in cameras:
            raise InputError("camera", f"unknown camera {d.camera!r}; known: {', '.join(names)}")
        seen = np.flatnonzero(d.confidence > 0)
        if len(seen) == 0:
            continue
        edges = _truncation_window(cameras[d.camera], d.keypoints[seen]) if config.truncation else None
        base_sigma = _base_sigma(d, config, vehicle_sizes)
        L = np.asarray(d.confidence[seen], dtype=float)[:, None, None] / base_sigma * np.eye(2)
        given = _own_covariance(d, seen)
        if given.any():
            L[given] = np.swapaxes(np.linalg.cholesky(np.linalg.inv(d.covariance[seen][given])), 1, 2)
        calibrated.append(given & bool(d.covariance_calibrated))
        shape_sigma.append(np.full(len(seen), float(d.shape_sigma or 0.0)))
        cut.append(np.full(len(seen), _roi_cut(cameras[d.camera], d.roi)))
        cam_idx.append(np.full(len(seen), names.index(d.camera)))
        kp_idx.append(seen)
        uv.append(d.keypoints[seen])
        sqrt_info.append(L)
        window.append(np.tile(edges if edges is not None else _NO_WINDOW, (len(seen), 1)))
    calibrated = _stacked(calibrated, (0,), bool)
    shape_sigma = _stacked(shape_sigma, (0,), float)
    cut = _stacked(cut, (0,), bool)
    sqrt_info = _stacked(sqrt_info, (0, 2, 2), float)
    if cut.all() and calibrated.any() and config.cut_view_sigma_factor != 1.0:  # no whole view: docs/factors.md
        sqrt_info[calibrated] /= config.cut_view_sigma_factor
    return KeypointObservations(
        cameras=tuple(cameras.values()),
        camera_index=_stacked(cam_idx, (0,), int),
        keypoint_index=_stacked(kp_idx, (0,), int),
        uv=_stacked(uv, (0, 2), float),
        sqrt_information=sqrt_info,
        window=_stacked(window, (0, 4), float),
        min_sigma=config.min_pixel_sigma,
        calibrated=calibrated if calibrated.any() else None,
        shape_sigma=shape_sigma if np.any(shape_sigma > 0) else None,
        cut=cut if cut.any() else None,
    )


def vehicle_image_sizes(cameras: dict[str, Camera], world_T_vehicle: gtsam.Pose3, wireframe: Wireframe,
                        names=None) -> dict[str, float]:
    """Camera name -> the diagonal (pixels) of the box around the vehicle's 12 keypoints projected into that
    camera's image at ``world_T_vehicle`` (those in front of the camera; none where fewer than two are), for
    :func:`observations_from_detections`'s ``vehicle_sizes``. The box is not clipped to the image: the vehicle's
    size, not the part of it in view; but it is at most :data:`MAX_SIZE_IN_IMAGES` image diagonals (a vehicle
    reaching behind the camera projects its nearest keypoints without bound).

    Args:
        cameras: the cameras by name; ``names`` (default: all of them) the ones to size the vehicle in.
        world_T_vehicle: the vehicle's pose (world frame, metres); ``wireframe`` its shape (body frame).
    """
    world_p = world_T_vehicle.transformFrom(np.asarray(wireframe.vehicle_p_keypoints, dtype=float).T).T
    sizes = {}
    for name in cameras if names is None else names:
        uv, depth = cameras[name].project(world_p)
        front = (depth > 0) & np.all(np.isfinite(uv), axis=1)
        if front.sum() >= 2:
            size = float(np.linalg.norm(uv[front].max(0) - uv[front].min(0)))
            if cameras[name].image_size is not None:
                size = min(size, MAX_SIZE_IN_IMAGES * float(np.hypot(*cameras[name].image_size)))
            sizes[name] = size
    return sizes


#: :func:`vehicle_image_sizes` caps a vehicle's size at this many diagonals of the camera's image.
MAX_SIZE_IN_IMAGES = 2.0
#: Where sizing a vehicle's keypoints' sigmas by the vehicle (:func:`sized_observations`) moves one by more than this
#: share, the one-frame solve (:func:`vfactor.solve.solve_observations`' ``resize``) refines at the sized sigmas.
#: On the frames of twelve two-camera track scenes 0.3 resized 30 % of the vehicles, 0.1 56 %, for the same gain; on
#: the one-frame evaluation's scenes (vehicles in view) none.
RESIZE_SHARE = 0.3


def _base_sigma(d: Detection, config: GraphConfig, vehicle_sizes: dict[str, float] | None = None) -> float:
    """The isotropic pixel sigma of a detection's keypoints at confidence 1 (:func:`observations_from_detections`)."""
    size = d.box_diagonal()
    if d.roi is None and vehicle_sizes and d.camera in vehicle_sizes:
        size = max(size, float(vehicle_sizes[d.camera]))
    return max(config.min_pixel_sigma, config.relative_pixel_sigma * size)


def _own_covariance(d: Detection, seen: np.ndarray) -> np.ndarray:
    """Which of a detection's ``seen`` keypoints (indices) come with a covariance of their own (a finite 2x2)."""
    if d.covariance is None:
        return np.zeros(len(seen), dtype=bool)
    return np.all(np.isfinite(d.covariance[seen]), axis=(1, 2))


def sized_observations(detections: list[Detection], cameras: dict[str, Camera], config: GraphConfig,
                       world_T_vehicle: gtsam.Pose3, wireframe: Wireframe) -> KeypointObservations:
    """:func:`observations_from_detections` with each keypoint's sigma sized by the vehicle at ``world_T_vehicle``
    with ``wireframe`` in each camera's image (:func:`vehicle_image_sizes`), not by the box of the few keypoints a
    detector kept of a vehicle the image border cuts (docs/factors.md, "Keypoint noise sized by the vehicle")."""
    sizes = vehicle_image_sizes(cameras, world_T_vehicle, wireframe, sorted({d.camera for d in detections}))
    return observations_from_detections(detections, cameras, config, sizes)


def resized_observations(detections: list[Detection], cameras: dict[str, Camera], config: GraphConfig,
                         world_T_vehicle: gtsam.Pose3, wireframe: Wireframe, share: float = RESIZE_SHARE
                         ) -> tuple[KeypointObservations | None, float]:
    """:func:`sized_observations` where they would change a keypoint's sigma by more than ``share``, for
    :func:`vfactor.solve.solve_observations`' ``resize``.

    The change is :func:`sigma_change`'s between the detections' observations as :func:`observations_from_detections`
    stacks them with ``config`` and as sized, computed from each detection's sigma alone: the observations are
    stacked again only where they are returned.

    Returns:
        (the sized observations, or None where no sigma changes by more than ``share``; the largest relative
        change of a keypoint's sigma).
    """
    sizes = vehicle_image_sizes(cameras, world_T_vehicle, wireframe, sorted({d.camera for d in detections}))
    change = 0.0
    for d in detections:
        seen = np.flatnonzero(d.confidence > 0)
        plain = seen[~_own_covariance(d, seen)]  # keypoints with a covariance of their own keep it
        if len(plain) == 0:
            continue
        confidence = np.asarray(d.confidence[plain], dtype=float)
        before, after = confidence / _base_sigma(d, config), confidence / _base_sigma(d, config, sizes)
        change = max(change, float(np.abs(after / before - 1.0).max()))
    if change <= share:
        return None, change
    return observations_from_detections(detections, cameras, config, sizes), change


def sigma_change(before: KeypointObservations, after: KeypointObservations) -> float:
    """The largest relative change of a keypoint's sigma between two stackings of the same detections (0 when
    none has any)."""
    if len(before) == 0:
        return 0.0
    return float(np.abs(after.sqrt_information[:, 0, 0] / before.sqrt_information[:, 0, 0] - 1.0).max())


_NO_WINDOW = np.full(4, np.nan)


def _stacked(parts: list, empty_shape: tuple, dtype) -> np.ndarray:
    """The detections' arrays of :func:`observations_from_detections` end to end (an empty one of ``empty_shape``)."""
    return np.concatenate(parts).astype(dtype, copy=False) if parts else np.zeros(empty_shape, dtype=dtype)


def _roi_cut(camera: Camera, roi) -> bool:
    """Whether the detection box ``roi`` says the image border cuts the vehicle: it reaches beyond the camera's image
    (a whole vehicle's box), or an edge stops at the border (a 2D detector's box, clipped to the image:
    :func:`vfactor.heatmaps.clipped_by_border`). False where either is not known."""
    if roi is None or camera.image_size is None:
        return False
    return roi_cut_by_border(roi, camera.image_size) or clipped_by_border(roi, camera.image_size)


def roi_cut_by_border(roi, image_size) -> bool:
    """Whether a box ``(x0, y0, x1, y1)`` (pixel edges) reaches beyond a ``(width, height)`` image, whose pixel edges
    span ``-0.5 .. width - 0.5``: a vehicle's whole (amodal) box where the image border cuts the vehicle."""
    width, height = image_size
    return bool(roi[0] < -0.5 or roi[1] < -0.5 or roi[2] > width - 0.5 or roi[3] > height - 0.5)


def _truncation_window(camera: Camera, uv: np.ndarray) -> np.ndarray | None:
    """The image's pixel edges ``[u_lo, v_lo, u_hi, v_hi]``, or None (size unknown, or a keypoint lies outside)."""
    if camera.image_size is None or not camera.in_image(uv).all():
        return None
    return np.array([-0.5, -0.5, camera.image_size[0] - 0.5, camera.image_size[1] - 0.5])


def hwc_terms(config: GraphConfig = GraphConfig(), bounds: HwcBounds | None = None):
    """The nonlinear HWC residual terms (fused into one factor by :func:`add_shape_factors`)."""
    bounds = bounds or default_hwc_bounds()
    return [
        layer_plane_term(LAYER_NAMES, config.plane_sigma_m, config.plane_sigma_rad),
        trapezoid_term(bounds.width_ratio, config.trapezoid_sigma_rad, config.width_ratio_sigma),
        distance_bounds_term(bounds.distance, sigma=config.hinge_sigma),
        layer_offset_term(bounds.layer_offset, sigma=config.hinge_sigma),
    ]


def add_shape_factors(
    graph: gtsam.NonlinearFactorGraph,
    keys: KeyScheme,
    vehicle: int = 0,
    config: GraphConfig = GraphConfig(),
    prior: ShapePrior | None = None,
    bounds: HwcBounds | None = None,
) -> None:
    """Adds one vehicle's shape factors: body frame, symmetry, wheel layer (parallel axles), shape prior, and HWC when ``config.hwc == "always"``.

    Add these once per vehicle (the shape is shared by all its frames). With
    ``"lazy"``, add :func:`hwc_factor` yourself when :func:`hwc_violation` says so.
    """
    layer_keys = tuple(keys.layer_keys(vehicle))
    for factor in _gauge_and_symmetry_factors(layer_keys, config.body_frame_sigma, config.symmetry_sigma,
                                              config.rectangle_sigma):
        graph.add(factor)
    graph.add(shape_prior_factor(layer_keys, prior or default_shape_prior(), config.shape_prior_weight,
                                 config.shape_prior_loss))
    if config.hwc == "always":
        graph.add(hwc_factor(keys, vehicle, config, bounds))


@lru_cache(maxsize=4096)
def _gauge_and_symmetry_factors(layer_keys: tuple, body_frame_sigma: float, symmetry_sigma: float,
                                rectangle_sigma: float) -> tuple:
    """The body-frame, symmetry and rectangle factors of one vehicle's layer keys: made once, shared by every graph
    that holds them (GTSAM factors are immutable; each graph of a solve or a track used to build its own)."""
    return (body_frame_factor(layer_keys[0], body_frame_sigma), *(symmetry_factor(k, symmetry_sigma) for k in layer_keys),
            rectangle_factor(layer_keys[0], rectangle_sigma))


def hwc_factor(keys: KeyScheme, vehicle: int = 0, config: GraphConfig = GraphConfig(), bounds: HwcBounds | None = None,
               terms=None):
    """The fused nonlinear HWC factor of one vehicle (one Python call per linearisation).

    Args:
        terms: the HWC terms, when already made by :func:`hwc_terms`.
    """
    return shape_terms_factor(keys.layer_keys(vehicle), terms if terms is not None else hwc_terms(config, bounds))


def hwc_residuals(wireframe: Wireframe, terms) -> np.ndarray:
    """Whitened residuals (sigmas) of the HWC ``terms`` (:func:`hwc_terms`) at a wireframe: the HWC factor's error is
    half their squared norm."""
    return evaluate_terms(terms, wireframe.vehicle_p_keypoints)


def hwc_violation(wireframe: Wireframe, terms) -> float:
    """Largest whitened residual (sigmas) of the HWC ``terms`` (:func:`hwc_terms`); 0 when every condition holds."""
    return float(np.abs(hwc_residuals(wireframe, terms)).max())


def add_observation_factor(
    graph: gtsam.NonlinearFactorGraph,
    keys: KeyScheme,
    observations: KeypointObservations,
    vehicle: int = 0,
    frame: int = 0,
    config: GraphConfig = GraphConfig(),
    offsets: Mapping[str, int] | None = None,
) -> None:
    """Adds the keypoint projection factor of one vehicle in one frame (no-op without observations).

    Args:
        offsets: camera name -> key of the detector pose offset (``gtsam.Pose3``) of that camera's keypoints
            (a track's, docs/factors.md "The detector's pose offset in tracks"): each such camera's keypoints
            get their own factor, which moves the vehicle by the offset; the other cameras' share one factor.
    """
    if not len(observations):
        return
    pose_key, layer_keys = keys.pose_key(vehicle, frame), keys.layer_keys(vehicle)
    if not offsets:  # the common case: one factor, no per-camera masks
        graph.add(projection_factor(pose_key, layer_keys, observations, config.loss))
        return
    shared = np.ones(len(observations), dtype=bool)
    for c, camera in enumerate(observations.cameras):
        rows = observations.camera_index == c
        if camera.name in offsets and rows.any():
            graph.add(projection_factor(pose_key, layer_keys, observations.subset(rows), config.loss,
                                        offset_key=offsets[camera.name]))
            shared &= ~rows
    if shared.all():
        graph.add(projection_factor(pose_key, layer_keys, observations, config.loss))
    elif shared.any():
        graph.add(projection_factor(pose_key, layer_keys, observations.subset(shared), config.loss))


def detector_shape_sigmas(observations: KeypointObservations, vehicle_p_keypoints: np.ndarray | None = None,
                          size_exponent: float = 0.0) -> dict[str, float]:
    """Camera name -> the ``shape_sigma`` (metres) of its detection of the vehicle, for the cameras whose
    detection has one (a camera's largest, if its observations differ), at the vehicle's size where its keypoints
    ``vehicle_p_keypoints`` ((12, 3), body frame) are given (:func:`shape_sigma_at_size` with ``size_exponent``,
    ``GraphConfig.shape_sigma_size_exponent``), held within :data:`SHAPE_SIGMA_RANGE`; empty where none has."""
    if observations.shape_sigma is None:
        return {}
    out = {}
    for c in np.unique(observations.camera_index):
        sigma = float(np.max(observations.shape_sigma[observations.camera_index == c]))
        if sigma > 0:
            if vehicle_p_keypoints is not None:
                sigma = shape_sigma_at_size(sigma, vehicle_p_keypoints, size_exponent)
            out[observations.cameras[c].name] = float(np.clip(sigma, *SHAPE_SIGMA_RANGE))
    return out


#: The volume (m^3) of the box the keypoints span (body frame, axis-aligned) at which a detection's ``shape_sigma``
#: holds as given: about a mid-size SUV's (the vehicle library's medians: hatchbacks 6.5, sedans 7.1, estates 7.4,
#: SUVs 9.3, pickups 11.8, vans 12.7; a Mini 5.4, a Citroen Jumper L3H3 20.4).
SHAPE_SIGMA_REFERENCE_VOLUME = 9.0


_SIZE_RATIO_RANGE = (0.25, 4.0)  # of the keypoints' box volume to SHAPE_SIGMA_REFERENCE_VOLUME


def shape_sigma_at_size(sigma: float, vehicle_p_keypoints: np.ndarray, exponent: float) -> float:
    """A detection's ``shape_sigma`` (metres) for the vehicle whose keypoints are ``vehicle_p_keypoints``
    ((12, 3), body frame, metres): ``sigma (V / V0) ** exponent``, ``V`` the volume of the box the keypoints span
    and ``V0`` :data:`SHAPE_SIGMA_REFERENCE_VOLUME`. A learnt detector errs on a vehicle it knows less well by
    more: the shipped network's error of the shape on vans and pickups is two to three times that on hatchbacks
    and sedans (``GraphConfig.shape_sigma_size_exponent``). ``V`` is held within a quarter and four times ``V0``
    (2.25-36 m^3: the library's vehicles span 5.4-20.4 m^3), so that a degenerate shape neither zeroes nor
    explodes the error; one that is not finite is taken at ``V0``."""
    if not exponent:
        return float(sigma)
    extent = np.ptp(np.asarray(vehicle_p_keypoints, dtype=float).reshape(12, 3), axis=0)
    ratio = float(np.clip(np.prod(extent) / SHAPE_SIGMA_REFERENCE_VOLUME, *_SIZE_RATIO_RANGE)) if np.all(
        np.isfinite(extent)) else 1.0
    return float(sigma) * ratio ** float(exponent)


#: The range (metres) :func:`detector_shape_sigmas` holds a detection's ``shape_sigma`` to: a tenth of a millimetre
#: is finer than any keypoint, ten metres more than any vehicle; beyond them the widening's arithmetic overflows (a
#: scene's ``shape_sigma`` of 1e-300 stopped the solve with an ``OverflowError``), and a detector offset's prior
#: could no longer hold its variable.
SHAPE_SIGMA_RANGE = (1e-4, 10.0)


def detector_offset_prior(offset_key: int, sigma: float, vehicle_p_keypoints: np.ndarray,
                          common_key: int | None = None, size_exponent: float = 0.0) -> gtsam.NonlinearFactor:
    """The prior of a detector pose offset ``vehicle_T_seen`` (:func:`add_observation_factor`'s ``offsets``).

    The identity, with the information of ``sigma`` metres (the detection's ``shape_sigma``) on each coordinate of
    the keypoints that the offset moves: ``J^T J / sigma^2``, ``J`` (36 x 6) the derivative of the 12 keypoints
    ``vehicle_p_keypoints`` under a small rigid motion ``(rotation, translation)`` of the body frame
    (docs/factors.md, "The detector's pose offset in tracks"). The keypoints are taken together with their half
    turn about z, so that the prior is the same in either gauge of the body frame (:func:`canonical_gauge`):
    about 1.1-1.3 cm of shift and 0.4-0.8 degrees of turn per axis for ``sigma`` 3.8 cm and a car.

    Args:
        offset_key: key of the ``gtsam.Pose3`` offset.
        sigma: metres on each keypoint coordinate, held within :data:`SHAPE_SIGMA_RANGE` (as
            :func:`detector_shape_sigmas` holds it; this also serves callers that read a detection's
            ``shape_sigma`` themselves, as ``vfactor.net.bias_error`` does).
        vehicle_p_keypoints: (12, 3) the track's keypoints (body frame, metres) when the offset is made.
        common_key: where the track has a common offset (the detector's bias, :func:`detector_bias_prior`), its
            key: the prior is then about that offset (a ``BetweenFactorPose3`` with the same noise: the camera's
            offset is the common one and the camera's own part).
        size_exponent: ``sigma`` is taken at the vehicle's size (:func:`shape_sigma_at_size`;
            ``GraphConfig.shape_sigma_size_exponent``); 0: as given.
    """
    noise = gtsam.noiseModel.Gaussian.Information(
        detector_offset_information(sigma, vehicle_p_keypoints, size_exponent))
    if common_key is not None:
        return gtsam.BetweenFactorPose3(common_key, offset_key, gtsam.Pose3(), noise)
    return gtsam.PriorFactorPose3(offset_key, gtsam.Pose3(), noise)


def detector_offset_information(sigma: float, vehicle_p_keypoints: np.ndarray, size_exponent: float = 0.0
                                ) -> np.ndarray:
    """(6, 6) the information of :func:`detector_offset_prior` (rotation, then translation; its arguments'
    meaning): ``J^T J / sigma^2`` over the keypoints and their half turn about z (the doubled points count once)."""
    sigma = float(np.clip(shape_sigma_at_size(sigma, vehicle_p_keypoints, size_exponent), *SHAPE_SIGMA_RANGE))
    p = np.asarray(vehicle_p_keypoints, dtype=float).reshape(12, 3)
    p = np.concatenate([p, p * [-1.0, -1.0, 1.0]])
    J = np.zeros((len(p), 3, 6))
    for axis in range(3):  # a turn about an axis moves a point by axis x p
        J[:, :, axis] = cross(np.broadcast_to(np.eye(3)[axis], p.shape), p)
    J[:, :, 3:] = np.eye(3)
    J = J.reshape(-1, 6)
    return J.T @ J / (2.0 * sigma**2)


#: The name, in a track's camera name -> detector offset key mappings, of the offset all its cameras share (the
#: detector's bias, :func:`detector_bias_prior`); no camera has it (camera names are not empty).
COMMON_OFFSET = ""


def detector_bias_sigma(detections) -> np.ndarray | None:
    """The largest ``bias_sigma`` of ``detections``, element by element ((6,): radians about the body x, y, z, then
    metres along them), or None where none has one (or every one is zero)."""
    found = [np.asarray(d.bias_sigma, dtype=float) for d in detections if d.bias_sigma is not None]
    largest = np.max(found, axis=0) if found else None
    return largest if largest is not None and np.any(largest > 0) else None


def detector_bias_prior(offset_key: int, bias_sigma) -> gtsam.NonlinearFactor:
    """The prior of a track's common detector offset (the offset every camera's keypoints of the track move by,
    docs/factors.md, "The detector's pose offset in tracks"): the identity with the detections' ``bias_sigma``
    ((6,): rotation about the body x, y, z in radians, then shift along them in metres) as the sigmas of its
    ``Pose3`` coordinates. A diagonal covariance is the same in either gauge of the body frame (the half turn about
    z changes the signs of the roll, pitch, x and y coordinates only). A zero sigma is taken as
    :data:`MIN_BIAS_SIGMA` (no bias there, and a variable the graph can still hold)."""
    sigmas = np.maximum(np.asarray(bias_sigma, dtype=float), MIN_BIAS_SIGMA)
    return gtsam.PriorFactorPose3(offset_key, gtsam.Pose3(), gtsam.noiseModel.Diagonal.Sigmas(sigmas))


#: The least sigma (radians or metres) :func:`detector_bias_prior` gives a coordinate of a track's common offset.
MIN_BIAS_SIGMA = 1e-4
#: The hubs' height above the road (metres) for a shape prior that gives none (:func:`hub_height`): about a car's
#: wheel radius.
DEFAULT_HUB_HEIGHT = 0.34


def hub_height(config: GraphConfig = GraphConfig(), prior: ShapePrior | None = None) -> float:
    """The hubs' height above the road (metres) that the ground-plane factor of a vehicle under the shape ``prior``
    takes: ``config.hub_height`` where it is set, else the prior's (the body type's wheel radius), else
    :data:`DEFAULT_HUB_HEIGHT`."""
    if config.hub_height is not None:
        return float(config.hub_height)
    if prior is not None and prior.hub_height is not None:
        return prior.hub_height
    return DEFAULT_HUB_HEIGHT


def add_ground_factor(
    graph: gtsam.NonlinearFactorGraph,
    keys: KeyScheme,
    plane: GroundPlane | None,
    vehicle: int = 0,
    frame: int = 0,
    config: GraphConfig = GraphConfig(),
    prior: ShapePrior | None = None,
) -> None:
    """Adds the ground-plane factor of one pose (hubs at :func:`hub_height` above ``plane``); no-op without a
    plane."""
    if plane is not None:
        graph.add(ground_factor(keys.pose_key(vehicle, frame), plane, config, prior=prior))


def ground_factor(pose_key: int, plane: GroundPlane, config: GraphConfig = GraphConfig(),
                  hub_key: int | None = None, prior: ShapePrior | None = None) -> gtsam.NonlinearFactor:
    """The ground-plane factor of the pose ``pose_key`` with ``config``'s sigmas and the hub height of
    :func:`hub_height` (``config``, the shape ``prior``); with ``hub_key`` (a track's hub height, :func:`hub_prior`)
    the hub height is that variable and the height's sigma ``config.ground_sigma_road``, each pose's own part of
    it."""
    if hub_key is None:
        return ground_plane_factor(pose_key, plane, hub_height(config, prior), config.ground_sigma_height,
                                   config.ground_sigma_tilt)
    return ground_plane_factor(pose_key, plane, hub_height(config, prior), config.ground_sigma_road,
                               config.ground_sigma_tilt, hub_key=hub_key)


def hub_prior(hub_key: int, config: GraphConfig = GraphConfig(), prior: ShapePrior | None = None
              ) -> gtsam.NonlinearFactor:
    """The prior of a track's hub height (``hub_key``): :func:`hub_height` (``config``, the track's shape
    ``prior``) with the part of ``config.ground_sigma_height`` that is not each pose's own (``ground_sigma_road``):
    the wheel radius, the same in every frame of the track, so that its uncertainty does not average away over the
    track's poses."""
    sigma = float(np.sqrt(config.ground_sigma_height**2 - config.ground_sigma_road**2))
    return hub_height_prior(hub_key, hub_height(config, prior), sigma)


def insert_vehicle_values(
    values: gtsam.Values,
    keys: KeyScheme,
    world_T_vehicle: gtsam.Pose3 | None,
    wireframe: Wireframe | None,
    vehicle: int = 0,
    frame: int = 0,
) -> None:
    """Inserts (or updates) a vehicle's pose in ``frame`` and/or its shape layers."""
    def put(key, value):
        if values.exists(key):
            values.update(key, value)
        else:
            values.insert(key, value)

    if world_T_vehicle is not None:
        put(keys.pose_key(vehicle, frame), world_T_vehicle)
    if wireframe is not None:
        for key, vec in zip(keys.layer_keys(vehicle), wireframe.layer_vectors().values()):
            put(key, vec)


def wireframe_from_values(values: gtsam.Values, keys: KeyScheme, vehicle: int = 0) -> Wireframe:
    """A vehicle's shape read back from its three layer variables (inverse of :func:`insert_vehicle_values`)."""
    return Wireframe.from_layer_vectors({name: values.atVector(k) for name, k in zip(LAYER_NAMES, keys.layer_keys(vehicle))})


def copy_graph(graph: gtsam.NonlinearFactorGraph) -> gtsam.NonlinearFactorGraph:
    """A new graph holding the same factors (``graph.clone()`` fails on a Python ``CustomFactor``)."""
    out = gtsam.NonlinearFactorGraph()
    for i in range(graph.size()):
        out.add(graph.at(i))
    return out


def build_vehicle_graph(
    observations: KeypointObservations,
    keys: KeyScheme = KeyScheme(),
    vehicle: int = 0,
    frame: int = 0,
    config: GraphConfig = GraphConfig(),
    prior: ShapePrior | None = None,
    bounds: HwcBounds | None = None,
    ground_plane: GroundPlane | None = None,
) -> gtsam.NonlinearFactorGraph:
    """The one-frame graph of one vehicle: projection factor, shape factors and, given a road plane, the ground factor."""
    graph = gtsam.NonlinearFactorGraph()
    add_observation_factor(graph, keys, observations, vehicle, frame, config)
    add_shape_factors(graph, keys, vehicle, config, prior, bounds)
    add_ground_factor(graph, keys, ground_plane, vehicle, frame, config, prior)
    return graph
