"""The network's repeated error per vehicle: the measurement finds a known one, the fit recovers a known spread, the
command reports bad input, the calibration carries it to the detections."""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from vfactor.net.bias_error import TrackBias, fit_bias_sigma, measure_track_bias  # noqa: E402
from vfactor.net.calibrate import CovarianceCalibration  # noqa: E402
from vfactor.net.infer import KeypointDetector, default_weights_path  # noqa: E402
from vfactor.sim import load_scenario, simulate  # noqa: E402
from vfactor.sim.noise import NoiseModel  # noqa: E402


def test_the_fit_recovers_a_known_spread_less_the_data_share():
    rng = np.random.default_rng(0)
    sigma = np.array([0.01, 0.012, 0.002, 0.02, 0.01, 0.02])
    data = np.array([0.005, 0.003, 0.003, 0.012, 0.01, 0.008])
    tracks = [TrackBias("v", "sedan", 30, rng.normal(size=6) * np.sqrt(sigma ** 2 + data ** 2), data ** 2)
              for _ in range(4000)]
    np.testing.assert_allclose(fit_bias_sigma(tracks), sigma, rtol=0.1, atol=5e-4)
    only_noise = [TrackBias("v", "sedan", 30, rng.normal(size=6) * data, data ** 2) for _ in range(4000)]
    assert np.all(fit_bias_sigma(only_noise) < 0.3 * data)  # the data explain (almost) the whole spread
    with pytest.raises(ValueError, match="no measured tracks"):
        fit_bias_sigma([])


def test_the_measurement_finds_each_tracks_shared_motion():
    """Keypoints moved by one known rigid motion of each vehicle in every frame and camera (plus the simulator's
    small pixel noise): each track's measured motion is that one, within a few times its own sigma."""
    clean = dataclasses.replace(load_scenario("library_tracks_2cam"),
                                noise=NoiseModel(relative_sigma=0.003, outlier_rate=0, swap_rate=0, missing_rate=0))
    sim = simulate(clean, seed=4, num_frames=12)
    rng = np.random.default_rng(1)
    vehicles = sorted({v for frame in sim.truth for v in frame})
    xi = {v: rng.normal(size=6) * [0.01, 0.01, 0.005, 0.05, 0.03, 0.03] for v in vehicles}
    frames = []
    for f, frame in enumerate(sim.scene.frames):
        detections = []
        for d in frame.detections:
            truth = sim.truth[f][d.vehicle]
            moved = truth.world_T_vehicle.compose(gtsam.Pose3.Expmap(xi[d.vehicle])).transformFrom(
                truth.wireframe.vehicle_p_keypoints.T).T
            camera = sim.scene.cameras[d.camera]
            shift = camera.project(moved)[0] - camera.project(truth.keypoints_world)[0]
            detections.append(dataclasses.replace(d, keypoints=d.keypoints + shift, shape_sigma=0.04))
        frames.append(dataclasses.replace(frame, detections=detections))
    detected = dataclasses.replace(sim.scene, frames=frames)
    tracks = measure_track_bias(sim, detected)
    seen = {v: sum(any(d.vehicle == v for d in frame.detections) for frame in detected.frames) for v in vehicles}
    assert sorted(t.vehicle for t in tracks) == [v for v in vehicles if seen[v] >= 10] and len(tracks) >= 2
    for t in tracks:
        assert t.frames == seen[t.vehicle] and np.all(t.variance > 0)
        assert np.all(np.abs(t.bias - xi[t.vehicle]) < 4 * np.sqrt(t.variance) + 1e-3), (t.bias, xi[t.vehicle])
    # too few frames to tell a bias from the frames' noise: not measured
    assert measure_track_bias(sim, detected, min_frames=len(detected.frames) + 1) == []


def test_the_calibration_carries_bias_sigma_to_the_detections_and_checks_it():
    cal = CovarianceCalibration(scale=2.0, shape_sigma=0.04, bias_sigma=(0.01, 0.01, 0.002, 0.02, 0.01, 0.02))
    assert CovarianceCalibration.from_dict(cal.to_dict()) == cal
    assert cal.detection_fields()["bias_sigma"] == (0.01, 0.01, 0.002, 0.02, 0.01, 0.02)
    assert CovarianceCalibration(scale=2.0).detection_fields()["bias_sigma"] is None
    assert "bias_sigma" not in CovarianceCalibration().to_dict()  # weights written before it read as before
    shipped = KeypointDetector(default_weights_path()).calibration  # python -m vfactor.net calibrate-bias --write
    # every coordinate within 0 (no shared error beyond the data's: the lateral shift of the fit of 2026-12-06) .. 10 cm
    assert shipped.bias_sigma is not None and min(shipped.bias_sigma) >= 0 and 0.001 < max(shipped.bias_sigma) < 0.1
    assert sum(s > 0.001 for s in shipped.bias_sigma) >= 4
    for bad in ((0.01, 0.02), (0.01, -0.01, 0, 0, 0, 0), (0.01, float("nan"), 0, 0, 0, 0)):
        with pytest.raises(ValueError, match="bias_sigma"):
            CovarianceCalibration(bias_sigma=bad)
