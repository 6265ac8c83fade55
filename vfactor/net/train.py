"""Training of the stacked-hourglass keypoint network: seeded, checkpointed, resumable, validated per epoch.

``train(config, dataset, val_dataset, out_dir)`` fits a
:class:`vfactor.net.model.StackedHourglass` to Gaussian heatmap targets
(:mod:`vfactor.net.targets`) with a weighted MSE summed over every stack
(intermediate supervision), Adam or RMSprop, a cosine learning-rate decay and
random augmentation (:mod:`vfactor.net.data`). After each epoch it scores the
validation set (PCK@0.1 of the crop size, visible and self-occluded keypoints
apart, :mod:`vfactor.net.evaluate`), writes a checkpoint (model, optimiser,
epoch, history, random states) and ``history.json``; at the end the weights
(``weights.pt``, and ``weights_best.pt`` by validation PCK).

Determinism: the model is initialised after ``torch.manual_seed(seed)``; the
order of each epoch comes from a generator seeded by ``(seed, epoch)`` and the
augmentation of each sample from ``(seed, epoch, index)``; deterministic
algorithms are switched on for the run (and restored after). On one machine
and device, the same config and data give the same weights, and training
resumed from a checkpoint gives the same weights as training straight through.
"""

from __future__ import annotations

import json
import logging
import math
import os
import random
import sys
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from vfactor.errors import check_numbers
from vfactor.net.data import AugmentConfig, KeypointDataset, as_dataset, augment, sample_rng
from vfactor.net.evaluate import decode_batch, score_predictions
from vfactor.net.model import (
    StackedHourglass, WeightsError, check_state_dict, count_parameters, load_weights, read_torch_file, save_weights,
    torch_device, weights_digest)
from vfactor.net.targets import heatmap_targets, keypoint_weights
from vfactor.progress import Progress

__all__ = ["TrainConfig", "TrainResult", "train", "heatmap_loss", "latest_checkpoint", "evaluate_model"]

log = logging.getLogger("vfactor.net.train")

_CHECKPOINT_FORMAT = "vfactor-train-checkpoint"
#: Config fields that may change between a run and its resumption.
_RESUMABLE_CHANGES = {"epochs", "num_workers", "keep_checkpoints", "num_threads"}


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run (the defaults make the shipped weights).

    Model: ``num_stacks``, ``channels``, ``depth``, ``input_size`` (see
    :class:`vfactor.net.model.ModelConfig`).

    Optimisation: ``epochs``; ``batch_size``; ``optimizer`` ("adam" or
    "rmsprop"); ``lr``; ``weight_decay``; ``lr_schedule`` ("cosine": from ``lr``
    down to ``lr * min_lr_factor`` over the epochs, or "constant").

    Targets: ``sigma`` (Gaussian std, heatmap pixels); ``self_occluded_weight``
    (loss weight of self-occluded keypoints, 1 as in the paper).

    Data: ``augment`` (:class:`vfactor.net.data.AugmentConfig`, or a dict);
    ``num_workers`` of the data loader (0: in the main process).

    Validation: ``pck_alpha`` (0.1: within 10% of the crop side);
    ``min_confidence`` of the decoder.

    Inference crop convention, stored with the weights for
    :class:`vfactor.net.infer.KeypointDetector`: a detector box is made square
    when ``roi_square`` and grown by ``roi_margin`` (fraction per side), to
    frame the vehicle as the training crops do (the renderer's crops: square,
    margin 0.1-0.3 of the box's larger side, so 0.2 and True).

    Housekeeping: ``seed``; ``keep_checkpoints`` (the newest N epoch
    checkpoints are kept); ``num_threads`` (torch CPU threads for the run; None:
    torch's default).
    """

    seed: int = 0
    epochs: int = 20
    batch_size: int = 16
    optimizer: str = "adam"
    lr: float = 2e-3
    weight_decay: float = 0.0
    lr_schedule: str = "cosine"
    min_lr_factor: float = 0.05
    num_stacks: int = 2
    channels: int = 64
    depth: int = 4
    input_size: int = 96
    sigma: float = 2.0
    self_occluded_weight: float = 1.0
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    num_workers: int = 0
    pck_alpha: float = 0.1
    min_confidence: float = 0.05
    roi_margin: float = 0.2
    roi_square: bool = True
    keep_checkpoints: int = 2
    num_threads: int | None = None

    def __post_init__(self):
        if isinstance(self.augment, dict):
            object.__setattr__(self, "augment", AugmentConfig(**_only_known(self.augment, AugmentConfig, "augment")))
        for name in ("seed", "num_workers"):
            _check_int(name, getattr(self, name), 0)
        for name in ("epochs", "batch_size", "keep_checkpoints"):
            _check_int(name, getattr(self, name), 1)
        if self.num_threads is not None:
            _check_int("num_threads", self.num_threads, 1)
        check_numbers("TrainConfig", self, ("lr", "sigma", "pck_alpha"))
        check_numbers("TrainConfig", self,
                      ("weight_decay", "self_occluded_weight", "min_confidence", "roi_margin", "min_lr_factor"),
                      strict=False)
        if self.optimizer not in ("adam", "rmsprop"):
            raise ValueError(f"optimizer: expected 'adam' or 'rmsprop', got {self.optimizer!r}")
        if self.lr_schedule not in ("cosine", "constant"):
            raise ValueError(f"lr_schedule: expected 'cosine' or 'constant', got {self.lr_schedule!r}")
        self.model_kwargs()  # validates the architecture (ValueError naming the field)

    def model_kwargs(self) -> dict:
        from vfactor.net.model import ModelConfig  # noqa: PLC0415

        return ModelConfig(self.num_stacks, 12, self.channels, self.depth, self.input_size).to_dict()

    def to_dict(self) -> dict:
        d = asdict(self)
        d["augment"] = asdict(self.augment)
        return d

    @classmethod
    def from_dict(cls, data: dict) -> "TrainConfig":
        """Builds a config from a dict (e.g. JSON); unknown keys raise ``ValueError`` naming them."""
        return cls(**_only_known(data, cls, "train config"))

    def lr_at(self, epoch: int) -> float:
        """Learning rate of 0-based ``epoch``."""
        if self.lr_schedule == "constant" or self.epochs == 1:
            return self.lr
        t = epoch / (self.epochs - 1)
        return self.lr * (self.min_lr_factor + (1 - self.min_lr_factor) * 0.5 * (1 + math.cos(math.pi * t)))


@dataclass
class TrainResult:
    """What :func:`train` returns.

    Attributes:
        model: the trained network (eval mode, on the training device).
        history: one dict per epoch: ``epoch`` (1-based), ``train_loss``,
            ``val_loss``, ``pck_visible``, ``pck_self_occluded``, ``pck_all``,
            ``n_visible``, ``n_self_occluded``, ``lr``, ``seconds`` (NaN / 0
            without a validation set).
        weights_path: the final weights (:func:`vfactor.net.model.load_weights`).
        best_weights_path: the weights of the epoch with the best validation
            PCK (visible + self-occluded), or None without a validation set.
        out_dir: the run's folder (checkpoints/, history.json, weights).
    """

    model: StackedHourglass
    history: list[dict]
    weights_path: Path
    best_weights_path: Path | None
    out_dir: Path


def heatmap_loss(outputs: list[torch.Tensor], target: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Weighted MSE summed over the stacks (intermediate supervision).

    ``sum_s mean_{b,k,y,x} w[b,k] (outputs[s] - target)^2`` with ``target``
    (B, K, h, w) and ``weight`` (B, K).
    """
    w = weight[:, :, None, None]
    return sum(((out - target) ** 2 * w).mean() for out in outputs)


def train(
    config: TrainConfig,
    dataset,
    val_dataset=None,
    out_dir="runs/keypoints",
    resume: bool = False,
    progress: bool = True,
    device: str | torch.device | None = None,
    init_weights: str | Path | None = None,
) -> TrainResult:
    """Trains the keypoint network; see the module docstring.

    Args:
        config: the run's :class:`TrainConfig`.
        dataset: training data: a :class:`vfactor.net.data.KeypointDataset`,
            ``Sample`` records, arrays, or ``.npz`` shard paths
            (:func:`vfactor.net.data.as_dataset`). Crops of another size than
            ``config.input_size`` are resized once.
        val_dataset: validation data in the same forms, or None.
        out_dir: folder for checkpoints, ``history.json`` and the weights.
        resume: continue from the newest checkpoint in ``out_dir`` (its config
            must match, but for ``epochs``, ``num_workers``, ``keep_checkpoints``
            and ``num_threads``); starts afresh when there is none.
        progress: show a progress bar and a line per epoch on stderr.
        device: "cuda", "cpu", ...; None: CUDA when available, else the CPU.
        init_weights: a weights file (:func:`vfactor.net.model.load_weights`) to start from instead of random
            weights, to fine-tune a trained network on other data; its architecture must be ``config``'s.
            Ignored when resuming from a checkpoint.

    Returns:
        :class:`TrainResult`.

    Raises:
        ValueError: ``init_weights`` of another architecture than ``config``'s (or a damaged file:
            :class:`vfactor.net.model.WeightsError`).
    """
    if not isinstance(config, TrainConfig):
        raise TypeError(f"config: expected a TrainConfig, got {type(config).__name__}")
    S = config.input_size
    train_set = as_dataset(dataset, size=S).resized(S)
    val_set = as_dataset(val_dataset, size=S).resized(S) if val_dataset is not None else None
    if len(train_set) < 2:
        raise ValueError(f"dataset: expected at least 2 samples, got {len(train_set)}")
    if train_set.num_keypoints != 12:
        raise ValueError(f"dataset: expected 12 keypoints per sample, got {train_set.num_keypoints}")
    device = torch_device(device)
    out = Path(out_dir)
    ckpt_dir = out / "checkpoints"
    ckpt_dir.mkdir(parents=True, exist_ok=True)

    with _deterministic(config.num_threads):
        torch.manual_seed(config.seed)
        random.seed(config.seed)
        np_rng = np.random.default_rng(config.seed)
        model = StackedHourglass(**config.model_kwargs())
        if init_weights is not None:
            _start_from(model, init_weights, config)
        model.to(device)
        optimizer = _make_optimizer(config, model)
        history: list[dict] = []
        start_epoch = 0
        best_score, best_path = -math.inf, None

        ckpt = latest_checkpoint(out) if resume else None
        if ckpt is not None:
            start_epoch, history = _restore(ckpt, config, model, optimizer, np_rng, device)
            best_path = out / "weights_best.pt" if (out / "weights_best.pt").exists() else None
            best_score = max((_score(h) for h in history), default=-math.inf)
            log.info("resumed from %s (epoch %d)", ckpt, start_epoch)
            if progress:
                _say(f"resumed from {ckpt.name} after epoch {start_epoch}")
        else:
            if resume:
                log.info("no checkpoint in %s: training from scratch", ckpt_dir)
            for stale in ckpt_dir.glob("epoch_*.pt"):
                stale.unlink()
        if progress and start_epoch == 0:
            _say(f"training {count_parameters(model):,} parameters on {device} for {config.epochs} epochs, "
                 f"{len(train_set)} samples ({S}x{S})" + (f", validating on {len(val_set)}" if val_set else ""))

        view = _TrainingView(train_set, config)
        for epoch in range(start_epoch, config.epochs):
            t0 = time.perf_counter()
            lr = config.lr_at(epoch)
            for group in optimizer.param_groups:
                group["lr"] = lr
            train_loss = _train_epoch(model, optimizer, view, config, epoch, device, progress)
            record: dict[str, Any] = {"epoch": epoch + 1, "train_loss": train_loss, "lr": lr}
            if val_set is not None:
                record.update(evaluate_model(model, val_set, config, device))
            else:
                record.update(val_loss=math.nan, pck_visible=math.nan, pck_self_occluded=math.nan, pck_all=math.nan,
                              n_visible=0, n_self_occluded=0)
            record["seconds"] = time.perf_counter() - t0
            history.append(record)
            log.info("epoch %d: %s", epoch + 1, _format_record(record, config.pck_alpha))
            if progress:
                _say(f"epoch {epoch + 1}/{config.epochs}: {_format_record(record, config.pck_alpha)}")
            if val_set is not None and _score(record) > best_score:
                best_score = _score(record)
                best_path = save_weights(model, out / "weights_best.pt", _weights_meta(config, record))
            _save_checkpoint(ckpt_dir / f"epoch_{epoch + 1:03d}.pt", config, model, optimizer, epoch + 1, history,
                             np_rng)
            _prune(ckpt_dir, config.keep_checkpoints)
            _write_history(out / "history.json", history)

        model.eval()
        final = history[-1] if history else {}
        weights_path = save_weights(model, out / "weights.pt", _weights_meta(config, final))
        _write_history(out / "history.json", history)
    return TrainResult(model, history, weights_path, best_path, out)


def _start_from(model: StackedHourglass, path, config: TrainConfig) -> None:
    """Copies the weights of ``path`` into ``model`` (fine-tuning); the architectures must match."""
    trained = load_weights(path)
    if trained.config.to_dict() != model.config.to_dict():
        raise ValueError(f"init_weights: {path} holds a network of another architecture ({trained.config.to_dict()}) "
                         f"than the config's ({model.config.to_dict()})")
    model.load_state_dict(trained.state_dict())


def evaluate_model(model: StackedHourglass, dataset, config: TrainConfig | None = None, device=None,
                   batch_size: int = 64) -> dict:
    """Validation loss and PCK (see :mod:`vfactor.net.evaluate`) of a model on un-augmented crops.

    Returns:
        dict with ``val_loss``, ``pck_visible``, ``pck_self_occluded``,
        ``pck_all``, ``n_visible``, ``n_self_occluded``.
    """
    config = config or TrainConfig(**{k: v for k, v in model.config.to_dict().items() if k != "num_keypoints"})
    S = model.config.input_size
    ds = as_dataset(dataset, size=S).resized(S)
    device = torch_device(device) if device is not None else next(model.parameters()).device
    h = model.config.heatmap_size
    was_training = model.training
    model.eval()
    preds, loss_sum = [], 0.0
    with torch.no_grad():
        for i in range(0, len(ds), batch_size):
            sl = slice(i, i + batch_size)
            images = torch.from_numpy(ds.images[sl]).permute(0, 3, 1, 2).float().div(255.0)
            targets = np.stack([heatmap_targets(k, S, h, config.sigma) for k in ds.keypoints[sl]])
            weights = np.stack([keypoint_weights(k, S, o & ~v, config.self_occluded_weight)
                                for k, v, o in zip(ds.keypoints[sl], ds.visible[sl], ds.self_occluded[sl])])
            outputs = model(images.to(device))
            loss = heatmap_loss(outputs, torch.from_numpy(targets).to(device), torch.from_numpy(weights).to(device))
            loss_sum += float(loss) * len(images)
            preds.append(decode_batch(outputs[-1].float().cpu().numpy(), S, config.min_confidence))
    model.train(was_training)
    pred = np.concatenate(preds)
    scores = score_predictions(pred, ds.keypoints, ds.visible, ds.self_occluded, S, config.pck_alpha)
    return {
        "val_loss": loss_sum / len(ds),
        "pck_visible": scores.pck_visible,
        "pck_self_occluded": scores.pck_self_occluded,
        "pck_all": scores.pck_all,
        "n_visible": scores.n_visible,
        "n_self_occluded": scores.n_self_occluded,
    }


def latest_checkpoint(out_dir) -> Path | None:
    """The newest ``checkpoints/epoch_NNN.pt`` of a run folder, or None."""
    files = sorted(Path(out_dir, "checkpoints").glob("epoch_*.pt"))
    return files[-1] if files else None


# ----------------------------------------------------------------- internals
class _TrainingView(Dataset):
    """Augmented crops, heatmap targets and weights for one epoch (set ``epoch`` before iterating)."""

    def __init__(self, data: KeypointDataset, config: TrainConfig):
        self.data, self.config, self.epoch = data, config, 0
        self.heatmap_size = config.input_size // 4

    def __len__(self) -> int:
        return len(self.data)

    def __getitem__(self, i: int):
        c, d = self.config, self.data
        rng = sample_rng(c.seed, self.epoch, i)
        img, kp, vis, occ = augment(d.images[i], d.keypoints[i], d.visible[i], d.self_occluded[i], rng, c.augment)
        target = heatmap_targets(kp, c.input_size, self.heatmap_size, c.sigma)
        weight = keypoint_weights(kp, c.input_size, occ & ~vis, c.self_occluded_weight)
        return torch.from_numpy(np.ascontiguousarray(img.transpose(2, 0, 1))), torch.from_numpy(target), \
            torch.from_numpy(weight)


def _train_epoch(model, optimizer, view: _TrainingView, config: TrainConfig, epoch: int, device, progress: bool):
    view.epoch = epoch
    n = len(view)
    generator = torch.Generator().manual_seed(_epoch_seed(config.seed, epoch))
    loader = DataLoader(
        view, batch_size=config.batch_size, shuffle=True, generator=generator, num_workers=config.num_workers,
        worker_init_fn=_seed_worker, drop_last=(n % config.batch_size == 1),  # BatchNorm needs 2+ per batch
        persistent_workers=False,
    )
    model.train()
    bar = Progress(len(loader), f"epoch {epoch + 1}/{config.epochs}", enabled=progress)
    total, count = 0.0, 0
    for images, target, weight in loader:
        images, target, weight = images.to(device), target.to(device), weight.to(device)
        loss = heatmap_loss(model(images), target, weight)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        total += loss.item() * len(images)
        count += len(images)
        bar.update(1, loss=total / count)
    bar.close()
    return total / max(count, 1)


def _make_optimizer(config: TrainConfig, model) -> torch.optim.Optimizer:
    if config.optimizer == "adam":
        return torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    return torch.optim.RMSprop(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)


def _epoch_seed(seed: int, epoch: int) -> int:
    return int(np.random.SeedSequence([int(seed), int(epoch), 7]).generate_state(1, dtype=np.uint64)[0] >> 1)


def _seed_worker(worker_id: int) -> None:
    """Seeds numpy and random in a data-loader worker from torch's per-worker seed."""
    s = torch.initial_seed() % 2**32
    np.random.seed(s)
    random.seed(s)


@contextmanager
def _deterministic(num_threads: int | None):
    """Deterministic algorithms (and optionally a thread count) for the block, restored after."""
    prev = (torch.are_deterministic_algorithms_enabled(), torch.is_deterministic_algorithms_warn_only_enabled(),
            torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark, torch.get_num_threads())
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.use_deterministic_algorithms(True, warn_only=True)
    torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark = True, False
    if num_threads is not None:
        torch.set_num_threads(num_threads)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(prev[0], warn_only=prev[1])
        torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark = prev[2], prev[3]
        torch.set_num_threads(prev[4])


def _rng_states(np_rng) -> dict:
    states = {"torch": torch.get_rng_state(), "numpy": np_rng.bit_generator.state, "python": random.getstate()}
    if torch.cuda.is_available():
        states["cuda"] = torch.cuda.get_rng_state_all()
    return states


def _save_checkpoint(path: Path, config, model, optimizer, epoch: int, history, np_rng) -> None:
    payload = {
        "format": _CHECKPOINT_FORMAT,
        "version": 1,
        "epoch": epoch,
        "config": config.to_dict(),
        "state_dict": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "history": [_plain(h) for h in history],
        "rng": _rng_states(np_rng),
    }
    payload["sha256"] = weights_digest(_checkpoint_tensors(payload, path))
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)


def _restore(path: Path, config: TrainConfig, model, optimizer, np_rng, device) -> tuple[int, list[dict]]:
    payload = read_torch_file(path)  # a damaged checkpoint raises WeightsError
    if not isinstance(payload, dict) or payload.get("format") != _CHECKPOINT_FORMAT:
        raise WeightsError(str(path), "not a vfactor training checkpoint")
    check_state_dict(_checkpoint_tensors(payload, path), str(path), payload.get("sha256"))
    stored = payload["config"]
    current = config.to_dict()
    changed = sorted(k for k in set(stored) | set(current)
                     if k not in _RESUMABLE_CHANGES and stored.get(k) != current.get(k))
    if changed:
        raise ValueError(f"resume: the config differs from the checkpoint's in {changed} "
                         f"(checkpoint: {[stored.get(k) for k in changed]}, now: {[current.get(k) for k in changed]})")
    model.load_state_dict(payload["state_dict"])
    optimizer.load_state_dict(payload["optimizer"])
    rng = payload["rng"]
    torch.set_rng_state(rng["torch"])
    np_rng.bit_generator.state = rng["numpy"]
    random.setstate(_as_tuple(rng["python"]))
    if "cuda" in rng and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(rng["cuda"])
    return int(payload["epoch"]), [dict(h) for h in payload["history"]]


def _checkpoint_tensors(payload: dict, path: Path) -> dict:
    """Every tensor of a checkpoint (model, optimiser state, random states), by its path in the payload.

    What the checkpoint's checksum covers.
    """
    if not isinstance(payload.get("state_dict"), dict) or not isinstance(payload.get("optimizer"), dict):
        raise WeightsError(str(path), "not a vfactor training checkpoint (no state_dict and optimizer)")
    tensors: dict = {}

    def walk(value, where: str) -> None:
        if isinstance(value, torch.Tensor):
            tensors[where] = value
        elif isinstance(value, dict):
            for key, item in value.items():
                walk(item, f"{where}.{key}")
        elif isinstance(value, (list, tuple)):
            for i, item in enumerate(value):
                walk(item, f"{where}[{i}]")

    for key in ("state_dict", "optimizer", "rng"):
        walk(payload.get(key), key)
    return tensors


def _as_tuple(x):
    return tuple(_as_tuple(v) for v in x) if isinstance(x, (list, tuple)) else x


def _prune(ckpt_dir: Path, keep: int) -> None:
    files = sorted(ckpt_dir.glob("epoch_*.pt"))
    for f in files[:-keep]:
        f.unlink()


def _score(record: dict) -> float:
    vals = [record.get("pck_visible", math.nan), record.get("pck_self_occluded", math.nan)]
    vals = [v for v in vals if isinstance(v, float) and math.isfinite(v)]
    return sum(vals) if vals else -math.inf


def _weights_meta(config: TrainConfig, record: dict) -> dict:
    return {
        "train": config.to_dict(),
        "sigma": config.sigma,
        "crop": {"margin": config.roi_margin, "square": config.roi_square},
        "min_confidence": config.min_confidence,
        "scores": _plain(record, nan_to_none=True),
    }


def _plain(d: dict, nan_to_none: bool = False) -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, (np.floating, float)):
            v = float(v)
            if nan_to_none and not math.isfinite(v):
                v = None
        elif isinstance(v, np.integer):
            v = int(v)
        out[k] = v
    return out


def _write_history(path: Path, history: list[dict]) -> None:
    path.write_text(json.dumps([_plain(h, nan_to_none=True) for h in history], indent=1) + "\n", encoding="utf-8")


def _format_record(r: dict, alpha: float) -> str:
    parts = [f"loss {r['train_loss']:.3e}"]
    if math.isfinite(r.get("val_loss", math.nan)):
        parts.append(f"val loss {r['val_loss']:.3e}")
        parts.append(f"PCK@{alpha:g} visible {r['pck_visible']:.3f} (n={r['n_visible']}) "
                     f"self-occluded {r['pck_self_occluded']:.3f} (n={r['n_self_occluded']})")
    parts.append(f"lr {r['lr']:.2e}")
    if "seconds" in r:
        parts.append(f"{r['seconds']:.0f} s")
    return ", ".join(parts)


def _say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _check_int(name: str, value, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {value!r}")


def _only_known(data: dict, cls, what: str) -> dict:
    if not isinstance(data, dict):
        raise TypeError(f"{what}: expected a dict, got {type(data).__name__}")
    known = {f.name for f in fields(cls)}
    unknown = set(data) - known
    if unknown:
        raise ValueError(f"{what}: unknown keys {sorted(unknown)}; expected some of {sorted(known)}")
    return dict(data)
