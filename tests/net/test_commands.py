"""The train and detect commands (python -m vfactor.net ..., forwarded to by vfactor train / vfactor detect)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from tests.net.synthetic import blob_dataset  # noqa: E402
from vfactor.net.commands import main  # noqa: E402
from vfactor.net.data import KeypointDataset  # noqa: E402
from vfactor.net.model import StackedHourglass, load_weights, save_weights  # noqa: E402


def test_train_command_from_shards_with_export(tmp_path, capsys):
    KeypointDataset(*blob_dataset(24, 32, seed=0)).save_npz(tmp_path / "train" / "shard_00000.npz")
    KeypointDataset(*blob_dataset(8, 32, seed=1)).save_npz(tmp_path / "val" / "shard_00000.npz")
    (tmp_path / "tiny.json").write_text(json.dumps(
        {"num_stacks": 1, "channels": 8, "depth": 2, "input_size": 32, "batch_size": 8, "num_threads": 1}))
    code = main(["train", "--data", str(tmp_path / "train"), "--val", str(tmp_path / "val"), "--config",
                 str(tmp_path / "tiny.json"), "--epochs", "2", "--out", str(tmp_path / "run"),
                 "--export", str(tmp_path / "shipped" / "keypoints.pt")])
    assert code == 0
    err = capsys.readouterr().err
    assert "epoch 2/2" in err and "weights:" in err
    model, meta = load_weights(tmp_path / "shipped" / "keypoints.pt", with_config=True)
    assert model.config.channels == 8 and meta["train"]["epochs"] == 2
    assert len(json.loads((tmp_path / "run" / "history.json").read_text())) == 2
    # resuming a finished run trains nothing more
    assert main(["train", "--data", str(tmp_path / "train"), "--config", str(tmp_path / "tiny.json"), "--epochs",
                 "2", "--out", str(tmp_path / "run"), "--resume", "--quiet"]) == 0


def test_train_command_reports_bad_input(tmp_path, capsys):
    assert main(["train", "--out", str(tmp_path)]) == 2
    assert "--data" in capsys.readouterr().err
    assert main(["train", "--data", str(tmp_path / "nothing"), "--out", str(tmp_path)]) == 2
    assert main(["train", "--data", str(tmp_path), "--epochs", "0", "--out", str(tmp_path)]) == 2
    assert "epochs" in capsys.readouterr().err
    KeypointDataset(*blob_dataset(8, 32, seed=0)).save_npz(tmp_path / "train" / "shard_00000.npz")
    assert main(["train", "--data", str(tmp_path / "train"), "--init", str(tmp_path / "none.pt"), "--out",
                 str(tmp_path / "run")]) == 2
    assert "--init" in capsys.readouterr().err
    (tmp_path / "bad.pt").write_bytes(b"not weights")
    assert main(["train", "--data", str(tmp_path / "train"), "--init", str(tmp_path / "bad.pt"), "--out",
                 str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --init") and len(err.strip().splitlines()) == 1
    assert main(["train", "--render", "2", "--library-share", "1.5", "--out", str(tmp_path / "run")]) == 2
    assert "--library-share" in capsys.readouterr().err
    for weight in ("van", "van=x", "truck=2", "van=-1"):
        assert main(["train", "--render", "2", "--library-weight", weight, "--out", str(tmp_path / "run")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: --library-weight") and len(err.strip().splitlines()) == 1, err
    assert main(["train", "--render", "2", "--clipped-box-share", "2", "--out", str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err.startswith("error: --clipped-box-share")
    assert main(["train", "--render", "2", "--shape-stretch", "0.7", "--out", str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err.startswith("error: --shape-stretch")


def test_detect_command_writes_keypoints_and_heatmaps(tmp_path, capsys):
    torch.manual_seed(0)
    save_weights(StackedHourglass(num_stacks=1, channels=8, depth=2, input_size=32).eval(), tmp_path / "w.pt",
                 {"crop": {"margin": 0.0, "square": False}})
    image = np.random.default_rng(0).integers(0, 255, (60, 80, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "a.png"), image)
    code = main(["detect", str(tmp_path / "a.png"), "--roi", "10", "5", "42", "37", "--roi", "30", "10", "70", "50",
                 "--weights", str(tmp_path / "w.pt"), "--heatmaps", str(tmp_path / "h.npz")])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["keypoint_names"]) == 12
    (entry,) = doc["images"]
    assert [d["roi"] for d in entry["detections"]] == [[10, 5, 42, 37], [30, 10, 70, 50]]
    d = entry["detections"][0]
    assert len(d["keypoints"]) == 12 and len(d["confidence"]) == 12 and np.shape(d["covariance"]) == (12, 2, 2)
    assert d["covariance_calibrated"] is False and d["shape_sigma"] is None  # these weights carry no calibration
    with np.load(tmp_path / "h.npz") as z:
        assert z["heatmaps"].shape == (2, 12, 8, 8) and z["image_index"].tolist() == [0, 0]

    (tmp_path / "rois.json").write_text(json.dumps({str(tmp_path / "a.png"): [[0, 0, 32, 32]]}))
    out = tmp_path / "r.json"
    assert main(["detect", str(tmp_path / "a.png"), "--rois", str(tmp_path / "rois.json"), "--weights",
                 str(tmp_path / "w.pt"), "--out", str(out)]) == 0
    assert len(json.loads(out.read_text())["images"][0]["detections"]) == 1


def test_detect_command_reports_bad_input(tmp_path, capsys):
    assert main(["detect", str(tmp_path / "missing.png"), "--roi", "0", "0", "5", "5",
                 "--weights", str(tmp_path / "w.pt")]) == 2
    assert main(["detect", str(tmp_path / "a.png")]) == 2
    assert "--roi" in capsys.readouterr().err


def test_detect_command_names_a_bad_box_file_image_and_device(tmp_path, capfd):
    """A --rois value of another shape and a --device the machine lacks were internal errors (exit 1); a missing
    image printed OpenCV's warning before the error."""
    image = tmp_path / "a.png"
    cv2.imwrite(str(image), np.zeros((40, 40, 3), np.uint8))
    for value, field in (([0, 0, 9, 9], f"--rois['{image}']"), (None, f"--rois['{image}']"),
                         ([["a", 0, 9, 9]], f"--rois['{image}'][0]")):
        (tmp_path / "rois.json").write_text(json.dumps({str(image): value}))
        assert main(["detect", str(image), "--rois", str(tmp_path / "rois.json")]) == 2
        assert capfd.readouterr().err.startswith(f"error: {field}: expected")
    if not torch.cuda.is_available():
        assert main(["detect", str(image), "--roi", "0", "0", "9", "9", "--device", "cuda"]) == 2
        assert capfd.readouterr().err.startswith("error: device: 'cuda': this machine has no such device")
    assert main(["detect", str(image), "--roi", "0", "0", "9", "9", "--device", "foo"]) == 2
    assert capfd.readouterr().err.startswith("error: device: expected cpu, cuda")
    assert main(["detect", str(tmp_path / "missing.png"), "--roi", "0", "0", "5", "5"]) == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "cannot read" in err and "WARN" not in err


@pytest.mark.parametrize("command", ["calibrate-shape", "calibrate-bias"])
def test_calibrate_shape_and_bias_commands_report_bad_input(command, tmp_path, capsys):
    """The inputs the two commands share (their weights, seeds and scenario) named when bad, in one line."""
    assert main([command, "--weights", str(tmp_path / "none.pt")]) == 2
    assert "--weights" in capsys.readouterr().err
    assert main([command, "--seeds", "0"]) == 2
    assert "--seeds" in capsys.readouterr().err
    assert main([command, "--scenario", "no_such_scenario", "--seeds", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --scenario") and len(err.strip().splitlines()) == 1
