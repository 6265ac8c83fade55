"""Truncation at the image border: the truncated-Gaussian mean, the windows the graph gives, and the bias it removes."""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest
from scipy.stats import truncnorm

from vfactor.camera import Camera
from vfactor.factors.robust import RobustLoss
from vfactor.factors.truncation import truncated_means
from vfactor.graph import (
    GraphConfig,
    add_observation_factor,
    add_shape_factors,
    insert_vehicle_values,
    observations_from_detections,
    wireframe_from_values,
)
from vfactor.keys import KeyScheme
from vfactor.observations import Detection

from ..conftest import K, look_at

LO, HI, SIGMA = -0.5, 1279.5, 6.0


def test_truncated_mean_and_slope_match_scipy():
    mu = np.linspace(LO - 8 * SIGMA, LO + 10 * SIGMA, 91)
    mu = np.concatenate([mu, HI - (mu - LO)])  # both edges
    m, slope = truncated_means(mu, SIGMA, LO, HI)
    a, b = (LO - mu) / SIGMA, (HI - mu) / SIGMA
    assert np.allclose(m, truncnorm.mean(a, b, loc=mu, scale=SIGMA), atol=1e-7)
    assert np.allclose(slope, truncnorm.var(a, b, loc=mu, scale=SIGMA) / SIGMA**2, atol=1e-7)


def test_slope_is_the_derivative_of_the_mean():
    mu = np.linspace(LO - 50, LO + 50, 41)
    h = 1e-5
    numeric = (truncated_means(mu + h, SIGMA, LO, HI)[0] - truncated_means(mu - h, SIGMA, LO, HI)[0]) / (2 * h)
    assert np.allclose(truncated_means(mu, SIGMA, LO, HI)[1], numeric, atol=1e-6)


def test_far_from_the_edges():
    inside = np.array([300.0, 640.0, 1000.0])
    m, slope = truncated_means(inside, SIGMA, LO, HI)
    assert np.array_equal(m, inside) and np.all(slope == 1.0)
    outside = np.array([-1e6, -400.0, 1700.0, 1e7])  # up to 1e6 sigmas out: finite, on the nearer edge
    m, slope = truncated_means(outside, SIGMA, LO, HI)
    assert np.all(np.isfinite(m)) and np.all((m >= LO) & (m <= HI))
    assert np.allclose(m, [LO, LO, HI, HI], atol=0.1) and np.all(slope < 1e-3)


CAMERA = Camera("a", K, look_at([15, 10, 7], [0, 0, 0]), image_size=(640, 480))
NO_SIZE = Camera("b", K, look_at([-15, -8, 8], [0, 0, 0]))


def _detection(camera, uv):
    return Detection(camera, "v1", np.asarray(uv, float), np.full(len(uv), 0.9))


def test_windows_of_observations():
    inside = np.tile([[100.0, 200.0], [600.0, 400.0], [320.0, 240.0]], (4, 1))
    obs = observations_from_detections([_detection("a", inside), _detection("b", inside)],
                                       {"a": CAMERA, "b": NO_SIZE})
    assert np.allclose(obs.window[:12], [-0.5, -0.5, 639.5, 479.5])
    assert np.all(np.isnan(obs.window[12:]))  # no image_size: not truncated
    beyond = inside.copy()
    beyond[5] = [-30.0, 200.0]  # this detector reports keypoints outside the image: it does not truncate
    obs = observations_from_detections([_detection("a", beyond)], {"a": CAMERA})
    assert np.all(np.isnan(obs.window))
    obs = observations_from_detections([_detection("a", inside)], {"a": CAMERA}, GraphConfig(truncation=False))
    assert np.all(np.isnan(obs.window))
    with pytest.raises(ValueError, match="truncation"):
        GraphConfig(truncation=1)
    with pytest.raises(ValueError, match="shape_prior_loss"):
        GraphConfig(shape_prior_loss="cauchy")


def test_truncation_removes_most_of_the_shrinking_of_a_vehicle_cut_by_the_border():
    """A van standing with its back out of one camera's image, 20 noisy frames of the same pose.

    The simulator loses keypoints whose noisy pixel leaves the image; least squares
    on the kept ones shrinks the van, whatever the number of frames
    (docs/factors.md); the truncated-mean residual removes most of it. Each
    detection carries the simulator's own pixel sigmas, so that the truncated
    model is the true one.
    """
    from vfactor.sim import simulate
    from vfactor.sim.noise import NoiseModel
    from vfactor.sim.simulate import _observe

    sim = simulate("tracks_3veh", seed=1, num_frames=16)
    truth = sim.truth[15]
    van = truth["v3"]
    scenario = dataclasses.replace(sim.scenario, noise=NoiseModel.gaussian_only(0.03))
    def observe(rng):
        frame, labels = _observe(scenario, truth, rng, t=0.0)
        for d in frame.detections:
            d.covariance = labels[(d.camera, d.vehicle)].sigma_px[:, None, None] ** 2 * np.eye(2)
        return frame

    frames = [[observe(np.random.default_rng([99 + draw, i])) for i in range(20)] for draw in range(4)]
    assert any(np.isnan(d.keypoints).any() for d in frames[0][0].detections if d.vehicle == "v3")
    p = van.keypoints_vehicle
    keys = KeyScheme()

    def scale_error(truncation: bool) -> float:
        config = GraphConfig(shape_prior_weight=1e-4, loss=RobustLoss("none"), truncation=truncation)
        out = []
        for draw in frames:
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            add_shape_factors(graph, keys, 0, config)
            insert_vehicle_values(values, keys, van.world_T_vehicle, van.wireframe)
            for frame in draw:
                add_observation_factor(graph, keys, observations_from_detections(
                    frame.detections_of("v3"), scenario.cameras, config), config=config)
            shape = wireframe_from_values(gtsam.LevenbergMarquardtOptimizer(graph, values).optimize(), keys)
            out.append(((shape.vehicle_p_keypoints - p) * p).sum() / (p * p).sum())
        return float(np.mean(out))

    plain, truncated = scale_error(False), scale_error(True)
    assert plain < -0.02  # 2 % short: 10 cm over the van's 5 m
    assert abs(truncated) < 0.3 * abs(plain)
