"""Inference: boxes are cropped, and heatmap peaks are mapped back to the right image pixels through the box."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from torch.nn import functional as F  # noqa: E402

from tests.net.fakes import COV, H, PEAKS, S, FixedHeatmaps  # noqa: E402
from vfactor.heatmaps import clip_roi_to_image, extend_clipped_roi, heatmap_to_image  # noqa: E402
from vfactor.net.crop import crop_roi, expand_roi, image_to_crop  # noqa: E402
from vfactor.net.infer import KeypointDetector, benchmark_inference  # noqa: E402
from vfactor.net.model import StackedHourglass, save_weights  # noqa: E402


class RedInFirstChannel(StackedHourglass):
    """Heatmap 0 (left front wheel) is the crop's red channel pooled over 4x4 blocks; the others are empty."""

    def forward(self, x):
        out = torch.zeros(len(x), 12, x.shape[2] // 4, x.shape[3] // 4)
        out[:, 0] = F.avg_pool2d(x[:, :1], 4)[:, 0]
        return [out]


class RedChannelPooled(StackedHourglass):
    """Every heatmap is the crop's red channel averaged over 4x4 blocks: a red blob comes out where it is."""

    def forward(self, x):
        return [F.avg_pool2d(x[:, :1], 4).expand(-1, 12, -1, -1)]


def blob(shape, uv, sigma):
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    return np.exp(-0.5 * ((cols - uv[0]) ** 2 + (rows - uv[1]) ** 2) / sigma**2)


def test_known_heatmaps_decode_to_image_pixels_through_the_roi():
    det = KeypointDetector(FixedHeatmaps(num_stacks=1, channels=8, depth=2, input_size=S), device="cpu",
                           flip_test=False)
    image = np.zeros((300, 400, 3), np.uint8)
    roi = (100, 50, 228, 146)  # 128 x 96 px: sx = 8, sy = 6 image px per heatmap px
    (kp,), heatmaps = det.detect(image, [roi], return_heatmaps=True)
    assert heatmaps.shape == (1, 12, H, H)
    none, empty = det.detect(image, [], return_heatmaps=True)  # no box: (0, 12, 0, 0) before, not stackable
    assert none == [] and empty.shape == (0, 12, H, H) and empty.dtype == np.float32
    np.testing.assert_allclose(kp.uv, heatmap_to_image(PEAKS, roi, (H, H)), atol=1e-6)
    J = np.diag([8.0, 6.0])
    np.testing.assert_allclose(kp.covariance, np.broadcast_to(J @ COV @ J.T, (12, 2, 2)), rtol=1e-6)
    np.testing.assert_allclose(kp.confidence, heatmaps[0].max(axis=(1, 2)), rtol=1e-6)  # the peak pixel


def test_a_blob_in_the_image_is_found_at_its_pixel():
    """Crop, resize, network, decoding and mapping back, end to end (a 'network' that pools the red channel)."""
    image = np.zeros((240, 320, 3), np.uint8)
    uv = np.array([181.3, 97.8])
    image[..., 0] = np.rint(230 * blob(image.shape[:2], uv, 12.0)).astype(np.uint8)
    det = KeypointDetector(RedChannelPooled(num_stacks=1, channels=8, depth=2, input_size=S), device="cpu")
    for roi in [(120, 40, 248, 168), (150.2, 60.7, 230.9, 139.1), (100, 20, 300, 220)]:
        (kp,) = det.detect(image, [roi])
        np.testing.assert_allclose(kp.uv, np.broadcast_to(uv, (12, 2)), atol=0.35)
        assert np.all(kp.confidence > 0.5)


def test_flip_test_mirrors_back_and_swaps_left_and_right():
    """A blob seen as the left front wheel: the mirrored crop sees it as the right front wheel, at the same pixel."""
    image = np.zeros((240, 320, 3), np.uint8)
    uv = np.array([171.6, 103.2])
    image[..., 0] = np.rint(230 * blob(image.shape[:2], uv, 12.0)).astype(np.uint8)
    net = RedInFirstChannel(num_stacks=1, channels=8, depth=2, input_size=S)
    roi = (120.0, 40.0, 248.0, 168.0)
    (plain,), hm_plain = KeypointDetector(net, device="cpu", flip_test=False).detect(image, [roi], True)
    (flipped,), hm_flip = KeypointDetector(net, device="cpu").detect(image, [roi], True)
    assert np.isnan(plain.uv[1]).all() and np.isfinite(plain.uv[0]).all()
    np.testing.assert_allclose(hm_flip[0, 0], 0.5 * hm_plain[0, 0], atol=0.02 * hm_plain.max())
    np.testing.assert_allclose(hm_flip[0, 1], 0.5 * hm_plain[0, 0], atol=0.02 * hm_plain.max())
    for k in (0, 1):  # both at the blob, to the accuracy of the un-flipped decoding
        np.testing.assert_allclose(flipped.uv[k], uv, atol=0.35)
    np.testing.assert_allclose(plain.uv[0], uv, atol=0.35)
    assert np.isnan(flipped.uv[2:]).all()


def test_boxes_are_grown_and_squared_as_the_weights_say(tmp_path):
    net = FixedHeatmaps(num_stacks=1, channels=8, depth=2, input_size=S)
    path = save_weights(net, tmp_path / "w.pt", {"crop": {"margin": 0.25, "square": True}})
    assert (KeypointDetector(path).roi_margin, KeypointDetector(path).roi_square) == (0.25, True)
    det = KeypointDetector(net, device="cpu", roi_margin=0.25, roi_square=True, flip_test=False)
    box = (100.0, 50.0, 180.0, 90.0)  # 80 x 40 -> 120 x 60 -> square 120 about (140, 70)
    assert det.crop_box(box) == (80.0, 10.0, 200.0, 130.0)
    [[d]] = det.detect_batch([np.zeros((200, 300, 3), np.uint8)], [[box]])
    assert d.roi == (80.0, 10.0, 200.0, 130.0)
    np.testing.assert_allclose(d.keypoints.uv, heatmap_to_image(PEAKS, d.roi, (H, H)), atol=1e-6)


def test_a_box_clipped_by_the_image_border_is_grown_beyond_it():
    """A 2D detector's box stops at the border of an image that cuts the vehicle; the network was trained on the
    whole vehicle's box, so that edge is first moved out by CLIPPED_EXTENSION of the box's side."""
    assert extend_clipped_roi((0, 100, 200, 180), 1280, 720) == pytest.approx((-50, 100, 200, 180))
    assert clip_roi_to_image((-50, 10, 1300, 730), 1280, 720) == pytest.approx((-0.5, 10, 1279.5, 719.5))
    assert extend_clipped_roi((1000, 100, 1280, 180), 1280, 720) == pytest.approx((1000, 100, 1350, 180))
    assert extend_clipped_roi((10, -0.5, 200, 719.5), 1280, 720) == pytest.approx((10, -180.5, 200, 899.5))
    for inside_or_beyond in [(10, 100, 200, 180), (-60, 100, 200, 180), (1000, 100, 1400, 180)]:
        assert extend_clipped_roi(inside_or_beyond, 1280, 720) == pytest.approx(inside_or_beyond)
    assert extend_clipped_roi((0, 100, 200, 180), 1280, 720, extension=0.0) == pytest.approx((0, 100, 200, 180))
    with pytest.raises(ValueError, match="extension"):
        extend_clipped_roi((0, 100, 200, 180), 1280, 720, extension=-1)
    net = FixedHeatmaps(num_stacks=1, channels=8, depth=2, input_size=S)
    image = np.zeros((100, 150, 3), np.uint8)
    detector = KeypointDetector(net, device="cpu", roi_margin=0.0, flip_test=False)
    [[grown]] = detector.detect_batch([image], [[(0, 20, 40, 60)]])
    assert grown.roi == (-10.0, 20.0, 40.0, 60.0)  # the left edge 10 px (a quarter of 40) beyond the image
    np.testing.assert_allclose(grown.keypoints.uv, heatmap_to_image(PEAKS, grown.roi, (H, H)), atol=1e-6)
    [[kept]] = KeypointDetector(net, device="cpu", roi_margin=0.0, flip_test=False,
                                clipped_extension=0).detect_batch([image], [[(0, 20, 40, 60)]])
    assert kept.roi == (0.0, 20.0, 40.0, 60.0)
    with pytest.raises(ValueError, match="clipped_extension"):
        KeypointDetector(net, device="cpu", clipped_extension=-0.1)


def test_batch_form_keeps_boxes_with_their_images():
    det = KeypointDetector(FixedHeatmaps(num_stacks=1, channels=8, depth=2, input_size=S), device="cpu", batch_size=2)
    images = [np.zeros((100, 100, 3), np.uint8), np.zeros((80, 120, 3), np.uint8), np.zeros((50, 50, 3), np.uint8)]
    rois = [[(0, 0, 50, 50), (10, 10, 90, 90)], [], [(-10, -10, 40, 40)]]
    out = det.detect_batch(images, rois)
    assert [len(o) for o in out] == [2, 0, 1]
    assert out[2][0].roi == (-10.0, -10.0, 40.0, 40.0) and out[0][1].heatmaps.shape == (12, H, H)
    with pytest.raises(ValueError, match=r"rois\[0\]\[0\]"):
        det.detect_batch(images[:1], [[(5, 5, 5, 9)]])
    with pytest.raises(ValueError, match="uint8"):
        det.detect(np.zeros((10, 10, 3)), [(0, 0, 5, 5)])


def test_crop_maps_image_pixels_to_crop_pixels():
    image = np.zeros((200, 260), np.float32)
    uv = np.array([131.4, 88.2])
    image[:] = blob(image.shape, uv, 6.0)
    for roi, exact in [((80, 40, 208, 168), True), ((80.3, 40.6, 207.2, 131.9), False)]:
        crop, used = crop_roi(image, roi, 64, integer_roi=exact)
        assert crop.shape == (64, 64)
        rows, cols = np.mgrid[0:64, 0:64]
        centroid = np.array([(crop * cols).sum(), (crop * rows).sum()]) / crop.sum()
        np.testing.assert_allclose(centroid, image_to_crop(uv, used, 64), atol=0.05)


def test_expand_roi():
    assert expand_roi((0, 0, 10, 20), 0.1) == pytest.approx((-1, -2, 11, 22))
    assert expand_roi((0, 0, 10, 20), 0.0, square=True) == pytest.approx((-5, 0, 15, 20))
    with pytest.raises(ValueError, match="roi"):
        expand_roi((0, 0, -1, 5))


def test_benchmark_reports_each_batch_size():
    net = StackedHourglass(num_stacks=1, channels=8, depth=2, input_size=32)
    times = benchmark_inference(net, (1, 4), repeats=1, warmup=0)
    assert set(times) == {1, 4} and all(t > 0 for t in times.values())
