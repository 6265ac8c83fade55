"""CPO + HWC (the paper's method as written): exact without noise, HWC rules kept, bad input reported."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vfactor.baselines.cpo import CpoOptions, cpo, hwc_projection, observation_confidence
from vfactor.factors.projection import KeypointObservations
from vfactor.graph import observations_from_detections
from vfactor.keypoints import LAYERS, MIRROR_PERMUTATION
from vfactor.metrics import pose_errors, rotation_error_deg
from vfactor.result import Status
from vfactor.shape_model import car_hwc_bounds, default_shape_prior
from vfactor.sim import load_scenario, simulate, within_hwc_bounds
from vfactor.wireframe import PRESETS, Wireframe

from .conftest import bad_inputs, one_camera


def body_error_cm(result, truth) -> float:
    return 100 * float(np.linalg.norm(result.keypoints_vehicle - truth.keypoints_vehicle, axis=1).mean())


def test_recovers_pose_and_shape_without_noise(noiseless_cases):
    for obs, truth in noiseless_cases:
        result = cpo(obs)
        assert result.status == Status.CONVERGED, (truth.preset, result.iterations)
        e = pose_errors(result.world_T_vehicle, result.keypoints_world, truth.world_T_vehicle, truth.keypoints_world)
        assert e["rotation_deg"] < 0.05 and e["translation_cm"] < 0.5 and e["mean_keypoint_cm"] < 0.5, (truth.preset, e)
        assert body_error_cm(result, truth) < 0.5, truth.preset
        assert result.final_error < 1e-6
        assert result.extras["pose_iterations"] >= CpoOptions().min_pose_iterations


def test_three_cameras_without_noise(noiseless_3cam_cases):
    for obs, truth in noiseless_3cam_cases:
        result = cpo(obs)
        assert result.ok
        assert set(result.extras["projection_error"]) == {"cam0", "cam1", "cam2"}
        e = pose_errors(result.world_T_vehicle, result.keypoints_world, truth.world_T_vehicle, truth.keypoints_world)
        assert e["rotation_deg"] < 0.05 and e["mean_keypoint_cm"] < 0.5, (truth.preset, e)


def test_without_hwc_the_shape_is_the_mean(lincoln):
    obs, _ = lincoln
    result = cpo(obs, CpoOptions(hwc=False))
    assert result.ok
    mean = default_shape_prior().mean
    # the same shape up to the hub-centred, level body frame
    assert np.allclose(np.linalg.norm(result.keypoints_vehicle - result.keypoints_vehicle[0], axis=1),
                       np.linalg.norm(mean - mean[0], axis=1), atol=1e-9)


def test_confidence_is_recovered_from_the_sqrt_information():
    sim = simulate(load_scenario("paper_webots"), seed=4, num_frames=2)
    for frame in sim.scene.frames:
        detections = frame.detections
        obs = observations_from_detections(detections, sim.scene.cameras)
        expected = np.concatenate([d.confidence[d.confidence > 0] for d in detections])
        assert np.allclose(observation_confidence(obs), expected, atol=1e-12)


def test_given_confidence_is_the_default(lincoln):
    obs, _ = lincoln
    a = cpo(obs, CpoOptions(max_iterations=8))
    b = cpo(obs, CpoOptions(max_iterations=8), confidence=observation_confidence(obs))
    assert np.allclose(a.world_T_vehicle.matrix(), b.world_T_vehicle.matrix())
    assert a.wireframe == b.wireframe


def test_hwc_projection_keeps_a_conforming_shape_and_fixes_the_mean():
    prius = PRESETS["toyota_prius"].wireframe().vehicle_p_keypoints
    assert np.allclose(hwc_projection(prius), prius, atol=1e-12)
    mean = hwc_projection(default_shape_prior().mean)
    wheel = mean[list(LAYERS["wheel"])]
    assert np.isclose(np.linalg.norm(wheel[0] - wheel[1]), np.linalg.norm(wheel[2] - wheel[3]))


def test_hwc_rules_hold_under_noise(paper_cases):
    for obs, truth in paper_cases[:4]:
        result = cpo(obs)
        assert result.ok
        p = result.keypoints_vehicle
        assert np.allclose(p, p[MIRROR_PERMUTATION] * [1, -1, 1], atol=1e-9)  # symmetric about the medial plane
        wheel = p[list(LAYERS["wheel"])]
        assert np.allclose(wheel[:, 2], 0, atol=1e-9) and np.allclose(wheel.mean(0), 0, atol=1e-9)  # body frame
        assert np.isclose(np.linalg.norm(wheel[0] - wheel[1]), np.linalg.norm(wheel[2] - wheel[3]))  # rectangle
        assert within_hwc_bounds(result.wireframe, car_hwc_bounds()), truth.preset  # the paper's car bounds


def with_outlier(obs: KeypointObservations, camera: int) -> tuple[KeypointObservations, int]:
    """``obs`` with camera ``camera``'s first keypoint moved by 40 % of that camera's box (and the moved row)."""
    rows = np.flatnonzero(obs.camera_index == camera)
    uv = obs.uv.copy()
    uv[rows[0]] += 0.4 * (uv[rows].max(0) - uv[rows].min(0))
    return KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, uv, obs.sqrt_information), rows[0]


def test_an_outlier_loses_its_weight_and_the_models_agree(noiseless_cases):
    """Eq. (6)'s weights are the paper's only outlier handling: the bad detection ends at the weight floor."""
    errors, fixed_errors = [], []
    for obs, truth in noiseless_cases:
        options = CpoOptions(hwc=False, mean=Wireframe(truth.keypoints_vehicle))  # the exact shape: only the outlier errs
        for camera in (0, 1):
            bad, row = with_outlier(obs, camera)
            result = cpo(bad, options)
            assert result.ok
            weight = result.extras["weights"][obs.cameras[camera].name][obs.keypoint_index[row]]
            assert weight < 1.1 * options.weight_floor / 12, (truth.preset, camera, weight)
            a, b = result.extras["poses"].values()  # each detection weighed by its own weight: one energy, one optimum
            assert rotation_error_deg(a, b) < 1e-3 and np.linalg.norm(a.translation() - b.translation()) < 1e-4
            e = pose_errors(result.world_T_vehicle, result.keypoints_world, truth.world_T_vehicle, truth.keypoints_world)
            assert e["rotation_deg"] < 0.5 and e["mean_keypoint_cm"] < 1.5, (truth.preset, camera, e)
            errors.append(e["rotation_deg"])
            fixed = cpo(bad, dataclasses.replace(options, mu_update=(1.0, 0.0, 0.0)))
            fixed_errors.append(rotation_error_deg(fixed.world_T_vehicle, truth.world_T_vehicle))
    assert np.mean(fixed_errors) > 5 * np.mean(errors), (fixed_errors, errors)


def test_the_model_with_the_smaller_weighted_projection_error_wins(paper_cases):
    for obs, truth in paper_cases[:3]:
        for weighting in ("image", "model"):
            result = cpo(obs, CpoOptions(weighting=weighting, max_iterations=10))
            errors = result.extras["projection_error"]
            assert result.extras["camera"] == min(errors, key=errors.get)
            assert set(result.extras["poses"]) == set(errors)


@pytest.mark.parametrize("case", ["none", "three_keypoints", "three_keypoints_two_cameras", "one_camera"])
def test_too_little_is_degenerate(lincoln, case):
    obs, _ = lincoln
    bad = one_camera(obs) if case == "one_camera" else bad_inputs(obs)[case]
    result = cpo(bad)
    assert result.status == Status.DEGENERATE and result.message and result.world_T_vehicle is None


def test_impossible_geometry_fails_without_raising(lincoln):
    obs, _ = lincoln
    result = cpo(bad_inputs(obs)["one_pixel"])
    assert result.status == Status.FAILED and "cpo" in result.message


def test_bad_confidence_fails(lincoln):
    obs, _ = lincoln
    for confidence in (np.ones(3), np.full(len(obs), np.nan), -np.ones(len(obs)), "high"):
        result = cpo(obs, confidence=confidence)
        assert result.status == Status.FAILED and "confidence" in result.message


@pytest.mark.parametrize("field, value", [("mu_init", (0.0, 0.5)), ("max_step_m", -1.0), ("max_iterations", 0),
                                          ("mu_init", (1.0, 2.0, 3.0)), ("min_keypoints_per_camera", 2),
                                          ("weighting", "camera"), ("weight_state", None)])
def test_options_are_checked(field, value):
    with pytest.raises(ValueError, match=f"CpoOptions.{field}"):
        CpoOptions(**{field: value})
