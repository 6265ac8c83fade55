"""Initialisation: Umeyama, triangulation and pose candidates."""

from __future__ import annotations

import gtsam
import numpy as np

from vfactor.graph import observations_from_detections
from vfactor.init import best_candidates, triangulate_keypoints, umeyama
from vfactor.factors.robust import RobustLoss
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
