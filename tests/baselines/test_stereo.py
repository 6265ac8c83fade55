"""The paper's stereo baseline: two-view, unweighted triangulation of every keypoint."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.baselines.stereo import stereo, stereo_pair
from vfactor.baselines.triangulation import triangulation
from vfactor.factors.projection import KeypointObservations
from vfactor.keypoints import LAYERS
from vfactor.metrics import pose_errors
from vfactor.result import Status

from .conftest import bad_inputs, keep, one_camera


def test_exact_without_noise(noiseless_cases):
    for obs, truth in noiseless_cases:
        result = stereo(obs)
        assert result.status == Status.CONVERGED
        assert np.allclose(result.keypoints_world, truth.keypoints_world, atol=1e-6)
        # the shape is exact; its axes are the mean wireframe's aligned to it, a fraction of a degree off
        d = lambda p: np.linalg.norm(p[:, None] - p[None], axis=2)  # noqa: E731
        assert np.allclose(d(result.keypoints_vehicle), d(truth.keypoints_vehicle), atol=1e-6)
        e = pose_errors(result.world_T_vehicle, result.keypoints_world, truth.world_T_vehicle, truth.keypoints_world)
        assert e["rotation_deg"] < 1.0 and e["translation_cm"] < 1e-3, (truth.preset, e)
        assert np.allclose(result.world_T_vehicle.translation(), truth.keypoints_world[list(LAYERS["wheel"])].mean(0), atol=1e-6)
        assert result.extras["cameras"] == ["cam0", "cam1"] and len(result.extras["triangulated"]) == 12


def test_confidence_does_not_matter(paper_cases):
    obs, _ = paper_cases[0]
    rng = np.random.default_rng(0)
    reweighted = KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, obs.uv,
                                      obs.sqrt_information * rng.uniform(0.1, 10.0, size=(len(obs), 1, 1)))
    a, b = stereo(obs), stereo(reweighted)
    assert np.allclose(a.keypoints_world, b.keypoints_world) and a.wireframe == b.wireframe
    # the confidence-weighted multi-view baseline does depend on them
    assert not np.allclose(triangulation(obs).keypoints_world, triangulation(reweighted).keypoints_world)


def test_untriangulated_keypoints_take_the_aligned_mean(lincoln):
    obs, truth = lincoln
    partial = keep(obs, ~((obs.camera_index == 1) & (obs.keypoint_index >= 8)))  # roof only in cam0
    result = stereo(partial)
    assert result.ok and result.extras["triangulated"] == list(range(8))
    assert np.allclose(result.keypoints_world[:8], truth.keypoints_world[:8], atol=1e-6)
    assert np.linalg.norm(result.keypoints_world[8:] - truth.keypoints_world[8:], axis=1).max() < 0.5


def test_pair_with_most_keypoints_in_common(noiseless_3cam_cases):
    obs, truth = noiseless_3cam_cases[0]
    fewer = keep(obs, ~((obs.camera_index == 0) & (obs.keypoint_index < 6)))
    assert stereo_pair(fewer) == (1, 2)
    result = stereo(fewer)
    assert result.extras["cameras"] == ["cam1", "cam2"]
    assert np.allclose(result.keypoints_world, truth.keypoints_world, atol=1e-6)
    assert stereo(fewer, cameras=("cam0", "cam2")).extras["cameras"] == ["cam0", "cam2"]


@pytest.mark.parametrize("case", ["none", "three_keypoints", "three_keypoints_two_cameras", "one_pixel", "one_camera"])
def test_bad_input_is_degenerate(lincoln, case):
    obs, _ = lincoln
    bad = one_camera(obs) if case == "one_camera" else bad_inputs(obs)[case]
    result = stereo(bad)
    assert result.status == Status.DEGENERATE and result.message.startswith("stereo:") and result.world_T_vehicle is None


@pytest.mark.parametrize("cameras", [("cam0",), ("cam0", "cam0"), ("cam0", "nope"), (0, 5)])
def test_bad_pair_fails(lincoln, cameras):
    obs, _ = lincoln
    assert stereo(obs, cameras=cameras).status == Status.FAILED
