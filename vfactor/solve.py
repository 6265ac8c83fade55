"""One-frame solve: Levenberg-Marquardt on one vehicle's graph, with covariances.

:func:`solve_vehicle` estimates one vehicle from its detections in one frame;
:func:`solve_frame` solves every vehicle of a frame, each on its own, so that
one that cannot be solved is reported with its status while the others are
still solved; :func:`solve_scene` does every frame.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cache, partial
from typing import Callable

import gtsam
import numpy as np
import numpy.ma  # noqa: F401  numpy 2 imports it lazily, on a solve's first np.unique (about 10 ms): here, with the other imports

from vfactor.box import BoxModel, vehicle_box
from vfactor.camera import Camera
from vfactor.errors import InputError, check_numbers
from vfactor.extrinsics import (declares_extrinsics, explained_residuals, extrinsic_covariance, with_extrinsics,
                                without_camera_errors)
from vfactor.factors.body_frame import canonical_gauge
from vfactor.factors.ground_plane import GroundPlane
from vfactor.factors.projection import KeypointObservations, projection_factor, whitened_residuals
from vfactor.factors.robust import RobustLoss
from vfactor.factors.shape_prior import shape_prior_factor
from vfactor.graph import (
    GraphConfig,
    build_vehicle_graph,
    copy_graph,
    detector_shape_sigmas,
    hwc_factor,
    hwc_residuals,
    hwc_terms,
    insert_vehicle_values,
    observations_from_detections,
    resized_observations,
    wireframe_from_values,
)
from vfactor.init import StartSearch, distinct_poses, own_pose
from vfactor.keys import KeyScheme
from vfactor.label_swaps import SWAP_MARGIN, apply_swaps, merge_findings, relabel_swaps, suspect_pairs, swapped_rows
from vfactor.observations import Detection, Frame, Scene, class_hints
from vfactor.parallel import InProcess
from vfactor.result import FrameResult, Status, VehicleResult
from vfactor.sanity import checked, summarise_error
from vfactor.shape_evidence import (NOISE_SCALE_RANGE, choose_body_type, considered_covariance, covariance_inflation,
                                    covariance_upper_bound, inlier_noise_scale, linearise, noise_scale,
                                    prior_misfit_covariance, sandwich_covariance, shape_information)
from vfactor.shape_model import HwcBounds, ShapeModel, ShapePrior, resolve_shape_prior
from vfactor.wireframe import Wireframe

log = logging.getLogger(__name__)

__all__ = ["SolveOptions", "solve_vehicle", "solve_observations", "solve_frame", "solve_scene", "iter_solve_scene",
           "POOR_FIT_SCALE", "RESCUE_SCALE", "RESTART_MARGIN",
           "pose_shape_covariance", "keypoint_covariances", "detector_shape_variance",
           "detector_shape_covariance"]


@dataclass(frozen=True)
class SolveOptions:
    """Settings of the one-frame solve.

    Attributes:
        graph: noise and constraint settings of the graph.
        max_iterations: Levenberg-Marquardt iteration limit per start.
        relative_error_tol: stop when the cost decreases by less than this fraction.
        absolute_error_tol: stop when the cost decreases by less than this.
        num_starts: at most this many distinct initial poses to optimise from
            (the lowest final cost wins): the best candidate, then, while the best
            solution so far keeps fewer than :data:`FURTHER_START_INLIERS` of the
            keypoints as inliers, the next candidates that differ from every
            solution reached (a start that LM would pull to a minimum already
            found is not another start).
        poor_fit_restarts: a solution that fits its keypoints poorly (``fit_noise_scale`` at least
            :data:`POOR_FIT_SCALE`) or is not sane (:mod:`vfactor.sanity`) is solved again, in full, from at most
            this many further starts, and the best fit in another basin is kept (``extras["restarted"]``; 0: never).
            Each costs a whole solve: about 0.7 % of the vehicles at hard simulated noise, none at paper-like noise,
            but every vehicle of a detector whose sigmas are far below its errors (then fix the sigmas).
        covariance: compute the pose and keypoint covariances (``gtsam.Marginals``).
        min_observations: fewer seen keypoints (over all cameras) make the
            vehicle ``degenerate``.
        min_keypoints_in_one_view: at least one camera must see this many
            keypoints (or enough must triangulate) to start without a pose guess.
        ground_plane: the road plane (world frame): the ground-plane factor
            holds the hubs at ``graph.hub_height`` above it and roll and pitch
            near its (docs/factors.md). ``None``: no ground factor; ``solve_scene``
            then uses the scene's plane when it gives one.
        estimate_noise: estimate the pixel-noise scale from the residuals of a
            first solve and solve again with it (docs/factors.md), so that the
            balance of keypoints and shape prior holds at any noise level;
            ``False`` keeps the sigmas of ``graph`` (``relative_pixel_sigma``,
            or the detections' covariances) as they are.
        relabel_swaps: exchange the labels of each camera's left/right pairs that the first solution says are
            swapped, and solve again (:mod:`vfactor.label_swaps`); where the refined solution still fits its
            keypoints worse than their sigmas (noise scale above :data:`SWAP_SEARCH_SCALE`) and two or more cameras
            see the vehicle, also solve for each
            suspect pair swapped and keep the swaps that lower the cost (:func:`_searched_swaps`). The result's
            ``extras["swapped_keypoints"]`` lists them.
        shape_information: keep the observations' information on the shape in
            the result's ``extras["shape_information"]`` (10 kB a vehicle), for
            :func:`vfactor.shape_evidence.track_shape` over several frames.
        box_model: the offsets from the wireframe to the result's ``box``
            (:class:`vfactor.box.BoxModel`); None: :func:`vfactor.box.default_box_model`.
    """

    graph: GraphConfig = field(default_factory=GraphConfig)
    max_iterations: int = 100
    relative_error_tol: float = 1e-6
    absolute_error_tol: float = 1e-9
    num_starts: int = 2
    poor_fit_restarts: int = 3
    covariance: bool = True
    min_observations: int = 6
    min_keypoints_in_one_view: int = 4
    ground_plane: GroundPlane | None = None
    estimate_noise: bool = True
    relabel_swaps: bool = True
    shape_information: bool = False
    box_model: BoxModel | None = None

    def __post_init__(self):  # as GraphConfig checks its fields: a bad setting fails here, naming itself
        for name, least in (("max_iterations", 1), ("num_starts", 1), ("poor_fit_restarts", 0),
                            ("min_observations", 1), ("min_keypoints_in_one_view", 1)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)) or value < least:
                raise ValueError(f"SolveOptions.{name}: expected an integer >= {least}, got {value!r}")
        check_numbers("SolveOptions", self, ("relative_error_tol", "absolute_error_tol"), strict=False)
        if not isinstance(self.graph, GraphConfig):
            raise ValueError(f"SolveOptions.graph: expected a GraphConfig, got {self.graph!r}")
        for name in ("covariance", "estimate_noise", "relabel_swaps", "shape_information"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"SolveOptions.{name}: expected True or False, got {getattr(self, name)!r}")
        if self.ground_plane is not None and not isinstance(self.ground_plane, GroundPlane):
            raise ValueError(f"SolveOptions.ground_plane: expected a GroundPlane or None, got {self.ground_plane!r}")
        if self.box_model is not None and not isinstance(self.box_model, BoxModel):
            raise ValueError(f"SolveOptions.box_model: expected a BoxModel or None, got {self.box_model!r}")

    def for_scene(self, scene: Scene) -> "SolveOptions":
        """These options, with the scene's road plane when they name none and the scene gives one."""
        if self.ground_plane is None and scene.ground_plane is not None:
            return dataclasses.replace(self, ground_plane=scene.ground_plane)
        return self

    def lm_params(self) -> gtsam.LevenbergMarquardtParams:
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(self.max_iterations)
        params.setRelativeErrorTol(self.relative_error_tol)
        params.setAbsoluteErrorTol(self.absolute_error_tol)
        return params


def pose_shape_covariance(marginals: gtsam.Marginals, keys: KeyScheme, vehicle: int = 0, frame: int = 0) -> np.ndarray:
    """(42, 42) joint marginal covariance of a vehicle's pose (6, GTSAM tangent) and shape (wheel, light, roof: 36)."""
    key_vector = gtsam.KeyVector([keys.pose_key(vehicle, frame), *keys.layer_keys(vehicle)])
    joint = marginals.jointMarginalCovariance(key_vector)
    return np.block([[joint.at(a, b) for b in key_vector] for a in key_vector])


def keypoint_covariances(
    marginals: gtsam.Marginals | np.ndarray, keys: KeyScheme, world_T_vehicle: gtsam.Pose3, wireframe: Wireframe,
    vehicle: int = 0, frame: int = 0,
) -> np.ndarray:
    """(12, 3, 3) covariances of the world keypoints from the joint marginal of pose and shape.

    ``world_p_k = R vehicle_p_k + t``; with GTSAM's right perturbation,
    ``d world_p_k / d xi = [-R [p_k]x, R]`` and ``d world_p_k / d vehicle_p_k = R``.

    Args:
        marginals: the graph's marginals, or the (42, 42) :func:`pose_shape_covariance` itself.
    """
    full = marginals if isinstance(marginals, np.ndarray) else pose_shape_covariance(marginals, keys, vehicle, frame)
    R = world_T_vehicle.rotation().matrix()
    out = np.empty((12, 3, 3))
    for k, p in enumerate(wireframe.vehicle_p_keypoints):
        J = np.zeros((3, 42))
        J[:, :3] = -R @ _skew(p)
        J[:, 3:6] = R
        J[:, 6 + 3 * k : 9 + 3 * k] = R
        out[k] = J @ full @ J.T
    return out


def _skew(p):
    return np.array([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])


def solve_observations(
    obs: KeypointObservations,
    options: SolveOptions = SolveOptions(),
    vehicle_id: str = "vehicle",
    prior: ShapePrior | ShapeModel | None = None,
    bounds: HwcBounds | None = None,
    initial: tuple[gtsam.Pose3, Wireframe] | None = None,
    hints: tuple[str, ...] = (),
    resize: Callable[[gtsam.Pose3, Wireframe], KeypointObservations] | None = None,
    start_prior: ShapePrior | None = None,
) -> VehicleResult:
    """Solves one vehicle from stacked observations (see :func:`solve_vehicle`).

    With a :class:`~vfactor.shape_model.ShapeModel` (the default), the vehicle
    is first solved with the model's pooled prior; the noise scale (with
    ``options.estimate_noise``) and the body type (Laplace evidence and the
    ``hints``) are then read off that solution, and it is solved again, from
    there, with the estimated sigmas and the moment-matched mixture of the
    types' priors (and the pooled one) under their posterior probabilities: the
    chosen type's own prior when the choice is clear (docs/factors.md). With a
    single :class:`~vfactor.shape_model.ShapePrior` that prior is used
    throughout. A refinement that fails numerically keeps the first solve
    (``extras["refinement"]`` says why).

    Args:
        obs: the vehicle's observations in all cameras
            (:func:`vfactor.graph.observations_from_detections`).
        options, prior, bounds: as for :func:`solve_vehicle`.
        vehicle_id: id for the result.
        initial: a (pose, wireframe) to start from instead of the PnP and
            triangulation candidates (e.g. a tracker's prediction).
        hints: 2D-detector classes of the vehicle (``"car"``, ``"truck"``,
            ``"bus"`` or a body type), weighing the body types
            (:data:`vfactor.shape_model.CLASS_HINTS`); never a hard rule.
        resize: ``resize(world_T_vehicle, wireframe)`` -> (the same observations with each keypoint's sigma sized
            by that vehicle, or None where that changes no sigma by more than :data:`vfactor.graph.RESIZE_SHARE`;
            the largest relative change) (:func:`vfactor.graph.resized_observations`; :func:`solve_vehicle` passes
            it). Where the first solution sizes them otherwise, the refinement
            starts with one LM at those sigmas (``extras["resized"]``: the largest relative change): a detector's
            few keypoints of a vehicle the image border cuts, sized by their own small box, were weighed as if
            several times more precise than they are (docs/factors.md, "Keypoint noise sized by the vehicle").
            Only with the refinement (a shape model or ``options.estimate_noise``).
        start_prior: the first solve's prior and the mean shape its starts align, in place of the model's pooled
            prior. Where the refinement chooses a body type far from the pooled prior
            (:meth:`~vfactor.shape_model.ShapeModel.far_from_pooled`: a bus), or the solution is ``poor_fit`` or
            has no estimate, the vehicle is solved again with such a type's prior here, and the better fit (the
            lower ``fit_noise_scale``) is returned (``extras["typed_start"]``: the type whose start gave it, where
            it is the second; the poor fit's only with ``options.poor_fit_restarts`` above 0).
    """
    given = obs  # as the caller gave them: a restart (_restarted) solves them again
    model, single, bounds = resolve_shape_prior(prior, bounds)
    first_prior = start_prior if start_prior is not None else model.pooled if model is not None else single
    keys = KeyScheme()
    n_seen = len(obs)
    if n_seen < options.min_observations:
        return VehicleResult(
            vehicle_id, Status.DEGENERATE,
            message=f"only {n_seen} keypoints seen over all cameras; at least {options.min_observations} are needed",
        )
    mean = Wireframe(first_prior.mean)
    graph = build_vehicle_graph(obs, keys, config=options.graph, prior=first_prior, bounds=bounds,
                                ground_plane=options.ground_plane)
    terms = hwc_terms(options.graph, bounds)
    hwc = hwc_factor(keys, 0, terms=terms)
    best, failure, tried, reached = None, "no start", 0, []  # reached: the starts tried and the poses LM reached
    best_inliers = 0.0  # the best solution's share of inliers

    def settled() -> bool:  # no further start: as many as allowed, or the best solution explains the keypoints
        return tried == options.num_starts or best_inliers >= FURTHER_START_INLIERS

    search = None  # the starts' search, made when a start is first needed (SQPnP and triangulation once)

    def candidate_starts(ransac: bool):
        nonlocal search
        if search is None:
            search = StartSearch(obs, mean, options.graph.loss, options.min_keypoints_in_one_view)
        return [(c.world_T_vehicle, c.wireframe) for c in search.best(None, ransac)]

    if initial is not None:
        rounds = [lambda: [initial]]
    else:  # the best SQPnP or triangulation start first; RANSAC's poses join the others only for a further start
        rounds = [lambda: candidate_starts(False)[:1], lambda: candidate_starts(True)]
    for make_starts in rounds:
        if settled():
            break
        for world_T_vehicle, wireframe in make_starts():
            if settled():
                break
            if not all(distinct_poses(world_T_vehicle, p) for p in reached):
                continue  # LM would pull it to a minimum already found: not another start
            tried += 1
            reached.append(world_T_vehicle)
            values = gtsam.Values()
            insert_vehicle_values(values, keys, world_T_vehicle, wireframe)
            try:
                outcome = _optimise(graph, values, keys, options, terms, hwc)
            except RuntimeError as exc:
                failure = summarise_error(exc)
                continue
            reached.append(outcome[0].atPose3(keys.pose_key()))
            if best is None or outcome[1] < best[1]:
                best, best_inliers = outcome, _inlier_share(obs, outcome[0], keys, options)
    if best is None and tried == 0 and initial is None:
        per_view = np.bincount(obs.camera_index, minlength=len(obs.cameras)).max()
        if per_view >= max(4, options.min_keypoints_in_one_view):  # PnP had its keypoints: no start was upright
            message = (f"no initial pose: every PnP start (the best camera sees {per_view} keypoints) puts the "
                       "vehicle upside down or behind a camera: check that each camera's world_T_camera maps "
                       "OpenCV's camera frame (x right, y down, z forward) to the world, whose z is up "
                       "(docs/conventions.md)")
        else:
            message = (f"no initial pose: the best camera sees {per_view} keypoints (PnP needs "
                       f"{options.min_keypoints_in_one_view}) and too few keypoints triangulate")
        return VehicleResult(vehicle_id, Status.DEGENERATE, message=message)
    if best is None:
        return VehicleResult(vehicle_id, Status.FAILED, message=f"optimisation failed: {failure}")
    swaps, as_given, left_out, fit_scale, hypotheses, resized = [], obs, None, None, None, None
    if options.relabel_swaps:
        best, obs, swaps = _relabelled(best, obs, options, first_prior, keys, bounds, terms, hwc)
    refining = model is not None or options.estimate_noise
    unsized = as_given, obs
    if resize is not None and refining:  # the keypoints' sigmas sized by the vehicle the first solution found
        sized, change = resize(best[0].atPose3(keys.pose_key()), wireframe_from_values(best[0], keys))
        if sized is not None:
            as_given, obs, resized = sized, apply_swaps(sized, swaps) if swaps else sized, change
    extras = {}
    nominal = obs
    graph_prior = first_prior  # the shape prior of the graph the estimate is the solution of
    if refining:
        try:  # at other sigmas than the first solution's: one LM at them first (_rerefined)
            best, obs, extras, refined_prior = (_refine if resized is None else _rerefined)(
                best, nominal, options, model, first_prior, hints, keys, bounds, terms, hwc)
        except (RuntimeError, np.linalg.LinAlgError) as exc:
            extras = {"refinement": f"kept the first solve: {exc}"}
            (as_given, obs), resized = unsized, None  # the first solve's own sigmas
            nominal = obs
        else:
            if (options.relabel_swaps and extras["noise_scale"] > SWAP_SEARCH_SCALE
                    and len(np.unique(nominal.camera_index)) >= 2):
                best, obs, nominal, extras, refined_prior, found, hypotheses = _searched_swaps(
                    best, obs, nominal, extras, refined_prior, options, model, hints, keys, bounds, terms, hwc)
                swaps = merge_findings(swaps, found)
            fit_scale = extras["noise_scale"]  # how well every keypoint fits (the refit below fits those left)
            if fit_scale > REFIT_SCALE and options.graph.loss.name != "none":  # least squares asked: as it is
                best, obs, nominal, extras, refined_prior, left_out = _refitted_without_gross_outliers(
                    best, obs, nominal, extras, refined_prior, options, model, hints, keys, bounds, terms, hwc)
            graph_prior = refined_prior  # the refinement's (the swap search's or the refit's where they solved again)
    estimate, error, iterations, hit_limit, graph = best
    pose_key = keys.pose_key()
    world_T_vehicle = estimate.atPose3(pose_key)
    wireframe = wireframe_from_values(estimate, keys)
    status, message = Status.MAX_ITERATIONS if hit_limit else Status.CONVERGED, ""
    if fit_scale is not None and fit_scale >= POOR_FIT_SCALE:
        status = Status.POOR_FIT
        message = (f"poor fit: the keypoints fit {fit_scale:.2g} times worse than their sigmas (noise scale >= "
                   f"{POOR_FIT_SCALE:g}); the estimate may be grossly wrong and its covariance too narrow")
    result = VehicleResult(
        vehicle_id, status, world_T_vehicle=world_T_vehicle, wireframe=wireframe, iterations=int(iterations),
        final_error=float(error), message=message, body_type=extras.pop("body_type", None),
        body_type_probability=extras.pop("body_type_probability", None),
    )
    if not options.shape_information:
        extras.pop("shape_information", None)
    result.extras.update(extras)
    if fit_scale is not None:
        result.extras["fit_noise_scale"] = fit_scale
    if resized is not None:
        result.extras["resized"] = resized
    if hypotheses is not None:
        result.extras["swap_hypotheses"] = hypotheses
    if swaps:
        result.extras["swapped_keypoints"] = swaps
    if left_out is None:
        e = whitened_residuals(obs, world_T_vehicle, wireframe.vehicle_p_keypoints)
        weights = options.graph.loss.weight(np.linalg.norm(e, axis=1))
    else:  # every observation, under the labels the solve settled on; those left out of the fit weigh 0
        every = apply_swaps(as_given, swaps).scaled(float(extras.get("noise_scale", 1.0)))
        weights = options.graph.loss.weight(np.linalg.norm(
            whitened_residuals(every, world_T_vehicle, wireframe.vehicle_p_keypoints), axis=1))
        weights[left_out] = 0.0
        result.extras["outliers_left_out"] = left_out
    result.extras["inlier_weights"] = weights
    # a camera at odds with the others inflates the estimated noise: judge it at no more than the nominal sigmas, and
    # with its labels as given (relabelling its pairs to fit the other cameras' pose would hide a wrong extrinsic)
    strict = as_given.scaled(min(float(extras.get("noise_scale", 1.0)), 1.0))
    strict_weights = options.graph.loss.weight(np.linalg.norm(
        whitened_residuals(strict, world_T_vehicle, wireframe.vehicle_p_keypoints), axis=1))
    explained = None  # a camera off by about the extrinsic error it declares is no camera at odds
    if declares_extrinsics(strict.cameras):
        @cache
        def explained():  # only for a camera the check would name, once
            return options.graph.loss.weight(np.linalg.norm(explained_residuals(
                strict, world_T_vehicle, wireframe.vehicle_p_keypoints, options.graph.loss), axis=1))
    problem, rejected, cut = _camera_disagreement(strict, strict_weights, mean, options, explained)
    if problem:
        suspects = _cut_views(as_given, exclude=rejected)
        if suspects:  # the joint solve followed a view the image border cuts: solve without it (the keypoints as given)
            kept = ~np.isin(as_given.camera_index,
                            [c for c, camera in enumerate(as_given.cameras) if camera.name in suspects])
            alone = solve_observations(as_given.subset(kept), options, vehicle_id, prior, bounds, None, hints,
                                       start_prior=start_prior)
            if alone.ok:
                note = (f"the keypoints of camera(s) {', '.join(repr(n) for n in suspects)}, whose view the image "
                        f"border cuts, disagree with those of camera(s) {', '.join(repr(n) for n in rejected)}: "
                        "left out")
                _add_note(alone, note)
                alone.extras["cut_cameras_left_out"] = suspects
                rows = np.flatnonzero(kept)  # the subset's observations among all of them (the cut views' weigh 0)
                if "inlier_weights" in alone.extras:
                    weights = np.zeros(len(as_given))
                    weights[rows] = alone.extras["inlier_weights"]
                    alone.extras["inlier_weights"] = weights
                if "outliers_left_out" in alone.extras:
                    alone.extras["outliers_left_out"] = rows[np.asarray(alone.extras["outliers_left_out"], dtype=int)]
                return alone
        failed = VehicleResult(vehicle_id, Status.FAILED, message=problem, extras={"disagreeing_cameras": rejected})
        return failed if search is None else _agreeing_restart(  # no start search: solved from a given pose
            failed, given, options, vehicle_id, prior, bounds, hints, resize, mean, world_T_vehicle, start_prior)
    if cut:  # a view cut by the image border: a detector's keypoints there may be a whole vehicle drawn in the part seen
        result.extras["disagreeing_cut_cameras"] = cut
        note = (f"the keypoints of camera(s) {', '.join(repr(n) for n in cut)} disagree with the other cameras where "
                "the image border cuts the vehicle: left to the robust loss")
        _add_note(result, note)
    joint = None
    if options.covariance:
        try:
            covariance_graph, inflation, inliers, covariance_scale, parameters = _covariance_graph(
                graph, obs, nominal.camera_scaled(extras.get("camera_noise_factors")),
                float(extras.get("noise_scale", 1.0)), estimate, keys, options)
            linear = covariance_graph.linearize(estimate)  # once: the marginals and the sandwich's residuals
            marginal = pose_shape_covariance(gtsam.Marginals(linear, estimate), keys)
            joint = inflation * marginal
            result.extras["covariance_inflation"] = inflation
            result.extras["covariance_noise_scale"] = covariance_scale
            if options.estimate_noise and options.graph.covariance_sandwich_weight > 0:
                joint = _widened_by_residuals(joint, inflation, linear, options.graph.covariance_sandwich_weight,
                                              result.extras, inliers, world_T_vehicle, options.graph.loss)
            sigmas = detector_shape_sigmas(obs, wireframe.vehicle_p_keypoints, options.graph.shape_sigma_size_exponent)
            if sigmas:  # the detectors' shape-like error, which no residual shows (item 6): on the shape ...
                shape_variance = _averaged_variance(sigmas)
                joint = joint + np.diag(np.r_[np.zeros(6), np.full(36, shape_variance)])
                result.extras["detector_shape_sigma"] = float(np.sqrt(shape_variance))
                through = options.graph.shape_error_through_fit ** 2 * detector_shape_covariance(
                    marginal, linear.at(0).jacobian()[0], inliers, sigmas)  # ... and through the fit
                if np.all(np.isfinite(through)):  # else the shape block alone, as where the sandwich is not
                    joint = joint + through
            if declares_extrinsics(inliers.cameras):  # their errors, through the fit
                joint = joint + extrinsic_covariance(marginal, linear.at(0).jacobian()[0], inliers, world_T_vehicle)
            if parameters is not None:  # a shape the prior does not describe (item 8), through the fit as 6 and 7
                misfit, excess = prior_misfit_covariance(
                    marginal, graph_prior, options.graph.shape_prior_weight, wireframe.vehicle_p_keypoints,
                    parameters - 6.0, [model.prior(t) for t in model.types] if model is not None else ())
                joint = joint + misfit
                result.extras["prior_misfit"] = excess
            result.pose_covariance = joint[:6, :6].copy()
            result.keypoint_covariances_world = keypoint_covariances(joint, keys, world_T_vehicle, wireframe)
        except (RuntimeError, np.linalg.LinAlgError) as exc:
            result.message = f"covariance unavailable: {exc}"
    result.box = vehicle_box(world_T_vehicle, wireframe, joint, result.extras.get("body_type_posterior"),
                             options.box_model)
    kept = {as_given.cameras[c].name for c in np.unique(as_given.camera_index[weights > INLIER_WEIGHT])}
    final = checked(result, [as_given.cameras[c] for c in np.unique(as_given.camera_index)], options.covariance,
                    in_image=kept)  # a camera whose every keypoint the solve takes for an outlier does not fail it
    first = final
    if search is not None and options.poor_fit_restarts > 0 and (final.status == Status.POOR_FIT or not final.ok):
        restarted = _restarted(given, options, vehicle_id, prior, bounds, hints, resize, search, reached,
                               world_T_vehicle, fit_scale if final.ok else None, start_prior)
        if restarted is not None:
            final = restarted
    if start_prior is None and model is not None:
        far = [t for t in model.types if model.far_from_pooled(t)]
        if final.body_type in far:
            far = [final.body_type]
        elif (final.ok and final.status != Status.POOR_FIT) or options.poor_fit_restarts == 0:
            far = []  # a poor fit's typed start is one more restart
        for body_type in far:
            final = _typed_start(final, body_type, given, options, vehicle_id, prior, bounds, initial, hints, resize,
                                 model)
    return _rescued(first, final)


def _rescued(first: VehicleResult, final: VehicleResult) -> VehicleResult:
    """``final``, ``poor_fit`` where it is another start's solution of a vehicle whose first solution fitted poorly
    (``fit_noise_scale`` at least :data:`POOR_FIT_SCALE`) and it fits no better than :data:`RESCUE_SCALE`: two
    basins that both fit poorly do not say which is right."""
    before, after = first.extras.get("fit_noise_scale"), final.extras.get("fit_noise_scale")
    if (final is first or final.status != Status.CONVERGED or before is None or after is None
            or before < POOR_FIT_SCALE or after < RESCUE_SCALE):
        return final
    return _poor_fit_in_another_basin(final, after, before)


def _poor_fit_in_another_basin(result: VehicleResult, scale: float, first: float | None = None) -> VehicleResult:
    """``result``, another start's solution that fits at ``scale`` (the first solution at ``first``, where it had
    one), made ``poor_fit``: it fits no better than :data:`RESCUE_SCALE` (:func:`_rescued`,
    :func:`_agreeing_restart`)."""
    result.status = Status.POOR_FIT
    note = (f"poor fit: the keypoints fit {scale:.3g} times worse than their sigmas in the best basin found"
            + ("" if first is None else f", {first:.3g} in the first")
            + f" (another start's solution is taken where it fits below {RESCUE_SCALE:g}); the estimate may be "
            "grossly wrong and its covariance too narrow")
    result.message = f"{note}; {result.message}" if result.message else note
    return result


def _typed_start(first: VehicleResult, body_type: str, obs: KeypointObservations, options: SolveOptions,
                 vehicle_id: str, prior, bounds, initial, hints, resize, model: ShapeModel) -> VehicleResult:
    """The vehicle solved again from ``body_type``'s own prior and mean shape (:func:`solve_observations`'
    ``start_prior``), a type far from the model's pooled prior; the better fit of ``first`` and that one (the lower
    ``fit_noise_scale``, a sane one before one that is not).

    A bus started from the light vehicles' pooled mean shape and prior: its first solve, held near a car's shape,
    can lead LM into another basin that the bus's prior then keeps (on `library_bus_2cam` at hard noise, seed 1:
    one bus 87 cm off with the pooled start, 37 cm from its own), or to a van or pickup that fits its keypoints
    poorly (seeds 10-29: 9 of 480 buses `poor_fit` at fit scales 2.4-4.0 and 1.7-5.7 m off, each 0.2-0.6 m off
    from the buses' start at fit scales 0.7-1.5; docs/results.md). So a type far from the pooled prior is tried
    where it was chosen or where the solution fits poorly (``poor_fit``) or has no estimate.
    """
    again = solve_observations(obs, options, vehicle_id, prior, bounds, initial, hints, resize,
                               start_prior=model.prior(body_type))
    if not again.ok:
        return first
    if first.ok and not _fits_better(_fit_score(again), _fit_score(first), first.status == Status.POOR_FIT):
        return first
    again.extras["typed_start"] = body_type
    return again


def _fit_score(result: VehicleResult) -> float:
    """How well a solution fits its keypoints, to choose between solutions of one vehicle: its ``fit_noise_scale``,
    or, where the solve estimates no noise scale (the sigmas as given, the same for all), its final error."""
    scale = result.extras.get("fit_noise_scale")
    return result.final_error if scale is None else scale


def _fits_better(score: float, than: float, poor_fit: bool) -> bool:
    """Whether a solution of a vehicle that fits at ``score`` (:func:`_fit_score`) replaces one that fits at ``than``:
    by any margin, or by more than :data:`RESTART_MARGIN` where that one is a poor fit (another basin that fits a few
    per cent better is no likelier right; a poor fit's further starts and its typed start)."""
    return score * (RESTART_MARGIN if poor_fit else 1.0) < than


#: A further start (up to ``SolveOptions.num_starts``) is optimised only while the best solution so far keeps fewer than
#: this share of the keypoints as inliers (robust-loss weight above 0.5): on 1476 simulated vehicles (library_2cam
#: seeds 5-8, accuracy_2cam and intersection_2cam seeds 0-1, three noise levels) a second start found a lower cost
#: once, where the first solution, turned by 180 degrees, kept 24 % of them; solutions within 90 degrees of the truth
#: keep at least 43 % (hard noise: 15 % outliers, 8 % swaps), 90 % at the median, and 0.9 % of them fewer than 60 %.
FURTHER_START_INLIERS = 0.6
#: An observation is an inlier of a solution where its robust-loss weight is above this (its whitened residual
#: within the loss's threshold).
INLIER_WEIGHT = 0.5


def _restarted(obs: KeypointObservations, options: SolveOptions, vehicle_id: str, prior, bounds, hints, resize,
               search: StartSearch, reached: list[gtsam.Pose3], solution: gtsam.Pose3,
               fit_scale: float | None, start_prior: ShapePrior | None = None) -> VehicleResult | None:
    """The vehicle solved again from further starts when its solution fits poorly or is not sane; None when no
    start gives a better one.

    Such a solution is most often in a wrong basin (turned, or held by one camera's outliers) that the first start
    led to, while its fit looked good enough at the first sigmas to try no other (:data:`FURTHER_START_INLIERS`).
    Each further start (the candidates of ``search`` by their robust cost, RANSAC PnP's included, that differ from
    every pose in ``reached`` and from the first ``solution``; at most ``options.poor_fit_restarts``) is solved in full
    (:func:`solve_observations` from it) until one fits below :data:`POOR_FIT_SCALE`. The best fit among them (the
    lowest noise scale; the lowest cost where the solve estimates none) is returned if it has an estimate and,
    where the first solution had one (``fit_scale``: its ``fit_noise_scale``; None: it was not sane), lies in
    another basin (:func:`vfactor.init.distinct_poses` from ``solution``) and fits better by more than
    :data:`RESTART_MARGIN`. Its
    ``extras["restarted"]``: the first solution's ``fit_noise_scale`` (None where it was not sane), the start's
    source and how many starts were solved. ``start_prior``: the first solve's (:func:`solve_observations`).
    """
    best, tried, reached = None, 0, reached + [solution]
    for candidate in search.best(None, ransac=True):
        if tried == options.poor_fit_restarts:
            break
        if not all(distinct_poses(candidate.world_T_vehicle, p) for p in reached):
            continue
        tried += 1
        reached.append(candidate.world_T_vehicle)
        result = solve_observations(obs, options, vehicle_id, prior, bounds,
                                    (candidate.world_T_vehicle, candidate.wireframe), hints, resize, start_prior)
        if not result.ok:
            continue
        reached.append(result.world_T_vehicle)
        scale, score = result.extras.get("fit_noise_scale"), _fit_score(result)
        better = fit_scale is None or (scale is not None and _fits_better(scale, fit_scale, True)
                                       and distinct_poses(result.world_T_vehicle, solution))
        if better and (best is None or score < best[0]):
            best = score, result, candidate.source
        if scale is not None and scale < POOR_FIT_SCALE:
            break
    if best is None:
        return None
    _, result, source = best
    result.extras["restarted"] = {"first_fit_noise_scale": None if fit_scale is None else float(fit_scale),
                                  "start": source, "starts": tried}
    return result


def _agreeing_restart(failed: VehicleResult, obs: KeypointObservations, options: SolveOptions, vehicle_id: str,
                      prior, bounds, hints, resize, mean: Wireframe, solution: gtsam.Pose3,
                      start_prior: ShapePrior | None) -> VehicleResult:
    """A vehicle whose solution the check of cameras at odds failed (``failed``), solved again from further starts
    (``mean`` placed by PnP with RANSAC under both labellings of each camera, as the check's own fits are;
    :func:`_restarted`, as a solution that is not sane): the best fit among their solutions that keep every camera's
    keypoints (each is solved in full and checked as the first was), where it fits below :data:`POOR_FIT_SCALE`,
    noting the cameras the first one rejected (``extras["cameras_at_odds_first"]``), and ``poor_fit`` unless it fits
    below :data:`RESCUE_SCALE` (as a poor fit's further start, :func:`_rescued`); ``failed`` where none does, or with
    ``options.poor_fit_restarts`` 0.

    With gross detection errors a camera's own keypoints can fit a vehicle of their own (a turned one, with its
    swapped pairs and outliers), and a joint solution that followed the other camera's keypoints then looks like a
    wrong ``world_T_camera``. Of a camera whose extrinsic is wrong, no vehicle found a start whose solution keeps
    every camera's keypoints and fits them in benchmarks/disagreement_check.py (docs/reliability.md, "Gross errors
    that fit a vehicle of their own").
    """
    if options.poor_fit_restarts == 0:
        return failed
    search = StartSearch(obs, mean, options.graph.loss, options.min_keypoints_in_one_view, True)
    restarted = _restarted(obs, options, vehicle_id, prior, bounds, hints, resize, search, [], solution, None,
                           start_prior)
    scale = None if restarted is None else restarted.extras.get("fit_noise_scale")
    if restarted is None or not restarted.ok or scale is None or scale >= POOR_FIT_SCALE:
        return failed  # no start explains both cameras' keypoints: at odds, as the first solution says
    names = failed.extras["disagreeing_cameras"]
    if restarted.status == Status.CONVERGED and scale >= RESCUE_SCALE:  # two basins, neither clearly right
        _poor_fit_in_another_basin(restarted, scale)
    _add_note(restarted, f"the first solution rejected the keypoints of camera(s) {', '.join(map(repr, names))}, "
                         "which fit a vehicle of their own; another start's solution keeps every camera's")
    restarted.extras["cameras_at_odds_first"] = names
    return restarted


def _inlier_share(obs: KeypointObservations, estimate: gtsam.Values, keys: KeyScheme, options: SolveOptions) -> float:
    """Share of the observations whose robust-loss weight at ``estimate`` is above 0.5 (whitened residual within the
    loss's threshold)."""
    e = whitened_residuals(obs, estimate.atPose3(keys.pose_key()), wireframe_from_values(estimate, keys).vehicle_p_keypoints)
    return float(np.mean(options.graph.loss.weight(np.linalg.norm(e, axis=1)) > INLIER_WEIGHT))


#: An observation whose whitened residual's square is beyond this (the 99 % point of chi2(2)) is an outlier to the
#: covariance.
INLIER_BOUND = 2.0 * np.log(100.0)
#: The covariances' noise scale is estimated by least squares on the observations whose whitened residual's square
#: at the solve's sigmas is within this (four times :data:`INLIER_BOUND`: about six sigmas; the solve's median scale
#: can be low, and a candidate beyond the inliers is still left out of the scale's mean square) ...
SCALE_CANDIDATE_BOUND = 4.0 * INLIER_BOUND
#: ... where at least this many are; else on all of them.
MIN_SCALE_CANDIDATES = 6


def _covariance_graph(graph: gtsam.NonlinearFactorGraph, obs: KeypointObservations, nominal: KeypointObservations,
                      scale: float, estimate: gtsam.Values, keys: KeyScheme,
                      options: SolveOptions) -> tuple[gtsam.NonlinearFactorGraph, float, KeypointObservations, float,
                                                      float | None]:
    """The graph whose marginals, times the returned factor, are the result's covariances, with that factor, the
    observations of its projection factor (the inliers, at the covariances' sigmas), their noise scale (what
    the nominal sigmas are multiplied by; calibrated ones are not narrowed by it: ``scale`` without
    ``options.estimate_noise``) and the parameters the keypoints determine (the hat matrix's trace; None without
    ``options.estimate_noise``).

    * **Inliers at full weight.** The Gauss-Newton information of a robust
      loss down-weights every observation by its residual, good ones too (the
      Cauchy loss gives a keypoint 1.5 sigmas off 63 % of its information),
      so its covariances come out too wide where the keypoints are clean.
      The projection factor is replaced by least squares on the inliers: the
      observations whose whitened residual's square is within
      :data:`INLIER_BOUND`, the others left out.
    * **The inliers' noise.** With ``options.estimate_noise``, their sigmas are
      the nominal ones times the solve's ``scale`` times
      :func:`~vfactor.shape_evidence.inlier_noise_scale` (read off least squares
      on the observations within :data:`SCALE_CANDIDATE_BOUND`, without the
      robust loss: the model the covariances are of), held above
      ``GraphConfig.covariance_min_pixel_sigma`` rather than the solve's
      ``min_pixel_sigma`` (clean keypoints are sharper than the solve's floor),
      and the factor is :func:`~vfactor.shape_evidence.covariance_inflation` of
      that scale's degrees of freedom (the Student t of an estimated scale);
      else the solve's sigmas and 1. ``nominal`` are the detector's sigmas with
      each camera's factor of the refinement where the cameras' noise differed
      (``extras["camera_noise_factors"]``).
    * **Calibrated sigmas are a floor.** An observation whose covariance is
      calibrated against the detector's true errors (``obs.calibrated``: the
      keypoint network's) keeps at least its nominal sigmas: a scale below 1
      is not applied to it. The network's errors are largely ones a pose and
      shape explain (an error shared by the keypoints of a detection), so the
      fit absorbs them and its residuals understate them: on rendered
      ``library_2cam`` images the inliers' scale came out about 0.5 where
      independent errors of the calibrated size give about 0.9, and the pose
      NEES 2.7x-4.5x (docs/network.md, "Covariances in the factor graph").
      When every observation keeps its nominal sigmas the scale is not an
      estimate and the factor is 1.

    ``graph`` is the solved graph: factor 0 its projection factor, with the
    observations ``obs`` (the solve's sigmas); ``nominal`` are the
    detector's. docs/factors.md gives the maths.
    """
    pose_key, layer_keys = keys.pose_key(), keys.layer_keys(0)
    world_T_vehicle = estimate.atPose3(pose_key)
    points = wireframe_from_values(estimate, keys).vehicle_p_keypoints
    inflation, noise, parameters = 1.0, scale, None
    if options.estimate_noise:
        floored = nominal.with_min_sigma(options.graph.covariance_min_pixel_sigma)
        obs = floored.scaled(scale)
        # the scale is read off least squares on the candidate inliers, the model the covariances are of: the robust
        # loss's down-weighting in the Hessian mispredicted the step to the covariance's sigmas (docs/factors.md)
        whitened = whitened_residuals(obs, world_T_vehicle, points)
        candidates = np.sum(whitened ** 2, axis=1) < SCALE_CANDIDATE_BOUND
        fitted = obs
        if candidates.sum() >= MIN_SCALE_CANDIDATES:
            fitted, whitened = obs.subset(candidates), whitened[candidates]
        at_scale = copy_graph(graph)
        raw = projection_factor(pose_key, layer_keys, fitted, RobustLoss("none"))
        at_scale.replace(0, raw)
        lin = with_extrinsics(linearise(at_scale, raw, None, estimate, keys), fitted, world_T_vehicle)
        relative, parameters, dof = inlier_noise_scale(whitened, lin)
        inflation, noise = covariance_inflation(dof), scale * relative
        calibrated = nominal.calibrated
        if calibrated is not None and noise < 1.0:  # calibrated sigmas are not narrowed
            obs = floored.scaled_above_calibrated(noise)
            inflation = 1.0 if calibrated.all() else inflation
        else:
            obs = obs.scaled(relative)
    if declares_extrinsics(obs.cameras):  # a camera's error is no outlier
        residuals = explained_residuals(obs, world_T_vehicle, points, options.graph.loss)
    else:
        residuals = whitened_residuals(obs, world_T_vehicle, points)
    within = np.sum(residuals ** 2, axis=1) < INLIER_BOUND
    if not within.any():  # sigmas far from the residuals (a refinement that failed at a detector's extreme sigmas)
        raise RuntimeError(f"no keypoint is within {np.sqrt(INLIER_BOUND):.3g} sigmas of the solution at the "
                           "covariances' sigmas")
    inliers = obs.subset(within)
    out = copy_graph(graph)
    out.replace(0, projection_factor(pose_key, layer_keys, inliers, RobustLoss("none")))
    return out, inflation, inliers, noise, parameters


def detector_shape_variance(obs: KeypointObservations, vehicle_p_keypoints: np.ndarray | None = None,
                            size_exponent: float = 0.0) -> float:
    """Variance (m^2, per axis of each body-frame keypoint) of a vehicle's shape from its detectors' errors shaped
    like a change of shape (``Detection.shape_sigma``; docs/factors.md, "Covariances", item 6).

    Each camera's detection errs by its own such error, and the fit averages the cameras' errors as it averages
    their views: ``1 / sum_c sigma_c^-2`` over the cameras whose detection has a ``shape_sigma`` (a camera's
    largest, if its observations differ), each at the size of the vehicle whose keypoints are
    ``vehicle_p_keypoints`` where given (:func:`vfactor.graph.shape_sigma_at_size` with ``size_exponent``); 0
    where none has.
    """
    return _averaged_variance(detector_shape_sigmas(obs, vehicle_p_keypoints, size_exponent))


def _averaged_variance(sigmas: dict[str, float]) -> float:
    """``1 / sum_c sigma_c^-2`` of camera name -> sigma (metres); 0 for none."""
    precision = sum(sigma ** -2 for sigma in sigmas.values())
    return 1.0 / precision if precision > 0 else 0.0


def detector_shape_covariance(covariance: np.ndarray, jacobian: np.ndarray, observations: KeypointObservations,
                              sigmas: dict[str, float]) -> np.ndarray:
    """(42, 42) covariance of the pose and shape that the detectors' errors shaped like a change of shape give the
    solution, through the fit.

    Camera ``c``'s detection errs as if it saw the vehicle's keypoints moved by ``d_c`` (36-vector, body frame,
    ``sigma_c`` metres per axis, a draw per detection); its whitened residuals then move by ``A_c,s d_c`` and the
    least-squares solution by ``G_c d_c``, ``G_c = P A_c^T A_c,s``, so that

    ``C_shape = sum_c sigma_c^2 G_c G_c^T``

    (``P = H^-1`` the covariance graph's, ``A_c`` that camera's rows of its projection factor's whitened Jacobian,
    ``A_c,s`` their 36 shape columns). The pose takes its share: an error the shape prior resists goes partly into it.

    Args:
        covariance: (42, 42) ``P``, the covariance graph's covariance of pose and shape (before the Student t's factor
            and the sandwich).
        jacobian: (2n, 42) the covariance graph's projection factor's whitened Jacobian, two rows per observation.
        observations: the n observations of those rows (their cameras).
        sigmas: camera name -> ``sigma_c`` (metres; :func:`vfactor.graph.detector_shape_sigmas`).
    """
    A = np.asarray(jacobian, dtype=float)
    rows = np.repeat(observations.camera_index, 2)
    seen = [(rows == c, sigmas.get(observations.cameras[c].name))  # the cameras that see the vehicle, not the scene's
            for c in np.unique(observations.camera_index)]
    return considered_covariance(covariance, A, ((mine, A[mine, 6:], np.full(36, sigma ** 2))
                                                 for mine, sigma in seen if sigma))


def _widened_by_residuals(joint: np.ndarray, inflation: float, linear: gtsam.GaussianFactorGraph, weight: float,
                          extras: dict, observations: KeypointObservations | None = None,
                          world_T_vehicle: gtsam.Pose3 | None = None, loss: RobustLoss | None = None) -> np.ndarray:
    """``joint`` (the model's (42, 42) covariance of pose and shape, times ``inflation``) widened where the residuals
    say the keypoints are off by more than it assumes: a covariance wider than both it and ``weight`` times the
    sandwich of the covariance graph ``linear`` (linearised at the solution; factor 0 its projection factor;
    docs/factors.md, "Covariances", item 5). The residuals are those the covariance graph's own least squares leaves
    (one Gauss-Newton step from the solution), not the solution's: the solve weighs the shape prior and the bounds
    otherwise (its own sigmas and robust loss), and the share of their pull that shows in the residuals is no
    spread of the keypoints. Where the cameras of ``observations`` (the projection factor's, at ``world_T_vehicle``)
    declare their extrinsics' errors, the residuals are taken less what those errors most likely make of them
    (:func:`vfactor.extrinsics.without_camera_errors`, with ``loss``): item 7 adds them. Sets
    ``extras["covariance_widening"]``; ``joint`` as it is where the sandwich is not defined (a numerically singular
    covariance)."""
    projection = linear.at(0)
    jacobian, rhs = projection.jacobian()  # columns [pose, wheel, light, roof]
    try:
        step = linear.optimize()
        rhs = rhs - jacobian @ np.concatenate([step.at(key) for key in projection.keys()])
        if observations is not None and declares_extrinsics(observations.cameras):
            rhs = without_camera_errors(rhs, jacobian[:, :6], observations, world_T_vehicle, loss)
        sandwich = sandwich_covariance(joint / inflation, jacobian, rhs)
        widened, widening = covariance_upper_bound(joint, weight * sandwich)
    except (np.linalg.LinAlgError, RuntimeError):
        return joint
    if not np.all(np.isfinite(widened)):
        return joint
    extras["covariance_widening"] = max(widening, 1.0)
    return widened


def _relabelled(best, obs: KeypointObservations, options: SolveOptions, prior: ShapePrior, keys: KeyScheme,
                bounds: HwcBounds, terms, hwc):
    """The first solution with the left/right labels it says are swapped exchanged
    (:func:`vfactor.label_swaps.relabel_swaps`), solved again from there.

    Returns:
        (the outcome of :func:`_optimise`, the observations, the findings); ``best`` and ``obs`` as they were when no
        pair is swapped or the new solve fails numerically.
    """
    estimate = best[0]
    relabelled, swaps = relabel_swaps(obs, estimate.atPose3(keys.pose_key()),
                                      wireframe_from_values(estimate, keys).vehicle_p_keypoints, options.graph.loss)
    if not swaps:
        return best, obs, []
    graph = build_vehicle_graph(relabelled, keys, config=options.graph, prior=prior, bounds=bounds,
                                ground_plane=options.ground_plane)
    try:
        outcome = _optimise(graph, estimate, keys, options, terms, hwc)
    except RuntimeError:
        return best, obs, []
    return (outcome[0], outcome[1], best[2] + outcome[2], best[3] or outcome[3], outcome[4]), relabelled, swaps


def _refine(first, obs: KeypointObservations, options: SolveOptions, model: ShapeModel | None, first_prior: ShapePrior,
            hints, keys: KeyScheme, bounds: HwcBounds, terms, hwc, passes: int = 3):
    """The refining solves: noise scale and body type read off the solution, then LM from it.

    Each pass linearises the graph at the current solution, estimates the noise
    scale (:func:`~vfactor.shape_evidence.noise_scale`; in all passes but the
    last, where the cameras' noise differs beyond chance, each camera's sigmas
    are first put on one scale, :func:`~vfactor.shape_evidence.camera_noise_factors`,
    ``extras["camera_noise_factors"]``: each camera's factor) and, with a model, the
    body type and prior spread (:func:`~vfactor.shape_evidence.choose_body_type`,
    with the prior of the graph removed from the information), and solves
    again from there with them. Passes stop when the scale moves by less than
    10 % and the choice stays: the first solution's residuals, fitted under the
    nominal sigmas and the pooled prior, overstate a small noise.

    Args:
        first: the outcome of :func:`_optimise` to refine, solved with ``obs`` at the detector's sigmas (the noise
            scale's fixed point reads the solution's residuals against the graph that made it; :func:`_rerefined`
            for a solution at other sigmas); ``first_prior`` the shape prior its graph holds.

    Returns:
        (the outcome of :func:`_optimise`, the observations with the estimated
        sigmas, extras: ``noise_scale``, ``effective_parameters``, ``passes``,
        and with a model ``body_type``, ``body_type_probability``,
        ``body_type_posterior``, ``prior_spread`` and ``shape_information``: the
        observations' (information, vector) on the shape,
        :func:`vfactor.shape_evidence.shape_information`; the prior the outcome's graph holds).
    """
    extras = {}
    outcome, scale, prior, scaled = first, 1.0, first_prior, obs
    for k in range(passes):
        estimate, graph = outcome[0], outcome[4]
        prior_factor = shape_prior_factor(keys.layer_keys(0), prior, options.graph.shape_prior_weight,
                                          options.graph.shape_prior_loss)
        lin = linearise(graph, graph.at(0), prior_factor, estimate, keys)
        new_scale, new_prior, cameras = scale, prior, None
        if options.estimate_noise:
            world_T_vehicle = estimate.atPose3(keys.pose_key())
            points = wireframe_from_values(estimate, keys).vehicle_p_keypoints
            relative, p_eff, cameras = noise_scale(whitened_residuals(scaled, world_T_vehicle, points), lin,
                                                   groups=obs.camera_index if k < passes - 1 else None)
            new_scale = float(np.clip(scale * relative, *NOISE_SCALE_RANGE))
            extras.update(effective_parameters=p_eff)
            if cameras is not None:  # the cameras' noise differs beyond chance: each camera's sigmas put on one scale
                obs = obs.scaled(cameras)
                found = extras.setdefault("camera_noise_factors", {})
                for c in np.unique(obs.camera_index):
                    name = obs.cameras[int(c)].name
                    found[name] = found.get(name, 1.0) * float(cameras[obs.camera_index == c][0])
        if model is not None:
            information, eta = shape_information(lin, (scale / new_scale) ** 2)
            choice = choose_body_type(model, information, eta, hints)
            new_prior = choice.prior
            extras.update(body_type=choice.body_type, body_type_probability=choice.probability,
                          body_type_posterior=choice.posterior, prior_spread=choice.spread,
                          shape_information=(information, eta))
        if (k > 0 and cameras is None and _same_prior(new_prior, prior)
                and abs(np.log(new_scale / scale)) < np.log(1.1)):
            break
        scale, prior = new_scale, new_prior
        scaled = obs.scaled(scale)
        graph = build_vehicle_graph(scaled, keys, config=options.graph, prior=prior, bounds=bounds,
                                    ground_plane=options.ground_plane)
        estimate, error, iterations, hit_limit, graph = _optimise(graph, estimate, keys, options, terms, hwc)
        outcome = (estimate, error, outcome[2] + iterations, hit_limit or outcome[3], graph)
        extras["passes"] = k + 1
    extras["noise_scale"] = scale
    return outcome, scaled, extras, prior


#: Where the refined noise scale is above this, the observations beyond :data:`GROSS_OUTLIER_SIGMAS` of the refined
#: solution are left out and the refinement run again (:func:`_refitted_without_gross_outliers`).
REFIT_SCALE = 1.0
#: An observation whose whitened residual at the refined solution (refined sigmas) is beyond this many sigmas is a
#: gross outlier: the Cauchy loss still gives it a pull of about ``k^2 / n`` (k = 2.5), enough, with a free shape and
#: several of them, to bend the shape towards them.
GROSS_OUTLIER_SIGMAS = 4.0


def _refitted_without_gross_outliers(refined, scaled: KeypointObservations, nominal: KeypointObservations,
                                     extras: dict, prior: ShapePrior, options: SolveOptions, model: ShapeModel | None,
                                     hints, keys: KeyScheme, bounds: HwcBounds, terms, hwc):
    """The refined solution, solved and refined again without its gross outliers.

    The robust loss down-weights an outlier but does not remove it: a Cauchy
    loss keeps a pull that falls only as ``1 / n`` with the residual, and where
    the shape is free, a few outliers in one camera bend it (at hard noise,
    with the outliers removed by the truth, the factor graph came within 1.1x
    of the known-shape reference for every body type: docs/results.md). Where
    the refined keypoints fit worse than their sigmas (noise scale above
    :data:`REFIT_SCALE`), the observations beyond
    :data:`GROSS_OUTLIER_SIGMAS` of the solution (at the refined sigmas) are
    left out (none of a camera of which that would leave out more than half: a
    camera at odds with the others is the camera check's to judge), and the
    rest solved again from the refined solution (:func:`_rerefined`: LM, then
    the noise scale and the body type estimated again). Not done with the loss
    ``none`` (plain least squares, as asked).

    Returns:
        (outcome, scaled observations, nominal observations, extras, prior, the indices of the rows of ``nominal``
        left out, or None when none was or the refit failed numerically: then the refined solution as it was).
    """
    estimate = refined[0]
    residual = np.linalg.norm(whitened_residuals(scaled, estimate.atPose3(keys.pose_key()),
                                                 wireframe_from_values(estimate, keys).vehicle_p_keypoints), axis=1)
    keep = residual <= GROSS_OUTLIER_SIGMAS
    for camera in np.unique(nominal.camera_index):  # most of a camera beyond: the camera is at odds, not its keypoints
        rows = nominal.camera_index == camera
        if keep[rows].sum() < 0.5 * rows.sum():
            keep[rows] = True
    if keep.all() or keep.sum() < options.min_observations:
        return refined, scaled, nominal, extras, prior, None
    kept = nominal.subset(keep)
    try:
        outcome, kept_scaled, more, kept_prior = _rerefined(refined, kept, options, model, prior, hints, keys, bounds,
                                                            terms, hwc)
    except (RuntimeError, np.linalg.LinAlgError):
        return refined, scaled, nominal, extras, prior, None
    return outcome, kept_scaled, kept, more, kept_prior, np.flatnonzero(~keep)


def _rerefined(refined, obs: KeypointObservations, options: SolveOptions, model: ShapeModel | None,
               prior: ShapePrior, hints, keys: KeyScheme, bounds: HwcBounds, terms, hwc):
    """:func:`_refine` again, for other observations (labels swapped, outliers left out) of a refined solution: LM at
    the detector's sigmas with ``prior`` from ``refined``'s solution, then the refinement from there (a refinement
    started at a large estimated scale converges slowly: the H-1 of tests/test_label_swaps.py was at 2.4 after three
    passes from 4, 0.9 from the detector's sigmas). Same returns as :func:`_refine`."""
    graph = build_vehicle_graph(obs, keys, config=options.graph, prior=prior, bounds=bounds,
                                ground_plane=options.ground_plane)
    start = _optimise(graph, refined[0], keys, options, terms, hwc)
    start = (start[0], start[1], refined[2] + start[2], refined[3] or start[3], start[4])
    return _refine(start, obs, options, model, prior, hints, keys, bounds, terms, hwc)


#: A solution whose estimated noise scale (the keypoints' residuals against their sigmas, :func:`_refine`; over every
#: keypoint, before :func:`_refitted_without_gross_outliers` leaves any out: ``extras["fit_noise_scale"]``) is at
#: least this is reported ``poor_fit`` (:class:`~vfactor.result.Status`), not ``converged``. At hard noise (15 %
#: outliers, 8 % swaps) on library_2cam seeds 0-8, 20-29 and 53-62 (2436 vehicles) 13 solutions reached it, 12 of
#: them 9-179 degrees off (the other 6; the median solution is 3 degrees off), and none of the other solutions was
#: more than 30 degrees off; at paper-like noise (3 %, 5 % outliers) none of 840 reached 1.4. A detector whose sigmas are half its
#: real errors makes every vehicle a poor fit: its sigmas are wrong (docs/reliability.md).
POOR_FIT_SCALE = 2.0
#: A poor fit (at least :data:`POOR_FIT_SCALE`) that a further start (a restart, or a far type's start) solves in
#: another basin is ``converged`` only where that solution fits below this: a basin that fits a little under the
#: threshold is no answer to which basin is right (hard noise, library_2cam seeds 489-513: a Passat and a Superb at
#: 1.59 and 1.99, 23 and 25 degrees off, where the first fit 2.1 and 3.3; seeds 489-513 and 599-628: two CAD cars at
#: 1.60 and 1.98, 5 and 7 degrees off, are now poor fits too).
RESCUE_SCALE = 1.5
#: A further start's solution of a poor fit replaces the first only where its ``fit_noise_scale`` is lower by more
#: than this factor: about one standard deviation of a scale estimated from some 30 degrees of freedom
#: (``1 / sqrt(2 nu)``); closer, the two basins fit alike and the first (the best start's) is kept. At hard noise on
#: library_2cam seeds 599-628 three poor fits moved to a basin fitting 5-10 % better, 170, 60 and 36 degrees off where
#: the first were 10-17 degrees off; one 11 % better went from 23 to 10 degrees.
RESTART_MARGIN = 1.1


#: The refined solution searches for left/right swaps the relabelling missed (:func:`_searched_swaps`) when its noise
#: scale is above this: its keypoints fit worse than their sigmas say. On library_2cam seeds 0-8 at hard noise
#: (756 vehicles; 15 % outliers, 8 % swaps) 57 refined solutions had a scale above 1.2, and they held 17 of the 23
#: rotation errors above 10 degrees; with the swaps undone by the truth their mean rotation error went from 9.2 to 5.2
#: degrees. At paper-like noise 7 of 756 reach it.
SWAP_SEARCH_SCALE = 1.2
#: At most this many swaps are added by the search, one per round.
SWAP_SEARCH_ROUNDS = 4


def _searched_swaps(refined, scaled: KeypointObservations, nominal: KeypointObservations, extras: dict,
                    prior: ShapePrior, options: SolveOptions, model: ShapeModel | None, hints, keys: KeyScheme,
                    bounds: HwcBounds, terms, hwc):
    """The refined solution with the left/right swaps found by solving for them, refined again.

    The relabelling judges each pair at the first solution; where a camera has
    several swapped pairs that solution is already bent around them, and each
    pair, judged there, seems right as given. Here each pair with a
    down-weighted keypoint (:func:`vfactor.label_swaps.suspect_pairs`, at the
    refined sigmas) is swapped in turn and LM run from the refined solution
    with the refined sigmas and prior; the swap whose solution costs least, at
    least :data:`~vfactor.label_swaps.SWAP_MARGIN` below the current one, is
    kept, and the search goes on from there (at most
    :data:`SWAP_SEARCH_ROUNDS` swaps). When a swap is kept the noise scale and
    the body type are estimated again (:func:`_refine`).

    Args:
        refined: :func:`_refine`'s outcome; ``scaled`` its observations at the refined sigmas, ``nominal`` the same at
            the detector's, ``extras`` and ``prior`` its extras and the prior its graph holds.

    Returns:
        (outcome, scaled observations, nominal observations, extras, the prior the outcome's graph holds, the swaps
        found: each finding's ``gain`` the fall in cost, the number of solves tried). When no swap is kept, or the
        refinement after it fails numerically, the refined solution as it was.
    """
    outcome, found, tried = refined, [], 0
    searched, searched_nominal = scaled, nominal
    for _ in range(SWAP_SEARCH_ROUNDS):
        estimate = outcome[0]
        best = None
        for rows in suspect_pairs(searched, estimate.atPose3(keys.pose_key()),
                                  wireframe_from_values(estimate, keys).vehicle_p_keypoints, options.graph.loss):
            swapped, finding = swapped_rows(searched, rows)
            graph = build_vehicle_graph(swapped, keys, config=options.graph, prior=prior, bounds=bounds,
                                        ground_plane=options.ground_plane)
            tried += 1
            try:
                candidate = _optimise(graph, estimate, keys, options, terms, hwc)
            except RuntimeError:
                continue
            gain = outcome[1] - candidate[1]
            if gain >= SWAP_MARGIN and (best is None or gain > best[0]):
                best = (gain, swapped, finding, candidate)
        if best is None:
            break
        gain, searched, finding, candidate = best
        searched_nominal = apply_swaps(searched_nominal, [finding])
        found = merge_findings(found, [dataclasses.replace(finding, gain=gain)])
        outcome = (candidate[0], candidate[1], outcome[2] + candidate[2], outcome[3] or candidate[3], candidate[4])
    if not found:
        return refined, scaled, nominal, extras, prior, [], tried
    try:
        outcome, searched, more, searched_prior = _rerefined(outcome, searched_nominal, options, model, prior, hints,
                                                             keys, bounds, terms, hwc)
    except (RuntimeError, np.linalg.LinAlgError):
        return refined, scaled, nominal, extras, prior, [], tried
    return outcome, searched, searched_nominal, more, searched_prior, found, tried


def _same_prior(a: ShapePrior, b: ShapePrior, mean_tol: float = 0.02, sigma_tol: float = 0.2) -> bool:
    """Whether two priors are the same for the solve: means within ``mean_tol`` m, sigmas within ``sigma_tol`` (relative)."""
    if a is b:
        return True
    if np.abs(np.asarray(a.mean) - np.asarray(b.mean)).max() > mean_tol:
        return False
    da, db = np.sqrt(np.diag(a.covariance)), np.sqrt(np.diag(b.covariance))
    return bool(np.abs(da / db - 1.0).max() <= sigma_tol)


def _optimise(graph, values, keys: KeyScheme, options: SolveOptions, terms, hwc):
    """LM on ``graph``; with ``hwc="lazy"``, again with the HWC factor when the shape breaks HWC; and once more from
    :func:`~vfactor.factors.body_frame.canonical_gauge` when the solution's body frame is turned front to back (the
    same pixels, a lower prior cost).

    Args:
        terms: the HWC terms (:func:`vfactor.graph.hwc_terms`).
        hwc: the vehicle's HWC factor made of ``terms``.

    Returns:
        (estimate, cost, iterations, hit the iteration limit, the graph finally used).
        The cost always includes the HWC factor's error, so that starts which did
        and did not need it compare on the same objective; without the factor that
        error is half the squared norm of the HWC residuals the check computed.
    """
    estimate, cost, iterations, hit_limit, graph, check = _lm(graph, values, keys, options, terms, hwc,
                                                               options.graph.hwc == "lazy")
    turned = canonical_gauge(estimate, (keys.pose_key(),), keys.layer_keys(0))
    if turned is not None:
        estimate, cost, more, hit_limit, graph, _ = _lm(graph, turned, keys, options, terms, hwc, check)
        iterations += more
    return estimate, cost, iterations, hit_limit, graph


def _lm(graph, values, keys: KeyScheme, options: SolveOptions, terms, hwc, check_hwc: bool):
    """:func:`_optimise`'s LM: with ``check_hwc``, again with the HWC factor added when the shape breaks HWC.

    Returns:
        (estimate, cost, iterations, hit the iteration limit, the graph used, whether HWC is still to be checked:
        ``check_hwc`` unless the factor was added).
    """
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, options.lm_params())
    estimate, iterations, cost = optimizer.optimize(), optimizer.iterations(), optimizer.error()
    if check_hwc:
        residuals = hwc_residuals(wireframe_from_values(estimate, keys), terms)
        if float(np.abs(residuals).max()) > options.graph.hwc_tolerance:
            graph = copy_graph(graph)
            graph.add(hwc)
            optimizer = gtsam.LevenbergMarquardtOptimizer(graph, estimate, options.lm_params())
            estimate, cost = optimizer.optimize(), optimizer.error()
            iterations += optimizer.iterations()
            check_hwc = False
        else:
            cost += 0.5 * float(residuals @ residuals)  # hwc.error(estimate), from the residuals of the check
    return estimate, cost, iterations, optimizer.iterations() >= options.max_iterations, graph, check_hwc


#: A camera is at odds with the others when the joint solution keeps less than this share of its keypoints ...
DISAGREEMENT_JOINT_INLIERS = 0.3
#: ... and a pose fitted to its keypoints alone (PnP of the mean shape) keeps this many more (a share of them).
DISAGREEMENT_MARGIN = 0.55
#: ... unless, with its declared extrinsic error's plausible part explained, it keeps at least this share.
EXPLAINED_INLIERS = 0.5


def _add_note(result: VehicleResult, note: str) -> None:
    """Appends ``note`` to a result's message (``"; "`` between them)."""
    result.message = f"{result.message}; {note}" if result.message else note


def _view_cut(obs: KeypointObservations, rows: np.ndarray) -> bool:
    """Whether the image border cuts the view of the vehicle that the observations ``rows`` (one camera's) come
    from (``obs.cut``)."""
    return obs.cut is not None and bool(rows.any()) and bool(obs.cut[rows].all())


def _cut_views(obs: KeypointObservations, exclude=()) -> list[str]:
    """Names of the cameras (but ``exclude``) whose view of the vehicle the image border cuts."""
    return [camera.name for c, camera in enumerate(obs.cameras)
            if camera.name not in exclude and _view_cut(obs, obs.camera_index == c)]


def _camera_disagreement(obs: KeypointObservations, weights: np.ndarray, mean: Wireframe, options: SolveOptions,
                         explained: Callable[[], np.ndarray] | None = None) -> tuple[str, list[str], list[str]]:
    """A message when some camera's keypoints agree among themselves but not with the other cameras, naming it,
    the names of those cameras ("" and [] when none), and the names of the cameras that would be named but whose
    view of the vehicle the image border cuts (``obs.cut``: a detector may draw a whole vehicle in the part it
    sees, consistent and wrong; those are not blamed on the camera).

    A camera is at odds when the joint solution rejects its keypoints (fewer
    than :data:`DISAGREEMENT_JOINT_INLIERS` of them have a robust-loss weight
    above 0.5) while a pose fitted to its keypoints alone (robust PnP of the
    mean shape) keeps at least :data:`DISAGREEMENT_MARGIN` more of them: its
    keypoints make sense as one vehicle, only elsewhere than where the other
    cameras see it, which points to its ``world_T_camera``. A camera whose
    keypoints are mostly outliers (heavy noise, swaps) is rejected by both fits
    and is not blamed. Measured by benchmarks/disagreement_check.py
    (docs/reliability.md). ``explained``: gives the robust-loss weights of the
    keypoints with each camera's declared extrinsic error's plausible part
    explained (:func:`vfactor.extrinsics.explained_residuals`; called only
    where a camera would be named); a camera that
    keeps at least :data:`EXPLAINED_INLIERS` of its keypoints so is off by
    about what it declares, and not at odds. The message also says when, as a
    camera sees it, the vehicle lies behind another camera.
    """
    rejected, cut, loss = [], [], options.graph.loss
    for c, camera in enumerate(obs.cameras):
        rows = obs.camera_index == c
        if rows.sum() < options.min_keypoints_in_one_view:
            continue
        joint = float(np.mean(weights[rows] > INLIER_WEIGHT))
        if joint >= DISAGREEMENT_JOINT_INLIERS:  # the joint solve keeps the camera: no PnP
            continue
        own = own_pose(obs, c, mean, loss)  # the camera's own PnP pose of the mean shape (fitted once per view)
        if own is None:
            continue
        alone = loss.weight(np.linalg.norm(whitened_residuals(obs.subset(rows), own, mean.vehicle_p_keypoints), axis=1))
        if float(np.mean(alone > INLIER_WEIGHT)) - joint < DISAGREEMENT_MARGIN - 1e-9:
            continue
        if explained is not None and float(np.mean(explained()[rows] > INLIER_WEIGHT)) >= EXPLAINED_INLIERS:
            continue  # off by about its declared extrinsic error
        (cut if _view_cut(obs, rows) else rejected).append(camera.name)
    if not rejected:
        return "", [], cut
    details = []
    for c in range(len(obs.cameras)):
        if (obs.camera_index == c).sum() < options.min_keypoints_in_one_view:
            continue
        own = own_pose(obs, c, mean, loss)
        if own is None:
            continue
        world = mean.in_world(own)
        for d, other in enumerate(obs.cameras):
            if d != c and (obs.camera_index == d).any() and np.median(other.to_camera(world)[:, 2]) <= 0:
                details.append(f"as camera '{obs.cameras[c].name}' sees it, the vehicle lies behind camera "
                               f"'{other.name}'")
    text = f"the keypoints of camera(s) {', '.join(repr(n) for n in rejected)} disagree with the other cameras"
    seeing = [camera.name for c, camera in enumerate(obs.cameras)
              if (obs.camera_index == c).sum() >= options.min_keypoints_in_one_view]
    if len(seeing) == 2 and len(rejected) == 1:  # two cameras cannot tell which of them is off: both are named
        followed = seeing[1] if seeing[0] in rejected else seeing[0]
        text = (f"the keypoints of cameras {seeing[0]!r} and {seeing[1]!r} disagree (two cameras cannot tell "
                f"which one is off; the joint solve followed {followed!r})")
    if details:
        text += "; " + "; ".join(details)
    hint = (" (or fit the cameras to their traffic: vfactor fit-extrinsics)" if explained is not None else
            " (or, where a camera is known only to a survey's accuracy, give its extrinsic_sigma and fit the cameras "
            "to their traffic: vfactor fit-extrinsics)")
    return text + ": check the cameras' world_T_camera" + hint, rejected, cut


def solve_vehicle(
    detections: list[Detection],
    cameras: dict[str, Camera],
    options: SolveOptions = SolveOptions(),
    vehicle_id: str | None = None,
    prior: ShapePrior | ShapeModel | None = None,
    bounds: HwcBounds | None = None,
) -> VehicleResult:
    """Estimates one vehicle's pose, shape and covariances from its detections in one frame.

    Args:
        detections: the vehicle's detections, one per camera that saw it.
        cameras: camera name -> camera (must hold every detection's camera).
        options: solver settings.
        vehicle_id: track id for the result (defaults to the detections' id).
        prior: the body-type shape model (default: :func:`~vfactor.shape_model.default_shape_model`,
            learnt from the vehicle library), or one :class:`~vfactor.shape_model.ShapePrior`
            to use for every vehicle (e.g. :func:`~vfactor.shape_model.default_shape_prior`, the paper's car prior).
        bounds: HWC bounds (default: the model's, spanning the library, PASCAL3D+ cars and presets).

    Returns:
        A :class:`VehicleResult`; ``degenerate`` when too little is seen.

    Raises:
        InputError: a detection names an unknown camera.
    """
    vehicle_id = vehicle_id or (detections[0].vehicle if detections else "vehicle")
    obs = observations_from_detections(detections, cameras, options.graph)
    return solve_observations(obs, options, vehicle_id, prior, bounds, hints=class_hints(detections),
                              resize=partial(resized_observations, detections, cameras, options.graph))


def solve_frame(frame: Frame, cameras: dict[str, Camera], options: SolveOptions = SolveOptions(), **kwargs) -> FrameResult:
    """Solves every vehicle of a frame, each on its own.

    Each result's ``extras["detections"]`` holds the indices of its detections in ``frame.detections``.
    A vehicle whose solve raises (an unknown camera, a numerical failure) is
    reported as ``failed`` with the message; the others are still solved.
    """
    return FrameResult(frame.t, [_solve_unit(_unit(frame, vid, cameras, options, kwargs)) for vid in frame.vehicle_ids()])


def _unit(frame: Frame, vehicle_id: str, cameras: dict[str, Camera], options: SolveOptions, kwargs: dict) -> tuple:
    """The unit of work of the one-frame solve (:mod:`vfactor.parallel`): one vehicle in one frame."""
    return frame.detections_of(vehicle_id), frame.indices_of(vehicle_id), cameras, options, vehicle_id, kwargs


def _solve_unit(unit: tuple) -> VehicleResult:
    """Solves one :func:`_unit`; a solve that raises (an unknown camera, a numerical failure) is a ``failed``
    result with the message."""
    detections, indices, cameras, options, vehicle_id, kwargs = unit
    try:
        result = solve_vehicle(detections, cameras, options, vehicle_id, **kwargs)
    except (InputError, RuntimeError, np.linalg.LinAlgError) as exc:
        result = VehicleResult(vehicle_id, Status.FAILED, message=summarise_error(exc))
    result.extras["detections"] = indices
    return result


def iter_solve_scene(scene: Scene, options: SolveOptions = SolveOptions(), progress: Callable[[int, int], None] | None = None,
                     engine=None, **kwargs) -> Iterator[FrameResult]:
    """:func:`solve_scene` one frame at a time: yields each frame's result, in the scene's order, as soon as it
    and every frame before it are solved (what ``vfactor solve`` writes as it goes).

    Args:
        engine: where the vehicles are solved (:mod:`vfactor.parallel`; default: in this process, one after
            another). The results do not depend on it.
        progress: called as ``progress(done, total)`` with the vehicles solved so far.

    Raises:
        InputError: a detection still waits for the keypoint network or for association
            (:meth:`~vfactor.observations.Scene.require_keypoints`).
    """

    scene.require_keypoints()
    options = options.for_scene(scene)
    engine = engine or InProcess()
    counts = [len(frame.vehicle_ids()) for frame in scene.frames]
    units = (_unit(frame, vid, scene.cameras, options, kwargs) for frame in scene.frames for vid in frame.vehicle_ids())
    results = engine.map(_solve_unit, units, progress=progress, total=sum(counts))
    solved = vehicles = 0
    for i, (frame, count) in enumerate(zip(scene.frames, counts)):
        out = FrameResult(frame.t, [next(results) for _ in range(count)])
        for v in out.vehicles:
            log.debug("frame %d (t = %g s) vehicle %r: %s after %d iterations, body type %s, noise scale %.2f%s", i,
                      frame.t, v.id, v.status.value, v.iterations, v.body_type, v.extras.get("noise_scale", float("nan")),
                      f": {v.message}" if v.message else "")
        solved, vehicles = solved + sum(v.ok for v in out.vehicles), vehicles + count
        yield out
    log.info("solved %d of %d vehicles in %d frames, %d cameras", solved, vehicles, len(scene.frames), len(scene.cameras))


def solve_scene(
    scene: Scene, options: SolveOptions = SolveOptions(), progress: Callable[[int, int], None] | None = None,
    engine=None, **kwargs
) -> list[FrameResult]:
    """Solves every frame of a scene, every vehicle on its own (``vfactor solve``).

    When the scene gives a road plane and ``options.ground_plane`` is None, the
    scene's plane is used (the ground-plane factor on every vehicle).

    Args:
        scene: the scene.
        options: solver settings.
        progress: called as ``progress(done, total)`` with the vehicles solved so far.
        engine: where the vehicles are solved: a :class:`vfactor.parallel.DaskEngine` spreads them over a Dask
            cluster; default: in this process. The results are the same.
        **kwargs: passed to :func:`solve_vehicle` (``prior``, ``bounds``).

    Returns:
        One :class:`~vfactor.result.FrameResult` per frame, in the scene's order.

    Raises:
        InputError: a detection still waits for the keypoint network or for association
            (:meth:`~vfactor.observations.Scene.require_keypoints`).
    """
    return list(iter_solve_scene(scene, options, progress, engine, **kwargs))
