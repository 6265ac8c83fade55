"""Covariance calibration: the fit recovers known parameters, the detector applies it, the weights carry it."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from tests.net.fakes import COV, H, PEAKS, S, fixed_net  # noqa: E402
from tests.net.synthetic import blob_dataset  # noqa: E402
from vfactor.heatmaps import heatmap_to_image  # noqa: E402
from vfactor.net.calibrate import (  # noqa: E402
    METADATA_KEY,
    CovarianceCalibration,
    KeypointErrors,
    fit_calibration,
    load_crops,
    measure_errors,
    summarise,
    write_calibration,
)
from vfactor.net.commands import main  # noqa: E402
from vfactor.net.data import KeypointDataset  # noqa: E402
from vfactor.net.infer import KeypointDetector  # noqa: E402
from vfactor.net.model import StackedHourglass, load_weights, save_weights  # noqa: E402


def synthetic_errors(truth: CovarianceCalibration, n: int = 3000, outliers: float = 0.05, seed: int = 0):
    """Errors drawn from ``truth.apply(S, confidence, box)`` for random heatmap covariances, plus gross errors."""
    rng = np.random.default_rng(seed)
    side = rng.uniform(60, 400, n)
    wh = np.stack([side, side * rng.uniform(0.8, 1.0, n)], axis=1)
    std = rng.uniform(0.02, 0.15, (n, 2)) * wh  # heatmap spreads of 2-15 % of the box
    c, s = np.cos(angle := rng.uniform(0, np.pi, n)), np.sin(angle)
    R = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    cov = R @ (std[:, :, None] * np.eye(2) * std[:, None, :]) @ np.swapaxes(R, 1, 2)
    conf = rng.uniform(0.4, 1.0, n)
    err = np.einsum("nij,nj->ni", np.linalg.cholesky(truth.apply(cov, conf, wh)), rng.standard_normal((n, 2)))
    gross = rng.random(n) < outliers
    err[gross] = rng.uniform(-0.5, 0.5, (int(gross.sum()), 2)) * wh[gross]
    vis = rng.random(n) < 0.7
    return KeypointErrors(err, cov, conf, wh, vis, ~vis, np.arange(n) // 12), gross


def test_fit_recovers_a_known_scale_floor_and_confidence_rate():
    truth = CovarianceCalibration(scale=0.04, floor=0.01, confidence_rate=3.0)
    errors, gross = synthetic_errors(truth)
    cal = fit_calibration(errors)
    assert cal.scale == pytest.approx(0.04, rel=0.15)
    assert cal.floor == pytest.approx(0.01, rel=0.15)
    assert cal.confidence_rate == pytest.approx(3.0, abs=0.4)
    # the 5 % gross errors do not inflate it: d2 of the rest is chi-square(2)
    stats = summarise(errors.subset(~gross), cal, alpha=1.0)["all"]
    assert stats["d2_median"] == pytest.approx(2 * np.log(2), rel=0.1)
    assert stats["d2_mean_correct"] == pytest.approx(2.0, rel=0.1)


def test_fit_of_a_scale_alone():
    errors, _ = synthetic_errors(CovarianceCalibration(scale=0.05), outliers=0.0, seed=1)
    cal = fit_calibration(errors, floor=False, confidence=False)
    assert cal.scale == pytest.approx(0.05, rel=0.05)
    assert cal.floor == 0.0 and cal.confidence_rate == 0.0
    with pytest.raises(ValueError, match="at least 10"):
        fit_calibration(errors.subset(np.arange(5)))


def test_apply():
    cal = CovarianceCalibration(scale=0.5, floor=0.01, confidence_rate=2.0)
    cov = np.array([[[4.0, 1.0], [1.0, 2.0]], [[np.nan] * 2] * 2])
    out = cal.apply(cov, [0.75, 0.0], (200.0, 100.0))
    np.testing.assert_allclose(out[0], np.exp(0.5) * (0.5 * cov[0] + np.diag([4.0, 1.0])))
    assert np.all(np.isnan(out[1]))
    np.testing.assert_allclose(CovarianceCalibration().apply(cov[0], 0.3, 50.0), cov[0])
    assert CovarianceCalibration().is_identity and not cal.is_identity


def test_detector_applies_a_given_calibration():
    cal = CovarianceCalibration(scale=0.2, floor=0.02, confidence_rate=1.5)
    image = np.zeros((300, 400, 3), np.uint8)
    roi = (100, 50, 228, 146)  # 128 x 96 px: sx = 8, sy = 6 image px per heatmap px
    (raw,) = KeypointDetector(fixed_net(), device="cpu", flip_test=False).detect(image, [roi])  # no metadata: the identity
    J = np.diag([8.0, 6.0])
    np.testing.assert_allclose(raw.covariance, np.broadcast_to(J @ COV @ J.T, (12, 2, 2)), rtol=1e-6)
    for given in (cal, cal.to_dict()):
        det = KeypointDetector(fixed_net(), device="cpu", calibration=given, flip_test=False)
        assert det.calibration == cal
        (kp,) = det.detect(image, [roi])
        gain = np.exp(1.5 * (1 - raw.confidence))[:, None, None]
        floor = np.diag([(0.02 * 128) ** 2, (0.02 * 96) ** 2])
        np.testing.assert_allclose(kp.covariance, gain * (0.2 * raw.covariance + floor), rtol=1e-9)
        np.testing.assert_array_equal(kp.uv, raw.uv)
        np.testing.assert_array_equal(kp.confidence, raw.confidence)


def test_calibration_round_trips_through_the_weights_metadata(tmp_path):
    torch.manual_seed(0)
    net = StackedHourglass(num_stacks=1, channels=8, depth=2, input_size=32)
    path = save_weights(net, tmp_path / "w.pt", {"crop": {"margin": 0.2, "square": True}})
    assert KeypointDetector(path).calibration.is_identity
    cal = CovarianceCalibration(scale=0.03, floor=0.004, confidence_rate=4.5)
    assert CovarianceCalibration.from_dict(cal.to_dict()) == cal
    write_calibration(path, cal, {"note": "test"})
    payload = torch.load(path, weights_only=True)
    assert payload["config"][METADATA_KEY] == cal.to_dict() and payload["config"]["note"] == "test"
    model, meta = load_weights(path, with_config=True)
    assert meta["crop"] == {"margin": 0.2, "square": True}
    for name, tensor in net.state_dict().items():
        assert torch.equal(model.state_dict()[name], tensor), name
    det = KeypointDetector(path)
    assert det.calibration == cal and (det.roi_margin, det.roi_square) == (0.2, True)
    assert KeypointDetector(path, calibration=CovarianceCalibration()).calibration.is_identity


def test_bad_calibration_input_raises_naming_the_field(tmp_path):
    for kwargs, field in [({"scale": -1.0}, "scale"), ({"scale": 0.0}, "scale"), ({"floor": np.nan}, "floor"),
                          ({"confidence_rate": -0.5}, "confidence_rate"), ({"scale": True}, "scale"),
                          ({"floor": "0.1"}, "floor")]:
        with pytest.raises(ValueError, match=rf"calibration\.{field}"):
            CovarianceCalibration(**kwargs)
    with pytest.raises(ValueError, match="sigma"):
        CovarianceCalibration.from_dict({"scale": 1.0, "sigma": 2.0})
    with pytest.raises(ValueError, match="covariance"):
        CovarianceCalibration().apply(np.eye(3), 1.0, 10.0)
    with pytest.raises(ValueError, match="box_size"):
        CovarianceCalibration().apply(np.stack([np.eye(2)] * 3), 1.0, np.ones((2, 2)))
    with pytest.raises(TypeError, match="calibration"):
        KeypointDetector(fixed_net(), calibration=0.5)
    torch.save({"something": 1}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a vfactor"):
        write_calibration(tmp_path / "other.pt", CovarianceCalibration())


def test_errors_are_measured_in_image_pixels_through_the_crop_boxes():
    """Known heatmaps against known keypoints: the errors are the offsets, scaled by each box."""
    rng = np.random.default_rng(0)
    truth_hm = PEAKS + rng.uniform(-0.5, 0.5, PEAKS.shape)  # heatmap px
    crop_kp = heatmap_to_image(truth_hm, (0, 0, S, S), (H, H))
    crop_kp[11] = [S + 5.0, 10.0]  # outside the crop: not measured
    occ = np.zeros((2, 12), bool)
    occ[:, :3] = True
    ds = KeypointDataset(np.zeros((2, S, S, 3), np.uint8), np.stack([crop_kp] * 2), ~occ, occ)
    rois = np.array([[0.0, 0.0, 64.0, 64.0], [100.0, 50.0, 356.0, 306.0]])  # scales 1 and 4
    err = measure_errors(KeypointDetector(fixed_net(), device="cpu", flip_test=False), ds, rois)
    assert len(err) == 22 and err.crop.tolist() == [0] * 11 + [1] * 11
    offset = (PEAKS - truth_hm)[:11] * (S / H)  # crop px
    np.testing.assert_allclose(err.error, np.concatenate([offset, 4 * offset]), atol=1e-4)  # float32 heatmaps
    np.testing.assert_allclose(err.covariance[11:], np.broadcast_to(16 * 16 * COV, (11, 2, 2)), rtol=1e-6)
    np.testing.assert_array_equal(err.box_size[11:], np.full((11, 2), 256.0))
    assert err.self_occluded.sum() == 6 and err.visible.sum() == 16
    stats = summarise(err)
    assert stats["self_occluded"]["n"] == 6 and stats["all"]["n"] == 22


def test_load_crops_returns_the_shards_rois_reading_each_shard_once(tmp_path, monkeypatch):
    images, kp, vis, occ = blob_dataset(6, 32, seed=2)
    rois = np.array([[10.0 * i, 20.0, 10.0 * i + 96.0, 116.0] for i in range(6)])
    (tmp_path / "val").mkdir()
    for name, rows in (("a", slice(0, 4)), ("b", slice(4, 6))):  # renderer-like shards: more keys than read
        np.savez_compressed(tmp_path / "val" / f"{name}.npz", images=images[rows], keypoints=kp[rows],
                            visible=vis[rows], self_occluded=occ[rows], rois=rois[rows], in_crop=vis[rows])
    opened = []
    real_load = np.load
    monkeypatch.setattr(np, "load", lambda f, *a, **k: opened.append(f) or real_load(f, *a, **k))
    ds, got = load_crops(tmp_path / "val", size=16)
    assert len(opened) == 2  # one read per shard
    assert ds.crop_size == 16 and got is ds.rois
    np.testing.assert_array_equal(got, rois)  # full-image boxes: unchanged by the resize
    monkeypatch.undo()
    np.savez_compressed(tmp_path / "val" / "c.npz", images=images[:1], keypoints=kp[:1])  # no rois
    ds, got = load_crops([tmp_path / "val" / "a.npz", tmp_path / "val" / "c.npz"])
    assert len(ds) == 5 and got is None
    arrays = {"images": images, "keypoints": kp, "visible": vis, "self_occluded": occ, "rois": rois}
    for form in (arrays, KeypointDataset(images, kp, vis, occ, rois)):
        np.testing.assert_array_equal(load_crops(form)[1], rois)
    assert load_crops(KeypointDataset(images, kp, vis, occ))[1] is None


def test_calibrate_command_reports_and_writes(tmp_path, capsys):
    torch.manual_seed(0)
    net = StackedHourglass(num_stacks=1, channels=8, depth=2, input_size=32).eval()
    with torch.no_grad():
        net.heads[-1].bias.fill_(0.5)  # every peak above min_confidence: keypoints found (far off: untrained)
    path = save_weights(net, tmp_path / "w.pt", {"crop": {"margin": 0.0, "square": True}})
    images, kp, vis, occ = blob_dataset(24, 32, seed=0)
    rois = np.tile([10.0, 20.0, 106.0, 116.0], (24, 1))
    np.savez_compressed(tmp_path / "val.npz", images=images, keypoints=kp, visible=vis, self_occluded=occ, rois=rois)
    bias = (0.01, 0.01, 0.01, 0.03, 0.01, 0.02)  # calibrate-shape's and calibrate-bias's, which --write keeps
    write_calibration(path, CovarianceCalibration(shape_sigma=0.07, bias_sigma=bias))
    code = main(["calibrate", "--weights", str(path), "--val", str(tmp_path / "val.npz"), "--write"])
    assert code == 0
    out = capsys.readouterr()
    assert "| visible | before |" in out.out and "| self-occluded | after |" in out.out
    assert "weights unchanged" in out.err
    model, meta = load_weights(path, with_config=True)
    cal = CovarianceCalibration.from_dict(meta[METADATA_KEY])
    assert KeypointDetector(path).calibration == cal and cal.shape_sigma == 0.07 and not cal.is_identity
    assert cal.bias_sigma == bias
    assert meta[f"{METADATA_KEY}_check"]["data"] == [str(tmp_path / "val.npz")]
    for name, tensor in net.state_dict().items():
        assert torch.equal(model.state_dict()[name], tensor), name


def test_calibrate_command_reports_bad_input(tmp_path, capsys):
    save_weights(StackedHourglass(num_stacks=1, channels=8, depth=2, input_size=32), tmp_path / "w.pt")
    assert main(["calibrate", "--weights", str(tmp_path / "w.pt")]) == 2
    assert "--val" in capsys.readouterr().err
    assert main(["calibrate", "--weights", str(tmp_path / "w.pt"), "--val", str(tmp_path / "missing")]) == 2
    assert "--val" in capsys.readouterr().err
    assert main(["calibrate", "--weights", str(tmp_path / "none.pt"), "--val", str(tmp_path)]) == 2
    assert "--weights" in capsys.readouterr().err
