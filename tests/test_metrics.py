"""The paper's error metrics."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from vfactor.metrics import (
    evaluate,
    keypoint_errors_cm,
    pose_errors,
    rotation_error_deg,
    summarise,
    translation_error_cm,
)
from vfactor.result import FrameResult, Status, VehicleResult
from vfactor.sim.simulate import VehicleTruth
from vfactor.wireframe import PRESETS


def test_a_10_degree_yaw_gives_10_degrees_in_every_input_form():
    a, b = gtsam.Rot3.Yaw(0.3), gtsam.Rot3.Yaw(0.3 + math.radians(10))
    assert rotation_error_deg(a, b) == pytest.approx(10.0, abs=1e-9)
    assert rotation_error_deg(a.matrix(), b.matrix()) == pytest.approx(10.0, abs=1e-9)
    pa, pb = gtsam.Pose3(a, [1, 2, 3]), gtsam.Pose3(b, [4, 5, 6])
    assert rotation_error_deg(pa, pb) == pytest.approx(10.0, abs=1e-9)
    assert rotation_error_deg(pa.matrix(), pb.matrix()) == pytest.approx(10.0, abs=1e-9)
    assert rotation_error_deg(b, a) == pytest.approx(10.0, abs=1e-9)


@pytest.mark.parametrize("angle_deg", [0.0, 1e-4, 3.0, 45.0, 90.0, 179.0, 180.0])
def test_rotation_error_is_the_geodesic_angle_about_any_axis(angle_deg):
    rng = np.random.default_rng(int(angle_deg * 10))
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    R1 = gtsam.Rot3.Expmap(rng.normal(size=3))
    R2 = R1.compose(gtsam.Rot3.Expmap(axis * math.radians(angle_deg)))
    assert rotation_error_deg(R1, R2) == pytest.approx(angle_deg, abs=1e-6)


def test_rotation_error_matches_the_frobenius_norm_of_the_matrix_log():
    from scipy.linalg import logm

    R1, R2 = gtsam.Rot3.Ypr(0.3, -0.2, 0.5), gtsam.Rot3.Ypr(-0.4, 0.1, 0.2)
    expected = math.degrees(np.linalg.norm(np.real(logm(R1.matrix().T @ R2.matrix())), "fro") / math.sqrt(2))
    assert rotation_error_deg(R1, R2) == pytest.approx(expected, abs=1e-9)


def test_rotation_error_rejects_bad_shapes():
    with pytest.raises(ValueError, match="R2"):
        rotation_error_deg(np.eye(3), np.eye(2))


def test_translation_and_keypoint_errors_in_cm():
    kp = PRESETS["lincoln_mkz"].wireframe().vehicle_p_keypoints
    shifted = kp + [0.03, 0.04, 0.0]
    assert translation_error_cm(shifted, kp) == pytest.approx(5.0)
    np.testing.assert_allclose(keypoint_errors_cm(shifted, kp), 5.0)
    moved = kp.copy()
    moved[3] += [0.0, 0.0, 0.12]
    errors = keypoint_errors_cm(moved, kp)
    assert errors[3] == pytest.approx(12.0) and np.count_nonzero(errors) == 1
    assert translation_error_cm(moved, kp) == pytest.approx(1.0)  # 12 cm / 12 keypoints
    with pytest.raises(ValueError, match="shapes differ"):
        keypoint_errors_cm(kp[:11], kp)


def test_pose_errors_of_a_rotated_and_shifted_vehicle():
    w = PRESETS["toyota_prius"].wireframe()
    true = gtsam.Pose3(gtsam.Rot3.Yaw(1.0), [2.0, -1.0, 0.32])
    est = gtsam.Pose3(gtsam.Rot3.Yaw(1.0 + math.radians(4)), [2.06, -0.92, 0.32])
    e = pose_errors(est, w.in_world(est), true, w.in_world(true))
    assert e["rotation_deg"] == pytest.approx(4.0)
    centroid = w.vehicle_p_keypoints.mean(0)
    expected = 100 * np.linalg.norm(est.transformFrom(centroid) - true.transformFrom(centroid))
    assert e["translation_cm"] == pytest.approx(expected)
    assert e["keypoint_cm"].shape == (12,) and e["mean_keypoint_cm"] == pytest.approx(e["keypoint_cm"].mean())


def test_summarise_means_and_medians():
    rows = [
        {"rotation_deg": r, "translation_cm": t, "keypoint_cm": np.full(12, k), "mean_keypoint_cm": k}
        for r, t, k in [(1.0, 10.0, 5.0), (2.0, 20.0, 6.0), (6.0, 30.0, 10.0)]
    ]
    s = summarise(rows + [{"frame": 3, "id": "v1", "status": "degenerate"}])
    assert s["count"] == 3 and s["skipped"] == 1
    assert s["rotation_deg"] == {"mean": pytest.approx(3.0), "median": pytest.approx(2.0)}
    assert s["translation_cm"]["mean"] == pytest.approx(20.0)
    assert s["mean_keypoint_cm"]["median"] == pytest.approx(6.0)
    assert s["keypoint_cm"]["mean"] == pytest.approx([7.0] * 12)
    empty = summarise([])
    assert empty["count"] == 0 and math.isnan(empty["rotation_deg"]["mean"])


def test_evaluate_matches_results_to_the_truth_by_frame_and_id():
    w = PRESETS["bmw_x5"].wireframe()
    true = gtsam.Pose3(gtsam.Rot3.Yaw(0.5), [0.0, 0.0, 0.38])
    truth = [{"v1": VehicleTruth(true, w, "bmw_x5", 0.38)}, {"v1": VehicleTruth(true, w, "bmw_x5", 0.38)}]
    est = gtsam.Pose3(gtsam.Rot3.Yaw(0.5 + math.radians(2)), [0.0, 0.0, 0.38])
    results = [
        FrameResult(
            0.0, [VehicleResult("v1", Status.CONVERGED, est, w), VehicleResult("v9", Status.CONVERGED, est, w)]
        ),
        FrameResult(0.1, [VehicleResult("v1", Status.DEGENERATE, message="too few keypoints")]),
    ]
    rows = evaluate(results, truth)
    assert [(r["frame"], r["id"], r["status"]) for r in rows] == [(0, "v1", "converged"), (1, "v1", "degenerate")]
    assert rows[0]["rotation_deg"] == pytest.approx(2.0)
    assert "rotation_deg" not in rows[1]
    assert summarise(rows)["count"] == 1
    with pytest.raises(ValueError, match="frames"):
        evaluate(results[:1], truth)


def test_ray_nees_splits_the_error_along_and_across_the_camera_ray():
    from vfactor.metrics import CHI2_95, ray_nees
    from vfactor.stats import chi2_quantile

    # the vehicle 10 m along world x from the camera, turned by 90 deg: the ray is body -y
    world_T_est = gtsam.Pose3(gtsam.Rot3.Yaw(math.pi / 2), np.array([10.0, 0.0, 0.0]))
    body_error = np.array([0.1, -0.2, 0.05])  # body frame: 0.2 m along the ray (away), 0.1 and 0.05 across
    world_T_true = world_T_est.compose(gtsam.Pose3(gtsam.Rot3(), body_error))
    P = np.diag([1e-4, 1e-4, 1e-4, 0.01, 0.04, 0.0025])
    along, along_z2, across_z2 = ray_nees(world_T_est, P, world_T_true, [0.0, 0.0, 0.0])
    assert along == pytest.approx(0.2)
    assert along_z2 == pytest.approx(0.2**2 / 0.04)
    assert across_z2 == pytest.approx(0.1**2 / 0.01 + 0.05**2 / 0.0025)
    # a correlated covariance: across the ray the 2x2 block's own inverse, not the diagonal
    P[3, 5] = P[5, 3] = 0.004
    block = P[[3, 5]][:, [3, 5]]
    e = body_error[[0, 2]]
    assert ray_nees(world_T_est, P, world_T_true, np.zeros(3))[2] == pytest.approx(e @ np.linalg.solve(block, e))
    for dof in (1, 2, 3, 6):
        assert CHI2_95[dof] == pytest.approx(chi2_quantile(dof, 0.95), rel=1e-6)
    with pytest.raises(ValueError, match="pose_covariance"):
        ray_nees(world_T_est, np.eye(3), world_T_true, np.zeros(3))


def test_pose_nees_components_are_each_axis_squared_error_over_its_variance():
    from vfactor.metrics import pose_nees, pose_nees_components

    world_T_est = gtsam.Pose3(gtsam.Rot3.Yaw(0.3), np.array([4.0, 2.0, 0.34]))
    xi = np.array([0.01, -0.02, 0.03, 0.1, -0.2, 0.05])  # roll, pitch, yaw (rad), x, y, z (m), body frame
    world_T_true = world_T_est.compose(gtsam.Pose3.Expmap(xi))
    sigmas = np.array([0.01, 0.01, 0.02, 0.1, 0.1, 0.05])
    P = np.diag(sigmas**2)
    parts = pose_nees_components(world_T_est, P, world_T_true)
    np.testing.assert_allclose(parts, (xi / sigmas) ** 2, rtol=1e-9)
    assert parts.sum() == pytest.approx(pose_nees(world_T_est, P, world_T_true))  # diagonal: they add up
    P[3, 4] = P[4, 3] = 0.005  # a correlation changes the NEES, not the components (the diagonal's)
    np.testing.assert_allclose(pose_nees_components(world_T_est, P, world_T_true), parts)
    with pytest.raises(ValueError, match="pose_covariance"):
        pose_nees_components(world_T_est, np.eye(3), world_T_true)
