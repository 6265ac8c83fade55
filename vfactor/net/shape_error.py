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
(:func:`vfactor.solve.detector_shape_variance`). :func:`fit_shape_sigma` finds
the ``shape_sigma`` whose widened keypoint covariances give the keypoints' mean
NEES its consistent value, 3 (three degrees of freedom), on the vehicles of
rendered scenes solved from the network's keypoints (:func:`measure_vehicles`).
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
from vfactor.net.end_to_end import render_and_detect
from vfactor.solve import SolveOptions

__all__ = ["VehicleErrors", "measure_vehicles", "fit_shape_sigma", "keypoint_nees_at"]


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
    """

    error: np.ndarray
    covariance: np.ndarray
    cameras: int
    body_type: str
    vehicle_p_keypoints: np.ndarray | None = None


def measure_vehicles(scenario: str, seeds, detector=None, options: SolveOptions = SolveOptions(),
                     frames: int | None = None, progress=None) -> list[VehicleErrors]:
    """Renders the scenes of ``scenario`` for each seed, finds the keypoints with the network and solves every
    vehicle (each with the shape model learnt without it, :func:`vfactor.evaluation.solve_held_out`), without any
    shape error of the detector.

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
        for f, frame in enumerate(detected.frames):
            for vid in frame.vehicle_ids():
                truth = sim.truth[f][vid]
                detections = [dataclasses.replace(d, shape_sigma=None) for d in frame.detections_of(vid)]
                obs = observations_from_detections(detections, detected.cameras, options.graph)
                result = solve_held_out(obs, truth.preset, options, vid,
                                        tuple(d.vehicle_class for d in detections if d.vehicle_class))
                if not result.ok or result.keypoint_covariances_world is None:
                    continue
                out.append(VehicleErrors(np.asarray(result.keypoints_world) - np.asarray(truth.keypoints_world),
                                         np.asarray(result.keypoint_covariances_world),
                                         len({d.camera for d in detections}), body_type_of(truth.preset),
                                         np.asarray(result.wireframe.vehicle_p_keypoints)))
    return out


def keypoint_nees_at(vehicles: list[VehicleErrors], shape_sigma: float, size_exponent: float = 0.0) -> np.ndarray:
    """(N, 12) keypoint NEES of each vehicle with its covariances widened by a detector shape error of
    ``shape_sigma`` metres per camera at the reference size, taken at each vehicle's size with ``size_exponent``
    (:func:`vfactor.graph.shape_sigma_at_size`; ``sigma^2 / cameras`` per axis)."""
    if not vehicles:
        return np.zeros((0, 12))
    error = np.stack([v.error for v in vehicles])
    cameras = np.array([max(v.cameras, 1) for v in vehicles], dtype=float)
    sigma = np.array([shape_sigma if v.vehicle_p_keypoints is None
                      else shape_sigma_at_size(shape_sigma, v.vehicle_p_keypoints, size_exponent) for v in vehicles])
    widened = np.stack([v.covariance for v in vehicles]) + (sigma ** 2 / cameras)[:, None, None, None] * np.eye(3)
    return np.einsum("nki,nki->nk", error, np.linalg.solve(widened, error[..., None])[..., 0])


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
