"""Keypoint detector noise: statistics, confidences, outliers, swaps and misses."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.keypoints import LEFT_RIGHT_PAIRS
from vfactor.sim import NoiseModel, box_diagonal, corrupt_keypoints

SIZE = (1280, 720)


def _true_uv(rng):
    """12 pixels in a random box well inside the image."""
    lo = rng.uniform([200, 150], [500, 300])
    return lo + rng.uniform(0, 1, (12, 2)) * rng.uniform([150, 80], [350, 200])


def test_pixel_noise_std_matches_relative_sigma_times_the_box_diagonal():
    rng = np.random.default_rng(0)
    noise = NoiseModel(relative_sigma=0.03, occluded_factor=2.0, outlier_rate=0, swap_rate=0, missing_rate=0)
    visible_err, occluded_err = [], []
    for _ in range(500):
        uv = _true_uv(rng)
        occluded = rng.random(12) < 0.3
        out = corrupt_keypoints(uv, occluded, noise, rng, SIZE)
        assert not out.missing.any()
        normalised = (out.keypoints - uv) / (0.03 * box_diagonal(uv))
        visible_err.append(normalised[~occluded])
        occluded_err.append(normalised[occluded] / 2.0)
        np.testing.assert_allclose(out.sigma_px, 0.03 * box_diagonal(uv) * np.where(occluded, 2.0, 1.0))
    visible_err, occluded_err = np.concatenate(visible_err), np.concatenate(occluded_err)
    assert len(visible_err) > 2000 and len(occluded_err) > 1000
    for err in (visible_err, occluded_err):
        assert np.std(err) == pytest.approx(1.0, rel=0.15)
        assert np.abs(np.mean(err, axis=0)).max() < 0.1


def test_confidences_are_drawn_from_the_visible_and_occluded_ranges():
    rng = np.random.default_rng(1)
    noise = NoiseModel.noiseless()
    occluded = np.arange(12) % 3 == 0
    conf = np.array([corrupt_keypoints(_true_uv(rng), occluded, noise, rng).confidence for _ in range(200)])
    vis, occ = conf[:, ~occluded], conf[:, occluded]
    assert vis.min() >= 0.7 and vis.max() <= 1.0 and vis.mean() == pytest.approx(0.85, abs=0.02)
    assert occ.min() >= 0.3 and occ.max() <= 0.6 and occ.mean() == pytest.approx(0.45, abs=0.02)


def test_noiseless_model_returns_the_true_pixels():
    rng = np.random.default_rng(2)
    uv = _true_uv(rng)
    out = corrupt_keypoints(uv, np.zeros(12, bool), NoiseModel.noiseless(), rng, SIZE)
    np.testing.assert_array_equal(out.keypoints, uv)


def test_missing_keypoints_have_zero_confidence_and_nan_pixels_at_the_given_rate():
    rng = np.random.default_rng(3)
    noise = NoiseModel(missing_rate=0.2, outlier_rate=0.0, swap_rate=0.0)
    missing = []
    for _ in range(300):
        out = corrupt_keypoints(_true_uv(rng), np.zeros(12, bool), noise, rng, SIZE)
        assert np.all(np.isnan(out.keypoints[out.missing])) and np.all(out.confidence[out.missing] == 0)
        assert np.all(np.isfinite(out.keypoints[~out.missing])) and np.all(out.confidence[~out.missing] >= 0.7)
        missing.append(out.missing)
    assert np.mean(missing) == pytest.approx(0.2, abs=0.02)


def test_keypoints_outside_the_image_or_behind_the_camera_are_missing():
    rng = np.random.default_rng(4)
    uv = _true_uv(rng)
    uv[0] = [-5.0, 100.0]
    uv[1] = [100.0, SIZE[1] + 3.0]
    in_front = np.ones(12, bool)
    in_front[2] = False
    out = corrupt_keypoints(uv, np.zeros(12, bool), NoiseModel.noiseless(), rng, SIZE, in_front=in_front)
    np.testing.assert_array_equal(np.flatnonzero(out.missing), [0, 1, 2])
    assert np.all(out.confidence[:3] == 0)


def test_outliers_fall_in_the_grown_box_with_visible_confidence():
    rng = np.random.default_rng(5)
    noise = NoiseModel(outlier_rate=1.0, swap_rate=0.0, missing_rate=0.0)
    for _ in range(50):
        uv = _true_uv(rng)
        out = corrupt_keypoints(uv, np.ones(12, bool), noise, rng)
        assert out.outlier.all()
        lo, hi = uv.min(0), uv.max(0)
        centre, half = (lo + hi) / 2, (hi - lo) / 2 * 1.5
        assert np.all(np.abs(out.keypoints - centre) <= half + 1e-9)
        assert np.all(out.confidence >= 0.7)
    # they spread over the grown box, beyond the original one
    assert np.any(out.keypoints < lo) or np.any(out.keypoints > hi)


def test_swaps_exchange_left_and_right_labels():
    rng = np.random.default_rng(6)
    uv = _true_uv(rng)
    occluded = np.zeros(12, bool)
    occluded[[1, 3]] = True
    noise = NoiseModel(relative_sigma=0.0, swap_rate=1.0, outlier_rate=0.0, missing_rate=0.0)
    out = corrupt_keypoints(uv, occluded, noise, rng)
    assert out.swapped.all()
    for left, right in LEFT_RIGHT_PAIRS:
        np.testing.assert_array_equal(out.keypoints[left], uv[right])
        np.testing.assert_array_equal(out.keypoints[right], uv[left])
    assert 0.3 <= out.confidence[0] <= 0.6  # the occluded right wheel's measurement moved to the left label
    rates = [corrupt_keypoints(uv, occluded, NoiseModel(swap_rate=0.25), rng).swapped.mean() for _ in range(400)]
    assert np.mean(rates) == pytest.approx(0.25, abs=0.03)


def test_same_generator_state_gives_the_same_detection_and_rates_do_not_shift_other_draws():
    uv = _true_uv(np.random.default_rng(7))
    occluded = np.zeros(12, bool)
    a = corrupt_keypoints(uv, occluded, NoiseModel(), np.random.default_rng(8), SIZE)
    b = corrupt_keypoints(uv, occluded, NoiseModel(), np.random.default_rng(8), SIZE)
    np.testing.assert_array_equal(a.keypoints, b.keypoints)
    np.testing.assert_array_equal(a.confidence, b.confidence)
    clean = corrupt_keypoints(uv, occluded, NoiseModel.gaussian_only(), np.random.default_rng(8), SIZE)
    keep = ~(a.outlier | a.swapped | a.missing)
    np.testing.assert_array_equal(a.keypoints[keep], clean.keypoints[keep])


def test_shape_checks():
    with pytest.raises(ValueError, match=r"uv_true: expected shape \(12, 2\)"):
        corrupt_keypoints(np.zeros((11, 2)), np.zeros(12, bool), NoiseModel(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="occluded"):
        corrupt_keypoints(np.zeros((12, 2)), np.zeros(10, bool), NoiseModel(), np.random.default_rng(0))


def test_a_keypoint_truly_outside_the_image_stays_missing_whatever_the_noise_or_the_labels():
    # Large pixel noise and outliers could move a point that lies outside the image into it; the detector
    # cannot see it, so it stays missing. A swapped label carries its source's visibility with it.
    rng = np.random.default_rng(5)
    noise = NoiseModel(relative_sigma=0.5, outlier_rate=0.5, outlier_box_growth=3.0, swap_rate=0.0, missing_rate=0.0)
    for _ in range(200):
        uv = _true_uv(rng)
        uv[0] = [-3.0, 300.0]  # just left of the image
        out = corrupt_keypoints(uv, np.zeros(12, bool), noise, rng, SIZE)
        assert out.missing[0] and out.confidence[0] == 0
    swap_all = NoiseModel(relative_sigma=0.0, outlier_rate=0.0, swap_rate=1.0, missing_rate=0.0)
    uv = _true_uv(rng)
    uv[0] = [-30.0, 300.0]  # left_front_wheel outside; its partner (1) inside
    out = corrupt_keypoints(uv, np.zeros(12, bool), swap_all, rng, SIZE)
    assert out.swapped[0] and out.swapped[1]
    assert not out.missing[0] and out.missing[1]  # label 0 now holds keypoint 1's (seen) pixel, label 1 nothing
    np.testing.assert_allclose(out.keypoints[0], uv[1])
