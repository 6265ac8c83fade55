"""The keypoint network's error shaped like a change of the vehicle's shape, fitted on solved rendered scenes.

The network's pixel covariances are calibrated keypoint by keypoint
(:mod:`vfactor.net.calibrate`), but the errors of one detection are not
independent: the network sees a vehicle it does not know as one it does, so
its keypoints err together, like those of a slightly other shape. The factor
graph then takes that error into the shape, and the residuals never show it:
from the network's keypoints the world keypoints' NEES was about 1.7x where the
simulator's independent keypoint noise gives about 1.0x (docs/network.md).

The model: each detection's keypoints are those of the vehicle's shape plus an
error of the shape, isotropic with ``shape_sigma`` metres per axis and keypoint,
drawn anew per detection. Averaged over a vehicle's ``n`` cameras it adds
``shape_sigma^2 / n`` to the variance of every body-frame keypoint
(:func:`vfactor.solve.detector_shape_variance`), and passed through the fit it
moves the pose as well (:func:`vfactor.solve.detector_shape_covariance`,
``GraphConfig.shape_error_through_fit``; docs/factors.md, "Covariances", item
6). :func:`fit_shape_sigma` finds the ``shape_sigma`` whose widened keypoint
covariances give the keypoints' mean NEES its consistent value, 3 (three
degrees of freedom), on the vehicles of rendered scenes solved from the
network's keypoints (:func:`measure_vehicles`).
``python -m vfactor.net calibrate-shape`` runs both and, with ``--write``,
stores the result in the weights' calibration
(:attr:`vfactor.net.calibrate.CovarianceCalibration.shape_sigma`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from vfactor.evaluation import body_type_of, solve_held_out
from vfactor.graph import observations_from_detections, shape_sigma_at_size
from vfactor.metrics import pose_tangent_error
from vfactor.net.end_to_end import render_and_detect
from vfactor.observations import class_hints
from vfactor.solve import SolveOptions

__all__ = ["VehicleErrors", "measure_vehicles", "vehicle_errors", "fit_shape_sigma", "keypoint_nees_at",
           "pose_nees_at"]


@dataclass(frozen=True)
class VehicleErrors:
    """One solved vehicle against its truth.

    Attributes:
        error: (12, 3) world keypoint errors (estimate - truth), metres.
        covariance: (12, 3, 3) the result's world keypoint covariances without a shape error, m^2.
        cameras: how many cameras saw the vehicle.
        body_type: the truth's body type (or ``"pascal3d"``).
        vehicle_p_keypoints: (12, 3) the solution's keypoints (body frame, metres): the size the detector's error
            is taken at (:func:`vfactor.graph.shape_sigma_at_size`); None: the reference size.
        unit_covariance: (12, 3, 3) what a detector's error of the shape whose sigma at the vehicle's size is 1 m
            per camera adds to ``covariance``, as the solve adds it (both parts; m^2 per m^2 of that sigma squared);
            None: ``I / cameras`` (the shape block alone).
        pose_error: (6,) ``Logmap(estimate^-1 truth)`` (rad, m; :func:`vfactor.metrics.pose_tangent_error`), or None.
        pose_covariance: (6, 6) the result's pose covariance without a shape error, or None.
        pose_unit_covariance: (6, 6) what that error adds to it, or None (nothing).
    """

    error: np.ndarray
    covariance: np.ndarray
    cameras: int
    body_type: str
    vehicle_p_keypoints: np.ndarray | None = None
    unit_covariance: np.ndarray | None = None
    pose_error: np.ndarray | None = None
    pose_covariance: np.ndarray | None = None
    pose_unit_covariance: np.ndarray | None = None


def measure_vehicles(scenario: str, seeds, detector=None, options: SolveOptions = SolveOptions(),
                     frames: int | None = None, progress=None) -> list[VehicleErrors]:
    """Renders the scenes of ``scenario`` for each seed, finds the keypoints with the network and solves every
    vehicle (each with the shape model learnt without it, :func:`vfactor.evaluation.solve_held_out`), without any
    shape error of the detector and again with one of 1 m per camera taken as given (:func:`vehicle_errors`: the
    same solution; the covariances' difference is what the detector's error adds per m^2 of its sigma^2, which
    :func:`keypoint_nees_at` and :func:`pose_nees_at` scale by each vehicle's sigma at its size).

    Args:
        scenario: packaged scenario name or file (cameras need ``image_size``).
        seeds: simulation and rendering seeds.
        detector: a :class:`~vfactor.net.infer.KeypointDetector`; None: the shipped weights.
        options: the factor graph's options.
        frames: frames per seed (default: the scenario's).
        progress: called with ``(images rendered, images total)`` per seed.

    Returns:
        The vehicles solved with covariances.
    """
    out = []
    for seed in seeds:
        sim, _, detected, detector = render_and_detect(scenario, int(seed), frames, detector, progress=progress)
        out += vehicle_errors(sim, detected, options)
    return out


def vehicle_errors(sim, detected, options: SolveOptions = SolveOptions()) -> list[VehicleErrors]:
    """Every vehicle of a detected scene solved (each with the shape model learnt without it) without any shape
    error of the detector and with one of 1 m per camera taken as given, against the simulation's truth
    (:func:`measure_vehicles`).

    Args:
        sim: the :class:`~vfactor.sim.Simulation` the scene was rendered from (its truth).
        detected: the scene with the detector's keypoints (``sim``'s frames and vehicle ids).
        options: the factor graph's options.
    """
    as_given = dataclasses.replace(options.graph, shape_sigma_size_exponent=0.0)  # the unit error's sigma is 1 m
    unit_options = dataclasses.replace(options, graph=as_given)
    out = []
    for f, frame in enumerate(detected.frames):
        for vid in frame.vehicle_ids():
            truth = sim.truth[f][vid]
            hints = class_hints(frame.detections_of(vid))
            results = []
            for sigma, opts in ((None, options), (1.0, unit_options)):  # the same solution, two covariances
                detections = [dataclasses.replace(d, shape_sigma=sigma) for d in frame.detections_of(vid)]
                obs = observations_from_detections(detections, detected.cameras, opts.graph)
                results.append(solve_held_out(obs, truth.preset, opts, vid, hints))
            result, unit = results
            if not (result.ok and unit.ok) or result.keypoint_covariances_world is None or \
                    unit.keypoint_covariances_world is None:
                continue
            out.append(VehicleErrors(
                np.asarray(result.keypoints_world) - np.asarray(truth.keypoints_world),
                np.asarray(result.keypoint_covariances_world), len({d.camera for d in detections}),
                body_type_of(truth.preset), np.asarray(result.wireframe.vehicle_p_keypoints),
                unit_covariance=np.asarray(unit.keypoint_covariances_world) -
                np.asarray(result.keypoint_covariances_world),
                pose_error=pose_tangent_error(result.world_T_vehicle, truth.world_T_vehicle),
                pose_covariance=np.asarray(result.pose_covariance),
                pose_unit_covariance=np.asarray(unit.pose_covariance) - np.asarray(result.pose_covariance)))
    return out


def _sigmas_at_size(vehicles: list[VehicleErrors], shape_sigma: float, size_exponent: float) -> np.ndarray:
    return np.array([shape_sigma if v.vehicle_p_keypoints is None
                     else shape_sigma_at_size(shape_sigma, v.vehicle_p_keypoints, size_exponent) for v in vehicles])


def keypoint_nees_at(vehicles: list[VehicleErrors], shape_sigma: float, size_exponent: float = 0.0) -> np.ndarray:
    """(N, 12) keypoint NEES of each vehicle with its covariances widened by a detector shape error of
    ``shape_sigma`` metres per camera at the reference size, taken at each vehicle's size with ``size_exponent``
    (:func:`vfactor.graph.shape_sigma_at_size`): ``sigma^2`` times the vehicle's ``unit_covariance``, or
    ``sigma^2 / cameras`` per axis where it has none."""
    if not vehicles:
        return np.zeros((0, 12))
    error = np.stack([v.error for v in vehicles])
    unit = np.stack([v.unit_covariance if v.unit_covariance is not None else np.eye(3) / max(v.cameras, 1)
                     * np.ones((12, 1, 1)) for v in vehicles])
    sigma = _sigmas_at_size(vehicles, shape_sigma, size_exponent)
    widened = np.stack([v.covariance for v in vehicles]) + sigma[:, None, None, None] ** 2 * unit
    return np.einsum("nki,nki->nk", error, np.linalg.solve(widened, error[..., None])[..., 0])


def pose_nees_at(vehicles: list[VehicleErrors], shape_sigma: float, size_exponent: float = 0.0) -> np.ndarray:
    """(N,) pose NEES of each vehicle with its pose covariance widened as :func:`keypoint_nees_at` widens the
    keypoints' (``sigma^2`` times its ``pose_unit_covariance``); NaN for a vehicle without a pose error."""
    out = np.full(len(vehicles), np.nan)
    for i, (v, sigma) in enumerate(zip(vehicles, _sigmas_at_size(vehicles, shape_sigma, size_exponent))):
        if v.pose_error is None or v.pose_covariance is None:
            continue
        widened = v.pose_covariance + (sigma ** 2 * v.pose_unit_covariance if v.pose_unit_covariance is not None
                                       else 0.0)
        out[i] = float(v.pose_error @ np.linalg.solve(widened, v.pose_error))
    return out


def fit_shape_sigma(vehicles: list[VehicleErrors], target: float = 3.0, upper: float = 1.0,
                    size_exponent: float = 0.0) -> float:
    """The detector shape error (metres, at the reference size; each vehicle's taken at its size with
    ``size_exponent``, :func:`keypoint_nees_at`) that gives the vehicles' keypoints a mean NEES of ``target``.

    The mean NEES falls as the shape error grows, so the root is found by bisection in ``[0, upper]``; 0 where the
    keypoints are already consistent or too wide (mean NEES at most ``target`` without a shape error).

    Raises:
        ValueError: no vehicles, or even ``upper`` metres leave the mean NEES above ``target``.
    """
    if not vehicles:
        raise ValueError("fit_shape_sigma: no solved vehicles to fit on")
    mean = lambda s: float(np.mean(keypoint_nees_at(vehicles, s, size_exponent)))  # noqa: E731
    if mean(0.0) <= target:
        return 0.0
    if mean(upper) > target:
        raise ValueError(f"fit_shape_sigma: a shape error of {upper} m still leaves the keypoints' mean NEES above "
                         f"{target}")
    lo, hi = 0.0, upper
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mean(mid) > target else (lo, mid)
    return 0.5 * (lo + hi)
