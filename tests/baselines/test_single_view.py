"""One view with a deformable PASCAL3D+ model (after Pavlakos et al.)."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.baselines.single_view import SingleViewOptions, deformable_model, single_view
from vfactor.factors.projection import KeypointObservations
from vfactor.keypoints import MIRROR_PERMUTATION
from vfactor.metrics import pose_errors
from vfactor.result import Status

from .conftest import bad_inputs


def test_the_model_is_a_symmetric_orthonormal_basis():
    model = deformable_model(5)
    flat = model.basis.reshape(5, 36)
    assert np.allclose(flat @ flat.T, np.eye(5), atol=1e-9)
    assert np.allclose(model.basis, model.basis[:, MIRROR_PERMUTATION] * [1, -1, 1], atol=1e-9)
    assert np.all(np.diff(model.std) <= 0) and np.all(model.std > 0)
    assert np.isclose(np.linalg.norm(model.mean[0] - model.mean[2]), 1.0, atol=0.01)  # wheelbase units
    assert len(deformable_model(8).std) == 8


def projected(obs: KeypointObservations, world_p: np.ndarray) -> KeypointObservations:
    uv = np.empty((len(obs), 2))
    for c, camera in enumerate(obs.cameras):
        rows = obs.camera_index == c
        uv[rows] = camera.project(world_p[obs.keypoint_index[rows]])[0]
    return KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, uv, obs.sqrt_information)


def test_recovers_a_shape_of_the_model_at_the_prior_wheelbase(noiseless_cases):
    obs, truth = noiseless_cases[1]
    model = deformable_model(5)
    coefficients = np.array([0.8, -0.6, 0.5, 0.0, 0.0]) * model.std
    shape = model.shape(coefficients, 2.75)
    world = shape @ truth.world_T_vehicle.rotation().matrix().T + truth.world_T_vehicle.translation()
    result = single_view(projected(obs, world), SingleViewOptions(coefficient_weight=1e-6))
    assert result.status == Status.CONVERGED
    e = pose_errors(result.world_T_vehicle, result.keypoints_world, truth.world_T_vehicle, world)
    assert e["rotation_deg"] < 0.05 and e["mean_keypoint_cm"] < 0.5, e
    assert result.extras["camera"] in ("cam0", "cam1")


def test_the_scale_comes_from_the_prior(noiseless_cases):
    """One view cannot tell size from distance: a larger wheelbase prior moves the car away."""
    obs, truth = noiseless_cases[0]
    near = single_view(obs, camera="cam0")
    far = single_view(obs, SingleViewOptions(wheelbase=3.2), camera="cam0")
    camera = obs.cameras[0].center
    d_near = np.linalg.norm(near.world_T_vehicle.translation() - camera)
    d_far = np.linalg.norm(far.world_T_vehicle.translation() - camera)
    assert d_far / d_near == pytest.approx(far.wireframe.wheelbase / near.wireframe.wheelbase, rel=0.02)
    assert pose_errors(near.world_T_vehicle, near.keypoints_world, truth.world_T_vehicle,
                       truth.keypoints_world)["rotation_deg"] < 5.0


def test_one_camera_at_a_time(noiseless_cases):
    obs, _ = noiseless_cases[0]
    result = single_view(obs)
    tried = result.extras["rms_relative_error"]
    assert set(tried) == {"cam0", "cam1"} and result.extras["camera"] == min(tried, key=tried.get)
    assert set(single_view(obs, camera=1).extras["rms_relative_error"]) == {"cam1"}
    assert single_view(obs, camera="nope").status == Status.FAILED


@pytest.mark.parametrize("case, status", [("none", Status.DEGENERATE), ("three_keypoints", Status.DEGENERATE),
                                          ("three_keypoints_two_cameras", Status.DEGENERATE), ("one_pixel", Status.FAILED)])
def test_bad_input_is_reported(noiseless_cases, case, status):
    obs, _ = noiseless_cases[0]
    result = single_view(bad_inputs(obs)[case])
    assert result.status == status and result.message.startswith("single_view:") and result.world_T_vehicle is None


@pytest.mark.parametrize("field, value", [("num_components", 0), ("wheelbase", -1.0), ("loss", "l3"), ("min_keypoints", 3)])
def test_options_are_checked(field, value):
    with pytest.raises(ValueError, match=field):
        SingleViewOptions(**{field: value})
