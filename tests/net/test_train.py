"""Training: a tiny run on blob images whose loss falls; checkpoints, resume and determinism; config checks."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from tests.net.synthetic import blob_dataset  # noqa: E402
from vfactor.net.data import KeypointDataset  # noqa: E402
from vfactor.net.model import load_weights  # noqa: E402
from vfactor.net.train import TrainConfig, evaluate_model, heatmap_loss, latest_checkpoint, train  # noqa: E402

TINY = dict(num_stacks=2, channels=16, depth=3, input_size=32, batch_size=16, lr=3e-3, sigma=1.0, num_threads=1)


@pytest.fixture(scope="module")
def blobs():
    return KeypointDataset(*blob_dataset(64, 32, seed=0)), KeypointDataset(*blob_dataset(16, 32, seed=1))


def test_tiny_training_run_loss_falls(blobs, tmp_path):
    data, val = blobs
    result = train(TrainConfig(epochs=3, **TINY), data, val, out_dir=tmp_path, progress=False)
    losses = [h["train_loss"] for h in result.history]
    assert [h["epoch"] for h in result.history] == [1, 2, 3]
    assert losses[0] > losses[1] > losses[2] and losses[2] < 0.75 * losses[0], losses
    last = result.history[-1]
    for key in ("val_loss", "pck_visible", "pck_self_occluded", "pck_all"):
        assert math.isfinite(last[key])
    assert last["n_visible"] > 0 and last["n_self_occluded"] > 0
    logged = json.loads((tmp_path / "history.json").read_text())
    assert [h["epoch"] for h in logged] == [1, 2, 3]
    assert result.best_weights_path is not None and result.best_weights_path.exists()
    model, meta = load_weights(result.weights_path, with_config=True)
    assert meta["train"]["epochs"] == 3 and meta["scores"]["epoch"] == 3
    for a, b in zip(model.state_dict().values(), result.model.state_dict().values()):
        assert torch.equal(a, b.cpu())


def test_resume_gives_the_same_weights_as_training_straight_through(blobs, tmp_path):
    data, val = blobs
    straight = train(TrainConfig(epochs=2, **TINY), data, val, out_dir=tmp_path / "a", progress=False)
    train(TrainConfig(epochs=1, **TINY), data, val, out_dir=tmp_path / "b", progress=False)
    assert latest_checkpoint(tmp_path / "b").name == "epoch_001.pt"
    resumed = train(TrainConfig(epochs=2, **TINY), data, val, out_dir=tmp_path / "b", resume=True, progress=False)
    for (name, a), b in zip(straight.model.state_dict().items(), resumed.model.state_dict().values()):
        assert torch.equal(a, b), name
    strip = lambda hs: [{k: v for k, v in h.items() if k != "seconds"} for h in hs]  # noqa: E731
    assert strip(straight.history) == strip(resumed.history)
    ckpt = torch.load(latest_checkpoint(tmp_path / "b"), weights_only=True)
    assert ckpt["epoch"] == 2 and set(ckpt["rng"]) >= {"torch", "numpy", "python"} and "optimizer" in ckpt


def test_checkpoints_are_pruned_to_the_newest(blobs, tmp_path):
    data, _ = blobs
    train(TrainConfig(epochs=3, keep_checkpoints=2, **TINY), data.subset(range(16)), out_dir=tmp_path,
          progress=False)
    assert sorted(p.name for p in (tmp_path / "checkpoints").glob("*.pt")) == ["epoch_002.pt", "epoch_003.pt"]


def test_resume_refuses_a_different_config(blobs, tmp_path):
    data, _ = blobs
    small = data.subset(range(16))
    train(TrainConfig(epochs=1, **TINY), small, out_dir=tmp_path, progress=False)
    with pytest.raises(ValueError, match="lr"):
        train(TrainConfig(epochs=2, **{**TINY, "lr": 1e-3}), small, out_dir=tmp_path, resume=True, progress=False)


def test_progress_bar_and_epoch_lines(blobs, tmp_path, capsys):
    data, val = blobs
    train(TrainConfig(epochs=1, **TINY), data.subset(range(32)), val, out_dir=tmp_path, progress=True)
    err = capsys.readouterr().err
    assert "epoch 1/1 [" in err and "PCK" in err


def test_config_from_dict_names_unknown_keys():
    cfg = TrainConfig.from_dict({"epochs": 2, "augment": {"flip": 0.0}})
    assert cfg.epochs == 2 and cfg.augment.flip == 0.0
    assert TrainConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="epoch_count"):
        TrainConfig.from_dict({"epoch_count": 2})
    with pytest.raises(ValueError, match="optimizer"):
        TrainConfig(optimizer="sgd")
    with pytest.raises(ValueError, match="input_size"):
        TrainConfig(input_size=50)


def test_loss_weights_each_keypoint_and_sums_the_stacks():
    target = torch.zeros(1, 2, 4, 4)
    out = torch.ones(1, 2, 4, 4)
    weight = torch.tensor([[1.0, 0.0]])
    assert heatmap_loss([out], target, weight).item() == pytest.approx(0.5)
    assert heatmap_loss([out, out], target, weight).item() == pytest.approx(1.0)


def test_evaluate_a_model_that_outputs_the_truth():
    """PCK is 1 when the heatmaps are the targets themselves (decoding and scoring agree)."""
    from vfactor.net.model import StackedHourglass
    from vfactor.net.targets import heatmap_targets

    images, kp, vis, occ = blob_dataset(8, 32, seed=2)
    images[:, 0, 0, 0] = np.arange(8)  # tells the oracle which sample it sees

    class Oracle(StackedHourglass):
        def forward(self, x):
            idx = torch.round(x[:, 0, 0, 0] * 255).long().tolist()
            return [torch.from_numpy(np.stack([heatmap_targets(kp[i], 32, 8) for i in idx]))]

    net = Oracle(num_stacks=1, channels=8, depth=2, input_size=32)
    scores = evaluate_model(net, KeypointDataset(images, kp, vis, occ))
    assert scores["pck_visible"] == 1.0 and scores["pck_self_occluded"] == 1.0
    assert scores["n_visible"] == int(vis.sum())


def test_fine_tuning_starts_from_the_given_weights(blobs, tmp_path):
    data, val = blobs
    first = train(TrainConfig(epochs=2, **TINY), data, val, out_dir=tmp_path / "a", progress=False)
    # one epoch at a tiny learning rate stays near the start (the batch-norm statistics still move a little)
    tuned = train(TrainConfig(epochs=1, **{**TINY, "lr": 1e-7}), data, val, out_dir=tmp_path / "b", progress=False,
                  init_weights=first.weights_path)
    fresh = train(TrainConfig(epochs=1, **{**TINY, "lr": 1e-7}), data, val, out_dir=tmp_path / "c", progress=False)
    assert tuned.history[0]["val_loss"] < 0.9 * fresh.history[0]["val_loss"]
    assert abs(tuned.history[0]["val_loss"] - first.history[-1]["val_loss"]) < 0.05 * first.history[-1]["val_loss"]
    other = {**TINY, "channels": 8}
    with pytest.raises(ValueError, match="init_weights.*architecture"):
        train(TrainConfig(epochs=1, **other), data, out_dir=tmp_path / "d", progress=False,
              init_weights=first.weights_path)
