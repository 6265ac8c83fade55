"""Heatmap targets peak at the keypoints (all of them, self-occluded too); weights are 0 outside the crop."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.heatmaps import decode_heatmaps
from vfactor.net.targets import heatmap_targets, in_crop, keypoint_weights


def test_targets_decode_back_to_the_keypoints():
    rng = np.random.default_rng(0)
    kp = rng.uniform(8, 120, size=(12, 2))
    t = heatmap_targets(kp, crop_size=128, heatmap_size=32, sigma=1.5)
    assert t.shape == (12, 32, 32) and t.dtype == np.float32
    d = decode_heatmaps(t, roi=(0, 0, 128, 128))
    np.testing.assert_allclose(d.uv, kp, atol=1e-3)
    # sigma is in heatmap pixels: 1.5 heatmap px = 6 crop px
    np.testing.assert_allclose(d.covariance, np.broadcast_to(np.eye(2) * 6.0**2, (12, 2, 2)), atol=1e-3)
    assert np.all(t.max(axis=(1, 2)) > 0.75)


def test_peak_pixel_is_the_nearest_heatmap_cell():
    t = heatmap_targets(np.array([[64.0, 32.0]]), crop_size=128, heatmap_size=32)
    # u = 64 -> x = (64 + 0.5) / 4 - 0.5 = 15.625 -> column 16; v = 32 -> y = 7.625 -> row 8
    assert np.unravel_index(t[0].argmax(), t[0].shape) == (8, 16)


def test_missing_and_far_keypoints_give_empty_heatmaps():
    kp = np.array([[np.nan, np.nan], [500.0, 40.0], [57.5, 57.5]])
    t = heatmap_targets(kp, 64, 16)
    assert not t[0].any() and not t[1].any() and t[2].max() > 0.9


def test_weights_zero_outside_the_crop_and_for_missing():
    kp = np.array([[10.0, 10.0], [-3.0, 10.0], [10.0, 64.2], [np.nan, 5.0], [63.4, 0.0]])
    assert in_crop(kp, 64).tolist() == [True, False, False, False, True]
    w = keypoint_weights(kp, 64, self_occluded=[False, False, False, False, True], self_occluded_weight=0.5)
    assert w.tolist() == [1.0, 0.0, 0.0, 0.0, 0.5]
    assert keypoint_weights(kp, 64).tolist() == [1.0, 0.0, 0.0, 0.0, 1.0]


def test_bad_sigma_is_reported():
    with pytest.raises(ValueError, match="sigma"):
        heatmap_targets(np.zeros((12, 2)), 64, 16, sigma=0.0)
