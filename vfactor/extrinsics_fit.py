"""The cameras' extrinsic errors fitted to their traffic: a rig calibrated by the vehicles it sees.

A survey gives each camera's ``world_T_camera`` to a fraction of a degree and a
few centimetres (:attr:`vfactor.camera.Camera.extrinsic_sigma`); at 30 m, 0.3
degrees moves a vehicle 16 cm. One vehicle cannot tell a camera's error from
its own pose (:mod:`vfactor.extrinsics` carries the error as a *consider*
parameter), but many can: every vehicle seen by two cameras says where each
camera is relative to the other, and a road plane where the rig's roll, pitch
and height are. :func:`fit_extrinsics` solves the scene's vehicles one frame at
a time, then all of them at once with each camera's error ``E_c`` (the true
pose ``world_T_camera * E_c``) as a variable under the prior its
``extrinsic_sigma`` gives:

* each vehicle (an id of a scene: a track) has one shape, with its shape
  factors and prior (the body type its solves chose most often), and a pose
  in each frame it was solved in, with the ground-plane factor where the
  scene gives a road plane;
* each camera's keypoints of it enter through the projection factor with that
  camera's error key (:func:`vfactor.factors.projection.projection_factor`'s
  ``camera_key``), at the solve's sigmas and labels, with the solve's robust
  loss; a camera that declares no sigma is held where it is given;
* Levenberg-Marquardt from the one-frame solutions and ``E_c = I``, then the
  marginal covariance of each ``E_c``;
* once more (``rounds``, 2 by default), the vehicles solved again with the
  cameras as fitted: solved with the survey's cameras, their keypoints'
  noise scales are widened by the cameras' disagreement (the fit's residuals
  came out at 0.51-0.69 of their sigmas with a survey off by 1 degree, and
  its covariances too narrow), and their outliers and relabelled pairs chosen
  under it.

The result's cameras are the given ones moved by their fitted errors, each
with the marginal standard deviations as its new ``extrinsic_sigma``: later
solves and tracks of the rig then carry what is left of the error
(docs/factors.md, "Covariances", item 7). What the vehicles cannot see stays
with the prior: without a road plane the rig's common motion (every camera
moved and turned together moves every vehicle with it), with one its common
yaw and horizontal shift. The command ``vfactor fit-extrinsics`` fits a
scene's cameras and writes it back with them. docs/factors.md ("The cameras'
errors fitted to the traffic") gives the maths, docs/results.md what it gives.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np

from vfactor.camera import SAME_PLACE, Camera, moved
from vfactor.errors import InputError
from vfactor.factors.projection import KeypointObservations, projection_factor
from vfactor.factors.robust import RobustLoss
from vfactor.graph import add_ground_factor, add_shape_factors, insert_vehicle_values, sized_observations
from vfactor.keys import KeyScheme
from vfactor.label_swaps import apply_swaps
from vfactor.observations import Scene
from vfactor.result import FrameResult, Status, VehicleResult
from vfactor.shape_evidence import median_scale
from vfactor.shape_model import ShapeModel, default_shape_model
from vfactor.solve import SolveOptions
from vfactor.stats import chi2_quantile
from vfactor.wireframe import Wireframe

__all__ = ["ExtrinsicsFit", "fit_extrinsics", "MIN_VEHICLES", "MIN_VIEW_KEYPOINTS", "PLAUSIBLE_CORRECTION"]

#: At least this many vehicle poses (a vehicle in a frame) seen by two cameras make a fit.
MIN_VEHICLES = 20
#: A camera's view of a vehicle counts where it has at least this many keypoints.
MIN_VIEW_KEYPOINTS = 4
#: The chi2 (6 dof) probability within which a camera's fitted error is plausible under its declared sigma; a
#: correction beyond it is noted (the survey is further off than it says, or the camera moved).
PLAUSIBLE_CORRECTION = 0.999
_NO_LOSS = RobustLoss("none")
_ERROR_KEY = "e"  # gtsam.Symbol character of the cameras' error variables (vfactor's KeyScheme does not use it)


@dataclass(frozen=True)
class ExtrinsicsFit:
    """The cameras' errors fitted to the traffic.

    Attributes:
        cameras: camera name -> the camera moved by its fitted error (``world_T_camera * Exp(correction)``), with
            the fit's standard deviations as its ``extrinsic_sigma``; a camera that declared none, as given.
        corrections: camera name -> (6,) the fitted error ``xi`` (rotation rad about the camera's axes, then
            translation m along them; its true pose is the given ``world_T_camera * Exp(xi)``), for the cameras
            fitted.
        covariances: camera name -> (6, 6) the marginal covariance of that error, same order.
        poses: how many vehicle poses (a vehicle in a frame) the fit rests on.
        views: camera name -> how many of those poses it saw.
        iterations: Levenberg-Marquardt iterations.
        residual_scale: the keypoints' whitened residuals at the fit, a robust scale (1: as their sigmas say).
        notes: what the caller should know (a correction beyond the declared sigma, a camera no vehicle showed).
    """

    cameras: dict[str, Camera]
    corrections: dict[str, np.ndarray]
    covariances: dict[str, np.ndarray]
    poses: int
    views: dict[str, int]
    iterations: int
    residual_scale: float
    notes: tuple[str, ...] = ()

    def rotation_deg(self, camera: str) -> np.ndarray:
        """(3,) the fitted rotation error of ``camera`` about its axes, degrees."""
        return np.degrees(self.corrections[camera][:3])

    def translation_m(self, camera: str) -> np.ndarray:
        """(3,) the fitted translation error of ``camera`` along its axes, metres."""
        return self.corrections[camera][3:].copy()


def fit_extrinsics(scenes: Scene | Sequence[Scene], results: Sequence[Sequence[FrameResult]] | None = None,
                   options: SolveOptions = SolveOptions(), default_sigma: np.ndarray | None = None,
                   shared_shape: bool = True, rounds: int = 2, engine=None,
                   model: ShapeModel | None = None) -> ExtrinsicsFit:
    """Fits the errors of the cameras of ``scenes`` (one rig: the same cameras where each scene has them) to the
    vehicles they see (the module's docstring gives the method).

    Args:
        scenes: one scene or several of the same rig (more traffic, a better fit); every detection names its
            vehicle (associate first) and has keypoints.
        results: per scene, its one-frame solves (:func:`vfactor.solve.solve_scene`, with these cameras); None:
            solved here with ``options`` (without covariances).
        options: the one-frame solves' settings, whose graph settings (loss, shape factors, ground-plane sigmas)
            the fit takes too.
        default_sigma: (6,) the extrinsic sigma (rad, m; :func:`vfactor.camera.extrinsic_sigma`) of the cameras
            that declare none; None: those cameras are held where they are given.
        shared_shape: each vehicle id of a scene is one vehicle (a track) with one shape over its frames; False: a
            shape per frame (ids that do not follow one vehicle).
        rounds: fits; each after the first solves the vehicles again with the cameras as the last one fitted them
            (the priors stay the survey's): the first fit takes the vehicles as the survey's cameras solved them,
            their noise scales widened and their outliers chosen by the cameras' disagreement.
        engine: where the vehicles are solved (:mod:`vfactor.parallel`, e.g. a
            :class:`~vfactor.parallel.DaskEngine`; default: in this process): the same fit. The joint fit runs here.
        model: the body-type shape model of the solves and the fit (default:
            :func:`~vfactor.shape_model.default_shape_model`).

    Returns:
        :class:`ExtrinsicsFit`.

    Raises:
        InputError: no camera to fit (none declares an ``extrinsic_sigma`` and no ``default_sigma``), scenes of
            different rigs, ``results`` that are not one list per scene, fewer than :data:`MIN_VEHICLES` vehicle
            poses seen by two cameras with :data:`MIN_VIEW_KEYPOINTS` keypoints each, or a fit that fails.
    """
    from vfactor.solve import solve_scene

    model = default_shape_model() if model is None else model
    if not isinstance(rounds, int) or isinstance(rounds, bool) or rounds < 1:
        raise InputError("rounds", f"expected an integer >= 1, got {rounds!r}")
    scenes = [scenes] if isinstance(scenes, Scene) else list(scenes)
    if not scenes:
        raise InputError("scenes", "expected at least one scene")
    cameras = _rig(scenes)
    sigmas = _prior_sigmas(cameras, default_sigma)
    solve = dataclasses.replace(options, covariance=False)
    if results is None:
        results = [solve_scene(scene, solve, engine=engine, prior=model) for scene in scenes]
    elif len(results) != len(scenes):
        raise InputError("results", f"expected one list of frame results per scene ({len(scenes)}), got {len(results)}")
    corrections = {name: np.zeros(6) for name in sigmas}
    for round_ in range(rounds):
        if round_:  # the vehicles solved again with the cameras as fitted: better starts, labels, inliers
            fitted = _moved(cameras, corrections)
            results = [solve_scene(dataclasses.replace(scene, cameras={**scene.cameras, **fitted}), solve,
                                   engine=engine, prior=model) for scene in scenes]
        corrections, covariances, count, views, iterations, scale = _joint_fit(scenes, results, sigmas, corrections,
                                                                               options, shared_shape, model)
    fitted = {**cameras, **_moved(cameras, corrections, covariances)}
    notes = []
    plausible = chi2_quantile(6, PLAUSIBLE_CORRECTION)
    for name, xi in corrections.items():
        if not views[name]:
            notes.append(f"camera {name!r} saw none of the vehicles fitted: it keeps its given pose and sigma")
        elif float(np.sum((xi / sigmas[name]) ** 2)) > plausible:
            notes.append(f"camera {name!r} is off by more than its extrinsic_sigma says (rotation "
                         f"{np.degrees(np.linalg.norm(xi[:3])):.2f} deg, translation {100 * np.linalg.norm(xi[3:]):.1f}"
                         " cm): the survey errs more, or the camera moved")
    return ExtrinsicsFit(fitted, corrections, covariances, count, views, iterations, scale, tuple(notes))


def _joint_fit(scenes: list[Scene], results, sigmas: dict[str, np.ndarray], start: dict[str, np.ndarray],
               options: SolveOptions, shared_shape: bool,
               model: ShapeModel) -> tuple[dict, dict, int, dict, int, float]:
    """One fit of the cameras' errors (the module's docstring) to the solved vehicles of ``results``, from the
    errors ``start``, under the priors ``sigmas`` about the scenes' cameras as given, each track's shape under
    ``model``'s prior of its body type.

    Returns:
        (camera name -> fitted error (6,), -> its covariance (6, 6); the vehicle poses fitted; camera name -> how
        many of them it saw; LM iterations; the robust scale of the keypoints' whitened residuals at the fit).
    """
    keys = KeyScheme()
    error_keys = {name: gtsam.symbol(_ERROR_KEY, i) for i, name in enumerate(sorted(sigmas))}
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for name, key in error_keys.items():
        values.insert(key, gtsam.Pose3.Expmap(start[name]))
        graph.add(gtsam.PriorFactorPose3(key, gtsam.Pose3(), gtsam.noiseModel.Diagonal.Sigmas(sigmas[name])))
    views = {name: 0 for scene in scenes for name in scene.cameras}
    tracks: dict[tuple[int, str], list] = {}  # (scene, vehicle id) -> its solved poses: (frame, result, observations)
    for s, (scene, frames) in enumerate(zip(scenes, results)):
        for f, (frame, solved) in enumerate(zip(scene.frames, frames)):
            for result in solved.vehicles:
                obs = _fitted_observations(scene, frame, result, options)
                if obs is not None:
                    tracks.setdefault((s, result.id) if shared_shape else (s, f"{result.id}@{f}"), []).append(
                        (f, result, obs))
    count, projections = 0, []
    for v, ((s, _), poses) in enumerate(tracks.items()):
        plane = options.ground_plane if options.ground_plane is not None else scenes[s].ground_plane
        chosen = [result.body_type for _, result, _ in poses if result.body_type in model.types]
        prior = model.prior(max(set(chosen), key=chosen.count)) if chosen else model.pooled
        add_shape_factors(graph, keys, v, options.graph, prior)
        shape = np.median([result.wireframe.vehicle_p_keypoints for _, result, _ in poses], axis=0)
        insert_vehicle_values(values, keys, None, Wireframe(shape), v)
        for f, result, obs in poses:
            for c in np.unique(obs.camera_index):
                name = obs.cameras[c].name
                views[name] += 1
                view = (keys.pose_key(v, f), keys.layer_keys(v), obs.subset(obs.camera_index == c),
                        error_keys.get(name))
                projections.append(view)
                graph.add(_view_factor(view, options.graph.loss))
            add_ground_factor(graph, keys, plane, v, f, options.graph, prior)
            insert_vehicle_values(values, keys, result.world_T_vehicle, None, v, f)
            count += 1
    if count < MIN_VEHICLES:
        raise InputError("scenes", f"{count} vehicle poses seen by two cameras with {MIN_VIEW_KEYPOINTS} keypoints "
                                   f"each; fitting the cameras needs at least {MIN_VEHICLES} (more traffic: more "
                                   "frames or --traffic scenes)")
    params = options.lm_params()
    params.setMaxIterations(max(options.max_iterations, 100))
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    try:
        estimate = optimizer.optimize()
        marginals = gtsam.Marginals(graph, estimate)
        covariances = {name: np.asarray(marginals.marginalCovariance(key)) for name, key in error_keys.items()}
    except RuntimeError as exc:
        raise InputError("scenes", f"the cameras' fit failed: {str(exc).splitlines()[0]}") from None
    corrections = {name: gtsam.Pose3.Logmap(estimate.atPose3(key)) for name, key in error_keys.items()}
    squares = np.concatenate([  # the whitened residuals themselves, without the robust loss's scaling
        np.sum(np.reshape(_view_factor(view, _NO_LOSS).unwhitenedError(estimate), (-1, 2)) ** 2, axis=1)
        for view in projections])
    return corrections, covariances, count, views, int(optimizer.iterations()), median_scale(squares)


def _view_factor(view: tuple, loss: RobustLoss) -> gtsam.CustomFactor:
    """The projection factor of one camera's keypoints of one vehicle pose: ``view`` is (pose key, layer keys, those
    observations, the camera's error key or None)."""
    pose_key, layer_keys, obs, camera_key = view
    return projection_factor(pose_key, layer_keys, obs, loss, camera_key=camera_key)


def _moved(cameras: dict[str, Camera], corrections: dict[str, np.ndarray],
           covariances: dict[str, np.ndarray] | None = None) -> dict[str, Camera]:
    """The cameras of ``corrections`` moved by them (``world_T_camera * Exp(xi)``), with the square roots of the
    ``covariances``' diagonals as their ``extrinsic_sigma`` where given."""
    out = {}
    for name, xi in corrections.items():
        sigma = cameras[name].extrinsic_sigma if covariances is None else np.sqrt(np.diag(covariances[name]))
        out[name] = dataclasses.replace(cameras[name], extrinsic_sigma=sigma,
                                        world_T_camera=cameras[name].pose.compose(gtsam.Pose3.Expmap(xi)).matrix())
    return out


def _rig(scenes: list[Scene]) -> dict[str, Camera]:
    """The cameras of ``scenes`` (the first scene's); InputError where another scene has them elsewhere."""
    cameras = dict(scenes[0].cameras)
    for i, scene in enumerate(scenes[1:], start=1):
        for name, camera in scene.cameras.items():
            if name not in cameras:
                cameras[name] = camera
                continue
            difference = moved(camera, cameras[name])
            if difference > SAME_PLACE:
                raise InputError(f"scenes[{i}].cameras.{name}", "not where the first scene has it (world_T_camera "
                                 f"differs by up to {difference:.3g}): the cameras of one rig are fitted together")
    return cameras


def _prior_sigmas(cameras: dict[str, Camera], default_sigma) -> dict[str, np.ndarray]:
    """Camera name -> (6,) the prior sigma of its error: its ``extrinsic_sigma``, else ``default_sigma``."""
    if default_sigma is not None:
        default_sigma = np.asarray(default_sigma, dtype=float)
        if default_sigma.shape != (6,) or not np.all(np.isfinite(default_sigma)) or not np.all(default_sigma > 0):
            raise InputError("default_sigma", "expected 6 positive numbers (rotation rad, translation m), got "
                                              f"{default_sigma.tolist()}")
    sigmas = {name: camera.extrinsic_sigma if camera.extrinsic_sigma is not None else default_sigma
              for name, camera in cameras.items()}
    sigmas = {name: np.asarray(s, dtype=float) for name, s in sigmas.items() if s is not None}
    if not sigmas:
        raise InputError("extrinsic_sigma", "no camera declares the accuracy of its pose: give the cameras to fit "
                                            "an extrinsic_sigma (docs/scene-format.md), or a default_sigma (vfactor "
                                            "fit-extrinsics --extrinsic-sigma)")
    return sigmas


def _fitted_observations(scene: Scene, frame, result: VehicleResult,
                         options: SolveOptions) -> KeypointObservations | None:
    """A solved vehicle's observations as its solve took them in the end (sized by the vehicle it found, its labels,
    its noise scale, without what it left out), where two cameras see it with :data:`MIN_VIEW_KEYPOINTS`
    keypoints each; None otherwise (not solved, a poor fit, one view)."""
    if not result.ok or result.status == Status.POOR_FIT or result.wireframe is None:
        return None
    detections = frame.detections_of(result.id)
    if len(detections) < 2:
        return None
    obs = sized_observations(detections, scene.cameras, options.graph, result.world_T_vehicle, result.wireframe)
    obs = apply_swaps(obs, result.extras.get("swapped_keypoints") or [])
    left_out = result.extras.get("outliers_left_out")
    if left_out is not None and len(left_out):
        kept = np.ones(len(obs), dtype=bool)
        kept[np.asarray(left_out, dtype=int)] = False
        obs = obs.subset(kept)
    seen = np.bincount(obs.camera_index, minlength=len(obs.cameras)) >= MIN_VIEW_KEYPOINTS
    if seen.sum() < 2:
        return None
    obs = obs.subset(seen[obs.camera_index])
    return obs.camera_scaled(result.extras.get("camera_noise_factors")).scaled(
        float(result.extras.get("noise_scale", 1.0)))
