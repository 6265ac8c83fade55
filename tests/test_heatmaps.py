"""Tests of vfactor.heatmaps: sub-pixel peaks, covariances, ROI mapping, empty heatmaps."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.heatmaps import (
    DecodedKeypoints,
    decode_heatmaps,
    heatmap_to_image,
    image_to_heatmap,
    render_gaussian_heatmap,
)


def rotated_covariance(sigma_major: float, sigma_minor: float, angle_deg: float) -> np.ndarray:
    a = np.deg2rad(angle_deg)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return R @ np.diag([sigma_major**2, sigma_minor**2]) @ R.T


def assert_covariance_close(actual, expected, rel=0.1):
    """Each entry within ``rel`` of the largest entry of ``expected`` (off-diagonals may be 0)."""
    expected = np.asarray(expected)
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rel * np.abs(expected).max())


COVARIANCES = {
    "isotropic": np.eye(2) * 1.5**2,
    "sharp": np.eye(2) * 0.7**2,
    "anisotropic": np.diag([2.5**2, 1.0**2]),
    "rotated": rotated_covariance(2.5, 0.9, 30.0),
    "rotated_steep": rotated_covariance(3.0, 0.8, -70.0),
}


@pytest.mark.parametrize("name", sorted(COVARIANCES))
@pytest.mark.parametrize("mu", [(20.0, 15.0), (20.37, 14.81), (31.5, 9.5), (7.93, 40.12)])
def test_gaussian_decodes_to_its_peak_and_covariance(name, mu):
    S = COVARIANCES[name]
    h = render_gaussian_heatmap(mu, S, (48, 40))
    d = decode_heatmaps(h)
    assert np.linalg.norm(d.uv - mu) < 0.05
    assert_covariance_close(d.covariance, S)
    assert d.confidence == pytest.approx(h.max())


def test_noisy_gaussians_decode_within_tolerance():
    rng = np.random.default_rng(7)
    S = rotated_covariance(2.0, 1.2, 40.0)
    peak_errors, cov_errors = [], []
    for _ in range(40):
        mu = rng.uniform(8, 40, size=2)
        h = render_gaussian_heatmap(mu, S, (48, 48)) + rng.normal(0.0, 0.01, (48, 48))
        d = decode_heatmaps(h)
        peak_errors.append(np.linalg.norm(d.uv - mu))
        cov_errors.append(np.abs(d.covariance - S).max() / np.abs(S).max())
    assert np.mean(peak_errors) < 0.05 and max(peak_errors) < 0.1
    assert np.mean(cov_errors) < 0.05 and max(cov_errors) < 0.15


def test_noise_spike_beside_a_sharp_peak_is_ignored():
    mu = np.array([20.2, 20.4])
    S = np.eye(2) * 0.8**2
    h = render_gaussian_heatmap(mu, S, (40, 40))
    h[23, 20] = 0.15  # isolated spike three rows below the peak
    d = decode_heatmaps(h)
    assert np.linalg.norm(d.uv - mu) < 0.05
    assert_covariance_close(d.covariance, S)


def test_second_blob_elsewhere_does_not_bias_the_peak():
    mu = (12.3, 10.6)
    S = np.eye(2) * 1.2**2
    h = render_gaussian_heatmap(mu, S, (32, 48)) + render_gaussian_heatmap((30.0, 20.0), S, (32, 48), peak=0.6)
    d = decode_heatmaps(h)
    assert np.linalg.norm(d.uv - mu) < 0.01
    assert_covariance_close(d.covariance, S, rel=0.02)


def test_peak_near_the_border():
    mu = (0.3, 22.6)
    S = np.diag([1.2, 0.8])
    d = decode_heatmaps(render_gaussian_heatmap(mu, S, (32, 32)))
    assert np.linalg.norm(d.uv - mu) < 0.05
    assert_covariance_close(d.covariance, S)


def test_one_pixel_spike_falls_back_to_moments():
    h = np.zeros((16, 16))
    h[5, 9] = 0.8
    d = decode_heatmaps(h)
    np.testing.assert_allclose(d.uv, [9.0, 5.0])
    np.testing.assert_allclose(d.covariance, np.eye(2) / 12.0)  # pixel quantisation only
    assert d.confidence == pytest.approx(0.8)


def test_flat_top_falls_back_to_moments():
    h = np.zeros((16, 16))
    h[5:7, 8:10] = 1.0  # a 2x2 plateau centred at (8.5, 5.5)
    d = decode_heatmaps(h)
    np.testing.assert_allclose(d.uv, [8.5, 5.5], atol=1e-12)
    assert np.all(np.linalg.eigvalsh(d.covariance) > 0)


def test_roi_pixel_convention():
    # 4 image pixels per heatmap pixel; heatmap column c covers image x in
    # [x0 + 4c, x0 + 4c + 4), so its centre is at u = x0 + 4c + 1.5.
    roi = (100.0, 50.0, 356.0, 242.0)
    shape = (48, 64)
    np.testing.assert_allclose(heatmap_to_image([0.0, 0.0], roi, shape), [101.5, 51.5])
    np.testing.assert_allclose(heatmap_to_image([10.25, 20.5], roi, shape), [142.5, 133.5])
    # The box's edges: heatmap edge -0.5 is the ROI's edge x0 - 0.5 in centre coordinates.
    np.testing.assert_allclose(heatmap_to_image([-0.5, -0.5], roi, shape), [99.5, 49.5])
    np.testing.assert_allclose(heatmap_to_image([63.5, 47.5], roi, shape), [355.5, 241.5])
    # Identity for a ROI covering the heatmap's own pixels, and for None.
    np.testing.assert_allclose(heatmap_to_image([3.3, 4.4], (0, 0, 64, 48), shape), [3.3, 4.4])
    np.testing.assert_allclose(heatmap_to_image([3.3, 4.4], None, shape), [3.3, 4.4])
    uv = np.array([[120.7, 60.2], [300.0, 200.0]])
    np.testing.assert_allclose(heatmap_to_image(image_to_heatmap(uv, roi, shape), roi, shape), uv)


def test_decode_with_roi_maps_peak_and_scales_covariance():
    roi = (200.0, 100.0, 392.0, 228.0)  # sx = 4, sy = 2
    shape = (64, 48)
    uv_image = np.array([271.3, 151.9])
    S_heatmap = rotated_covariance(1.8, 1.1, 25.0)
    h = render_gaussian_heatmap(image_to_heatmap(uv_image, roi, shape), S_heatmap, shape)
    d = decode_heatmaps(np.stack([h, h]), roi=roi)
    J = np.diag([4.0, 2.0])
    for k in range(2):
        assert np.linalg.norm(d.uv[k] - uv_image) < 0.05 * 4
        assert_covariance_close(d.covariance[k], J @ S_heatmap @ J.T)
    xy = image_to_heatmap(uv_image, roi, shape)
    np.testing.assert_allclose(xy, [(271.3 + 0.5 - 200.0) / 4 - 0.5, (151.9 + 0.5 - 100.0) / 2 - 0.5])


def test_stack_of_twelve_and_not_found_keypoints():
    rng = np.random.default_rng(3)
    shape = (32, 32)
    mus = rng.uniform(6, 26, size=(12, 2))
    peaks = np.linspace(0.0, 1.1, 12)  # 0 (empty), low (below min_confidence), ..., > 1 (clipped)
    stack = np.stack(
        [render_gaussian_heatmap(mu, np.eye(2) * 1.5, shape, peak=p) for mu, p in zip(mus, peaks, strict=True)]
    )
    d = decode_heatmaps(stack, min_confidence=0.05)
    assert isinstance(d, DecodedKeypoints)
    assert d.uv.shape == (12, 2) and d.confidence.shape == (12,) and d.covariance.shape == (12, 2, 2)
    found = peaks >= 0.05
    assert not found[0] and found[1:].all()
    assert d.confidence[0] == 0 and np.all(np.isnan(d.uv[0])) and np.all(np.isnan(d.covariance[0]))
    assert np.all(d.confidence[1:] > 0) and d.confidence.max() == 1.0
    assert np.all(np.linalg.norm(d.uv[found] - mus[found], axis=1) < 0.05)
    d_high = decode_heatmaps(stack, min_confidence=0.5)
    lost = stack.max(axis=(1, 2)) < 0.5  # the sampled peak, not the Gaussian's
    assert np.all(d_high.confidence[lost] == 0) and np.all(np.isnan(d_high.uv[lost]))
    assert np.all(d_high.confidence[~lost] > 0)


def test_empty_and_negative_heatmaps_have_zero_confidence():
    for h in (np.zeros((20, 30)), np.full((20, 30), -0.2)):
        d = decode_heatmaps(h)
        assert d.uv.shape == (2,) and d.covariance.shape == (2, 2)
        assert d.confidence == 0
        assert np.all(np.isnan(d.uv)) and np.all(np.isnan(d.covariance))


def test_float32_input():
    h = render_gaussian_heatmap((10.4, 12.7), np.eye(2) * 2.0, (32, 32)).astype(np.float32)
    d = decode_heatmaps(h)
    assert np.linalg.norm(d.uv - (10.4, 12.7)) < 0.05
    assert_covariance_close(d.covariance, np.eye(2) * 2.0)


@pytest.mark.parametrize(
    "heatmaps, roi, match",
    [
        (np.zeros((2, 3, 4, 5)), None, "shape"),
        (np.zeros((3, 0, 4)), None, "shape"),
        (np.zeros((4, 4), dtype=bool), None, "real numbers"),
        (np.full((4, 4), np.nan), None, "NaN"),
        (np.zeros((4, 4)), (10, 0, 5, 8), "roi"),
        (np.zeros((4, 4)), (0, 0, 8), "roi"),
    ],
)
def test_bad_inputs_raise(heatmaps, roi, match):
    with pytest.raises(ValueError, match=match):
        decode_heatmaps(heatmaps, roi=roi)


def test_render_gaussian_heatmap_values():
    S = np.array([[2.0, 0.6], [0.6, 1.0]])
    h = render_gaussian_heatmap((3.0, 2.0), S, (5, 7), peak=0.9)
    assert h.shape == (5, 7)
    assert h[2, 3] == pytest.approx(0.9)
    d = np.array([1.0, 1.0])  # pixel (row 3, col 4)
    assert h[3, 4] == pytest.approx(0.9 * np.exp(-0.5 * d @ np.linalg.solve(S, d)))
    with pytest.raises(ValueError, match="positive-definite"):
        render_gaussian_heatmap((1.0, 1.0), [[1.0, 2.0], [2.0, 1.0]], (5, 5))
