"""PnP of a fixed wireframe in the best single camera."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.baselines.pnp import box_diagonals, pnp, relative_residuals
from vfactor.metrics import pose_errors
from vfactor.result import Status
from vfactor.shape_model import default_shape_prior

from .conftest import bad_inputs, one_camera


def errors(result, truth):
    return pose_errors(result.world_T_vehicle, result.keypoints_world, truth.world_T_vehicle, truth.keypoints_world)


def test_exact_with_the_true_wireframe(noiseless_cases):
    for obs, truth in noiseless_cases:
        result = pnp(obs, wireframe=truth.wireframe)
        assert result.status == Status.CONVERGED
        e = errors(result, truth)
        assert e["rotation_deg"] < 1e-3 and e["translation_cm"] < 1e-2, (truth.preset, e)
        assert result.extras["camera"] in ("cam0", "cam1")
        assert max(result.extras["rms_relative_error"].values()) < 1e-6


def test_the_mean_wireframe_gets_the_orientation_not_the_distance(noiseless_cases):
    for obs, truth in noiseless_cases:
        result = pnp(obs)
        assert result.wireframe.vehicle_p_keypoints is not None
        assert np.allclose(result.keypoints_vehicle, default_shape_prior().mean)
        assert errors(result, truth)["rotation_deg"] < 5.0, truth.preset


def test_the_best_camera_wins(lincoln):
    obs, truth = lincoln
    result = pnp(obs)
    tried = result.extras["rms_relative_error"]
    assert set(tried) == {"cam0", "cam1"} and result.extras["camera"] == min(tried, key=tried.get)
    for name in ("cam0", "cam1", 0, 1):
        forced = pnp(obs, camera=name)
        assert forced.ok and set(forced.extras["rms_relative_error"]) == {obs.cameras[name].name if isinstance(name, int) else name}


def test_one_camera_is_enough(lincoln):
    obs, truth = lincoln
    result = pnp(one_camera(obs), wireframe=truth.wireframe)
    assert result.ok and errors(result, truth)["rotation_deg"] < 1e-3


def test_relative_residuals_are_in_units_of_the_box(lincoln):
    obs, truth = lincoln
    r = relative_residuals(obs, truth.world_T_vehicle, truth.keypoints_vehicle)
    assert np.abs(r).max() < 1e-9
    boxes = box_diagonals(obs)
    assert boxes.shape == (2,) and np.all(boxes > 50)


@pytest.mark.parametrize("case, status", [("none", Status.DEGENERATE), ("three_keypoints", Status.DEGENERATE),
                                          ("three_keypoints_two_cameras", Status.DEGENERATE), ("one_pixel", Status.FAILED)])
def test_bad_input_is_reported(lincoln, case, status):
    obs, _ = lincoln
    result = pnp(bad_inputs(obs)[case])
    assert result.status == status and result.message.startswith("pnp:") and result.world_T_vehicle is None


def test_unknown_camera_fails(lincoln):
    obs, _ = lincoln
    assert pnp(obs, camera="nope").status == Status.FAILED
    assert pnp(obs, camera=7).status == Status.FAILED
