"""Initialisation: Umeyama, triangulation and pose candidates."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from vfactor.graph import observations_from_detections
from vfactor.init import best_candidates, cross_projection_cost, own_pose, triangulate_keypoints, umeyama
from vfactor.factors.projection import robust_costs, whitened_residuals
from vfactor.factors.robust import LOSSES, RobustLoss
from vfactor.shape_model import default_shape_prior
from vfactor.wireframe import Wireframe

from .test_solve import detections_for


def test_umeyama_recovers_a_similarity():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(10, 3))
    R = gtsam.Rot3.Ypr(0.3, -0.2, 0.1).matrix()
    dst = 1.3 * src @ R.T + [1, 2, 3]
    R_est, t_est, s_est = umeyama(src, dst)
    assert np.allclose(R_est, R) and np.allclose(t_est, [1, 2, 3]) and np.isclose(s_est, 1.3)


def test_triangulation_is_exact_without_noise(cameras, prius, world_T_vehicle):
    obs = observations_from_detections(detections_for(cameras, prius, world_T_vehicle), cameras)
    idx, world = triangulate_keypoints(obs)
    assert len(idx) == 12
    assert np.allclose(world, prius.in_world(world_T_vehicle)[idx], atol=1e-6)


def test_best_candidate_is_near_the_truth_for_any_yaw(cameras, prius):
    for yaw in np.linspace(0, 2 * np.pi, 8, endpoint=False):
        truth = gtsam.Pose3(gtsam.Rot3.Yaw(yaw), np.array([0.5, 0.5, 0.32]))
        rng = np.random.default_rng(int(yaw * 100))
        obs = observations_from_detections(detections_for(cameras, prius, truth, noise_px=3.0, rng=rng), cameras)
        best = best_candidates(obs, Wireframe(default_shape_prior().mean), RobustLoss(), 1)[0]
        angle = np.degrees(np.linalg.norm(gtsam.Rot3.Logmap(best.world_T_vehicle.rotation().between(truth.rotation()))))
        assert angle < 15, (yaw, best.source, angle)


def test_candidates_are_scored_in_one_pass_as_by_their_residuals(cameras, prius, world_T_vehicle):
    """robust_costs (every candidate in one compiled pass) is sum rho(|e|) of the NumPy whitened residuals."""
    rng = np.random.default_rng(3)
    obs = observations_from_detections(detections_for(cameras, prius, world_T_vehicle, noise_px=3.0, rng=rng), cameras)
    poses = [world_T_vehicle.compose(gtsam.Pose3(gtsam.Rot3.Ypr(*rng.normal(0, 0.3, 3)), rng.normal(0, 0.5, 3)))
             for _ in range(5)]
    shapes = [prius.scaled(s).vehicle_p_keypoints for s in (0.8, 0.9, 1.0, 1.1, 1.2)]
    for name in LOSSES:
        loss = RobustLoss(name)
        costs = robust_costs(obs, np.array([p.matrix() for p in poses]), np.array(shapes), loss)
        expected = [np.sum(loss.rho(np.linalg.norm(whitened_residuals(obs, p, x), axis=1))) for p, x in zip(poses, shapes)]
        assert np.allclose(costs, expected, rtol=1e-9), name
    assert cross_projection_cost(obs, poses[0], prius, RobustLoss()) == pytest.approx(
        robust_costs(obs, poses[0].matrix()[None], prius.vehicle_p_keypoints[None], RobustLoss())[0])


def test_a_cameras_own_pose_is_fitted_once_per_view(cameras, prius, world_T_vehicle, monkeypatch):
    """own_pose (the check of cameras at odds) is best_candidates' RANSAC fit of that camera's keypoints alone, kept
    by its inputs: the same view in another vehicle's observations is not fitted again, another view is."""
    import vfactor.init as init

    rng = np.random.default_rng(5)
    detections = detections_for(cameras, prius, world_T_vehicle, noise_px=2.0, rng=rng)
    obs = observations_from_detections(detections, cameras)
    mean, loss = Wireframe(default_shape_prior().mean), RobustLoss()
    fits = []
    monkeypatch.setattr(init, "best_candidates", lambda *a, **k: fits.append(a[0]) or best_candidates(*a, **k))
    monkeypatch.setattr(init, "_own_poses", type(init._own_poses)())
    first = own_pose(obs, 0, mean, loss)
    expected = best_candidates(obs.subset(obs.camera_index == 0), mean, loss, 1, ransac_every_labelling=True)[0]
    assert first.equals(expected.world_T_vehicle, 1e-12)
    alone = observations_from_detections([d for d in detections if d.camera == obs.cameras[0].name], cameras)
    assert own_pose(alone, 0, mean, loss) is first and len(fits) == 1  # the same view, other observations around it
    moved = observations_from_detections([d for d in detections_for(cameras, prius, world_T_vehicle.compose(
        gtsam.Pose3(gtsam.Rot3(), np.array([0.5, 0.0, 0.0])))) if d.camera == obs.cameras[0].name], cameras)
    assert not own_pose(moved, 0, mean, loss).equals(first, 1e-6) and len(fits) == 2
    assert own_pose(obs, 0, mean, RobustLoss("huber")) is not first and len(fits) == 3  # the loss is an input
