"""Training data: augmentation moves keypoints with the pixels (flip swaps left and right), datasets in every form
(the crops' boxes, ``rois``, carried along)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.net.synthetic import COLOURS, blob_dataset, blob_image, spread_keypoints
from vfactor.keypoints import MIRROR_PERMUTATION
from vfactor.net.data import AugmentConfig, KeypointDataset, Sample, as_dataset, augment, sample_rng

STILL = dict(flip=0.0, scale=0.0, rotation_deg=0.0, shift=0.0, brightness=0.0, contrast=0.0, saturation=0.0,
             channel_gain=0.0, noise=0.0)


def colour_at(image: np.ndarray, uv) -> np.ndarray:
    u, v = np.rint(uv).astype(int)
    return image[v, u]


def test_flip_mirrors_the_image_and_swaps_left_and_right():
    rng = np.random.default_rng(3)
    kp = spread_keypoints(rng, 64)
    img = blob_image(kp, 64)
    vis = np.arange(12) % 2 == 0
    occ = ~vis
    out, kp2, vis2, occ2 = augment(img, kp, vis, occ, rng, AugmentConfig(**{**STILL, "flip": 1.0}))
    np.testing.assert_array_equal(out, img[:, ::-1] / np.float32(255.0))
    for k in range(12):
        # the new keypoint k (e.g. a left wheel) is the mirrored old partner (the right wheel)
        np.testing.assert_allclose(kp2[k], [63 - kp[MIRROR_PERMUTATION[k], 0], kp[MIRROR_PERMUTATION[k], 1]], atol=1e-4)
        assert np.array_equal(np.rint(colour_at(out, kp2[k]) * 255), COLOURS[MIRROR_PERMUTATION[k]])
    assert np.array_equal(vis2, vis[MIRROR_PERMUTATION]) and np.array_equal(occ2, occ[MIRROR_PERMUTATION])


def test_scale_rotation_shift_keep_each_blob_under_its_keypoint():
    kp = spread_keypoints(np.random.default_rng(4), 96, lo=0.2, hi=0.8)
    img = blob_image(kp, 96, radius=3.5)
    config = AugmentConfig(**{**STILL, "scale": 0.2, "rotation_deg": 20.0, "shift": 0.05})
    for seed in range(5):
        out, kp2, _, _ = augment(img, kp, np.ones(12, bool), np.zeros(12, bool), sample_rng(seed, 0, 0), config)
        for k in range(12):
            if np.all((kp2[k] > 3) & (kp2[k] < 92)):
                np.testing.assert_allclose(colour_at(out, kp2[k]) * 255, COLOURS[k], atol=40)


def test_augmentation_depends_only_on_seed_epoch_index():
    images, kp, vis, occ = blob_dataset(2, 64)
    a = augment(images[0], kp[0], vis[0], occ[0], sample_rng(1, 2, 3))
    b = augment(images[0], kp[0], vis[0], occ[0], sample_rng(1, 2, 3))
    c = augment(images[0], kp[0], vis[0], occ[0], sample_rng(1, 3, 3))
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0], c[0])
    assert a[0].dtype == np.float32 and 0.0 <= a[0].min() and a[0].max() <= 1.0


def test_bad_augment_config_names_the_field():
    with pytest.raises(ValueError, match="augment.rotation_deg"):
        AugmentConfig(rotation_deg=-1.0)


def test_dataset_from_samples_resizes_crops_and_keypoints():
    images, kp, vis, occ = blob_dataset(3, 128)
    samples = [Sample(images[i], kp[i], vis[i], occ[i]) for i in range(3)]
    ds = KeypointDataset.from_samples(samples, size=64)
    assert ds.images.shape == (3, 64, 64, 3) and len(ds) == 3
    np.testing.assert_allclose(ds.keypoints, (kp + 0.5) / 2 - 0.5, atol=1e-5)
    k = 5
    assert np.array_equal(colour_at(ds.images[0], ds.keypoints[0, k]), COLOURS[k])


def test_dataset_forms_and_npz_shards(tmp_path):
    images, kp, vis, occ = blob_dataset(4, 32)
    ds = KeypointDataset(images, kp, vis, occ)
    ds.subset([0, 1]).save_npz(tmp_path / "shards" / "a.npz")
    ds.subset([2, 3]).save_npz(tmp_path / "shards" / "b.npz")
    for form in (tmp_path / "shards", [tmp_path / "shards" / "a.npz", tmp_path / "shards" / "b.npz"],
                 {"images": images, "keypoints": kp, "visible": vis, "self_occluded": occ}, ds,
                 [ds.sample(i) for i in range(4)]):
        got = as_dataset(form)
        np.testing.assert_array_equal(got.images, images)
        np.testing.assert_array_equal(got.keypoints, kp)
        np.testing.assert_array_equal(got.visible, vis)
        np.testing.assert_array_equal(got.self_occluded, occ)


def test_dataset_checks_shapes():
    with pytest.raises(ValueError, match="images"):
        KeypointDataset(np.zeros((2, 32, 16, 3), np.uint8), np.zeros((2, 12, 2)))
    with pytest.raises(ValueError, match="visible"):
        KeypointDataset(np.zeros((2, 32, 32, 3), np.uint8), np.zeros((2, 12, 2)), np.zeros((2, 11), bool))
    with pytest.raises(ValueError, match=r"rois: expected shape \(2, 4\)"):
        KeypointDataset(np.zeros((2, 32, 32, 3), np.uint8), np.zeros((2, 12, 2)), rois=np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"rois: expected shape \(2, 4\)"):
        KeypointDataset(np.zeros((2, 32, 32, 3), np.uint8), np.zeros((2, 12, 2)), rois=np.zeros((3, 4)))
    with pytest.raises(ValueError, match="rois: expected finite"):
        KeypointDataset(np.zeros((2, 32, 32, 3), np.uint8), np.zeros((2, 12, 2)),
                        rois=[[0, 0, 8, 8], [0, np.nan, 8, 8]])


def boxed_dataset(n: int = 4, size: int = 32) -> KeypointDataset:
    """Blob crops with distinct boxes: crop i covers ``(10 i, 5 i, 10 i + 64, 5 i + 64)`` of its image."""
    images, kp, vis, occ = blob_dataset(n, size)
    i = np.arange(n, dtype=float)
    return KeypointDataset(images, kp, vis, occ, rois=np.stack([10 * i, 5 * i, 10 * i + 64, 5 * i + 64], axis=1))


def test_rois_round_trip_through_npz_shards(tmp_path):
    ds = boxed_dataset()
    assert ds.rois.dtype == np.float64 and ds.rois.shape == (4, 4)
    ds.subset([0, 1]).save_npz(tmp_path / "shards" / "a.npz")
    ds.subset([2, 3]).save_npz(tmp_path / "shards" / "b.npz")
    got = KeypointDataset.from_npz(tmp_path / "shards")
    np.testing.assert_array_equal(got.rois, ds.rois)
    np.testing.assert_array_equal(got.images, ds.images)
    # a shard without boxes among shards with them: the boxes of the whole are unknown
    KeypointDataset(ds.images[:1], ds.keypoints[:1]).save_npz(tmp_path / "shards" / "c.npz")
    with np.load(tmp_path / "shards" / "c.npz") as z:
        assert "rois" not in z.files
    mixed = KeypointDataset.from_npz(tmp_path / "shards")
    assert len(mixed) == 5 and mixed.rois is None
    assert KeypointDataset.from_npz([tmp_path / "shards" / "a.npz", tmp_path / "shards" / "b.npz"]).rois is not None


def test_subset_concatenate_and_resized_keep_each_crops_box():
    ds = boxed_dataset()
    np.testing.assert_array_equal(ds.subset([3, 1]).rois, ds.rois[[3, 1]])
    np.testing.assert_array_equal(ds.subset(np.array([True, False, True, False])).rois, ds.rois[[0, 2]])
    both = KeypointDataset.concatenate([ds.subset([2]), ds.subset([0, 1])])
    np.testing.assert_array_equal(both.rois, ds.rois[[2, 0, 1]])
    assert KeypointDataset.concatenate([ds.subset([2]), KeypointDataset(ds.images[:1], ds.keypoints[:1])]).rois is None
    small = ds.resized(16)
    assert small.crop_size == 16
    np.testing.assert_allclose(small.keypoints, (ds.keypoints + 0.5) / 2 - 0.5, atol=1e-5)  # crop pixels: scaled
    np.testing.assert_array_equal(small.rois, ds.rois)  # full-image pixels: unchanged
    assert KeypointDataset(ds.images, ds.keypoints).resized(16).rois is None


def test_as_dataset_takes_the_rois_of_arrays_and_objects():
    ds = boxed_dataset()
    arrays = {"images": ds.images, "keypoints": ds.keypoints, "visible": ds.visible,
              "self_occluded": ds.self_occluded, "rois": ds.rois}
    for form in (arrays, SimpleNamespace(**arrays), ds):  # SimpleNamespace: like vfactor.render.RenderedDataset
        np.testing.assert_array_equal(as_dataset(form).rois, ds.rois)
    assert as_dataset({k: v for k, v in arrays.items() if k != "rois"}).rois is None
    assert as_dataset([ds.sample(i) for i in range(4)]).rois is None
