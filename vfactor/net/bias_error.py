"""The keypoint network's error that repeats over a vehicle's frames and cameras, fitted on rendered tracks.

The network sees one vehicle much alike in every frame and from every
camera: its keypoints of that vehicle err together, frame after frame, as
if the vehicle stood a little elsewhere (a few centimetres along it, a
fraction of a degree in roll and pitch). A track that counts each frame as
new evidence averages the frames' independent errors away, but not this
one, so its poses' covariances come out narrower than their errors
(docs/results.md, "Tracking from images").

The model: the detections of one track share a rigid motion ``b`` of the
vehicle in its body frame (``Pose3`` coordinates: rotation about x, y, z in
radians, then shift along them in metres), drawn once per vehicle with the
standard deviations ``bias_sigma``, on top of each camera's own offset
(``shape_sigma``'s, docs/factors.md "The detector's pose offset in tracks").
:func:`measure_track_bias` estimates ``b`` for each track of a rendered scene
with what the simulation knows held fixed (every pose at its truth) and the
shape free (the shape model of the vehicle's body type, learnt without it),
together with the variance of that estimate from the data; the data's share
is taken out of the spread of the estimates (:func:`fit_bias_sigma`, by
moments) so that what is left is the spread of ``b`` itself.
``python -m vfactor.net calibrate-bias`` renders the scenes, runs both and,
with ``--write``, stores the result in the weights' calibration
(:attr:`vfactor.net.calibrate.CovarianceCalibration.bias_sigma`); the
pipeline then gives it to every detection (``Detection.bias_sigma``).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from vfactor.evaluation import body_type_of, held_out_scene_model
from vfactor.graph import (
    GraphConfig,
    add_observation_factor,
    add_shape_factors,
    detector_offset_prior,
    insert_vehicle_values,
    observations_from_detections,
)
from vfactor.keys import KeyScheme

__all__ = ["TrackBias", "measure_track_bias", "measure_rendered_tracks", "fit_bias_sigma"]

#: Tracks seen in fewer frames than this are not measured: their bias is not told from their frames' noise.
MIN_FRAMES = 10
#: The weak prior (sigmas of rotation, radians, and shift, metres) of ``b`` while it is measured.
_LOOSE = np.r_[0.2, 0.2, 0.2, 2.0, 2.0, 2.0]
_HELD = gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)


@dataclass(frozen=True)
class TrackBias:
    """One track's repeated error of the detector.

    Attributes:
        vehicle: the track's id.
        body_type: the truth's body type (or ``"pascal3d"``).
        frames: frames the track was seen in.
        bias: (6,) the estimate of ``b``: rotation about the body x, y, z (radians), shift along them (metres).
        variance: (6,) the variance of that estimate from the data alone (its marginal, same units squared).
    """

    vehicle: str
    body_type: str
    frames: int
    bias: np.ndarray
    variance: np.ndarray


def measure_track_bias(sim, detected, config: GraphConfig = GraphConfig(),
                       min_frames: int = MIN_FRAMES) -> list[TrackBias]:
    """The repeated error of each track of a scene whose keypoints a detector found.

    Per track seen in at least ``min_frames`` frames: every pose held at its truth, the shape free with the prior
    of its body type from the shape model learnt without the scene's vehicle models, each camera's detector offset
    (where its detections carry a ``shape_sigma``) tied to the common offset ``b`` as tracks tie them, ``b`` with a
    weak prior; Levenberg-Marquardt, then ``b`` and its marginal variance.

    Args:
        sim: the :class:`vfactor.sim.Simulation` (its truth).
        detected: the scene with the detector's keypoints (as :func:`vfactor.net.end_to_end.render_and_detect`
            gives it).
        config: the factor graph's noise settings.
        min_frames: the fewest frames a measured track has.
    """
    keys = KeyScheme()
    model = held_out_scene_model(sim)
    tracks: dict[str, dict[int, list]] = {}
    for f, frame in enumerate(detected.frames):
        for d in frame.detections:
            if np.count_nonzero(d.confidence > 0) >= 3:
                tracks.setdefault(d.vehicle, {}).setdefault(f, []).append(d)
    out = []
    for vid, frames in tracks.items():
        if len(frames) < min_frames:
            continue
        truth = sim.truth[min(frames)][vid]
        body_type = body_type_of(truth.preset)
        prior = model.prior(body_type) if body_type in model.types else model.pooled
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        add_shape_factors(graph, keys, 0, config, prior, model.bounds)
        insert_vehicle_values(values, keys, None, truth.wireframe, 0)
        common = keys.offset_key(0, 0)
        values.insert(common, gtsam.Pose3())
        graph.add(gtsam.PriorFactorPose3(common, gtsam.Pose3(), gtsam.noiseModel.Diagonal.Sigmas(_LOOSE)))
        offsets: dict[str, int] = {}
        for f, detections in sorted(frames.items()):
            for d in detections:
                if d.camera not in offsets:
                    offsets[d.camera] = key = keys.offset_key(0, len(offsets) + 1)
                    values.insert(key, gtsam.Pose3())
                    if d.shape_sigma:  # the camera's own part, as a track's offsets have it
                        graph.add(detector_offset_prior(key, float(d.shape_sigma),
                                                        truth.wireframe.vehicle_p_keypoints, common,
                                                        config.shape_sigma_size_exponent))
                    else:
                        graph.add(gtsam.BetweenFactorPose3(common, key, gtsam.Pose3(), _HELD))
            obs = observations_from_detections(detections, detected.cameras, config)
            pose_key = keys.pose_key(0, f)
            add_observation_factor(graph, keys, obs, 0, f, config, offsets)
            values.insert(pose_key, sim.truth[f][vid].world_T_vehicle)
            graph.add(gtsam.PriorFactorPose3(pose_key, sim.truth[f][vid].world_T_vehicle, _HELD))
        estimate = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
        variance = np.diag(gtsam.Marginals(graph, estimate).marginalCovariance(common))
        out.append(TrackBias(vid, body_type, len(frames), gtsam.Pose3.Logmap(estimate.atPose3(common)), variance))
    return out


def measure_rendered_tracks(scenario: str, seeds, detector=None, frames: int | None = None,
                            progress=None) -> list[TrackBias]:
    """Renders the scenes of the track scenario ``scenario`` for each seed, finds the keypoints with the network
    and measures each track's repeated error (:func:`measure_track_bias`).

    Args:
        scenario: packaged scenario name or file (cameras need ``image_size``; vehicles seen over several frames).
        seeds: simulation and rendering seeds.
        detector: a :class:`~vfactor.net.infer.KeypointDetector`; None: the shipped weights.
        frames: frames per seed (default: the scenario's).
        progress: called with ``(images rendered, images total)`` per seed.
    """
    from vfactor.net.end_to_end import render_and_detect  # noqa: PLC0415  (torch and the renderer: only here)

    out = []
    for seed in seeds:
        sim, _, detected, detector = render_and_detect(scenario, int(seed), frames, detector, progress=progress)
        out += measure_track_bias(sim, detected)
    return out


def fit_bias_sigma(tracks: list[TrackBias]) -> np.ndarray:
    """``bias_sigma`` (6,) by moments: per coordinate the root of the mean square of the tracks' estimates less the
    mean variance the data leave them (0 where the data explain the whole spread).

    Raises:
        ValueError: no tracks.
    """
    if not tracks:
        raise ValueError("fit_bias_sigma: no measured tracks to fit on")
    bias = np.stack([t.bias for t in tracks])
    variance = np.stack([t.variance for t in tracks])
    return np.sqrt(np.maximum(np.mean(bias ** 2, axis=0) - np.mean(variance, axis=0), 0.0))
