"""The stacked-hourglass keypoint network (Newell et al. 2016, as used by the paper).

Architecture (channels ``C``, input ``S x S``, heatmaps ``S/4 x S/4``):

* **Stem** (downsamples by 4): 7x7 convolution, stride 2, to ``C/2`` channels,
  batch norm, ReLU; a residual module; 2x2 max pooling; two residual modules
  to ``C`` channels. (Newell's stem widens to 128 channels at half resolution;
  ours stays at ``C/2`` there, which is most of the saving on a CPU.)
* **Hourglass** of ``depth`` levels (4 in the paper): at each level a residual
  branch at the current resolution (``up1``) and, after 2x2 max pooling, a
  residual module, the next level (or a residual module at the bottom) and a
  residual module, upsampled (nearest) back to the branch's size and added.
  Upsampling is to the branch's exact size, so input sizes whose heatmap side is
  not a power of two (e.g. 96 -> 24 -> 12 -> 6 -> 3 -> 1) work.
* **Residual modules** are pre-activation bottlenecks: BN-ReLU-1x1 (``C/2``),
  BN-ReLU-3x3 (``C/2``), BN-ReLU-1x1 (``C``), plus the identity (or a 1x1
  projection when the channel count changes).
* **Heads**, per stack: residual module, 1x1 conv-BN-ReLU, 1x1 conv to
  ``num_keypoints`` heatmaps (no output activation: trained on Gaussian targets
  in [0, 1]).
* **Intermediate supervision**: every stack's heatmaps are returned (and
  supervised); between stacks the features and the heatmaps, each mapped by a
  1x1 convolution, are added to the stack's input.

``forward`` returns a list of ``num_stacks`` tensors ``(B, num_keypoints, S/4,
S/4)``; the last one is the prediction.
"""

from __future__ import annotations

import hashlib
import json
import re
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
from torch import nn
from torch.nn import functional as F

from vfactor.errors import InputError
from vfactor.keypoints import NUM_KEYPOINTS

__all__ = [
    "torch_device",
    "ModelConfig",
    "Residual",
    "Hourglass",
    "StackedHourglass",
    "save_weights",
    "load_weights",
    "read_torch_file",
    "check_state_dict",
    "weights_digest",
    "default_weights_path",
    "count_parameters",
    "WeightsError",
    "WEIGHTS_FORMAT",
    "SHIPPED_WEIGHTS_SHA256",
]

#: Tag in the header of weight files written by :func:`save_weights`.
WEIGHTS_FORMAT = "vfactor-stacked-hourglass"
_WEIGHTS_VERSION = 1
#: :func:`weights_digest` of the shipped weights (:func:`default_weights_path`), checked on every load of
#: that file: update it (``weights_digest`` of the new file) when the shipped network is replaced.
SHIPPED_WEIGHTS_SHA256 = "cfd5e5a0bb527f6f0c65737f631821f434ef9e235d0ee0f1850e07c311fd7d95"
#: The stem downsamples by this factor: heatmaps are ``input_size / STRIDE`` pixels.
STRIDE = 4


@dataclass(frozen=True)
class ModelConfig:
    """Hyper-parameters of :class:`StackedHourglass` (all that is needed to rebuild it).

    Attributes:
        num_stacks: hourglasses in sequence (>= 1), each supervised.
        num_keypoints: heatmaps per crop (12 for vehicles, order of :mod:`vfactor.keypoints`).
        channels: feature channels ``C`` (even, >= 8); 64 runs comfortably on a CPU.
        depth: levels of each hourglass (4 in the paper).
        input_size: side ``S`` of the square input crop, pixels; a multiple of 4
            with ``S / 4 >= 2 ** depth`` (each level halves the resolution).
    """

    num_stacks: int = 2
    num_keypoints: int = NUM_KEYPOINTS
    channels: int = 64
    depth: int = 4
    input_size: int = 128

    def __post_init__(self):
        for name in ("num_stacks", "num_keypoints", "channels", "depth", "input_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected a positive integer, got {value!r}")
        if self.channels < 8 or self.channels % 2:
            raise ValueError(f"channels: expected an even integer >= 8, got {self.channels}")
        if self.input_size % STRIDE:
            raise ValueError(f"input_size: expected a multiple of {STRIDE}, got {self.input_size}")
        if self.heatmap_size < 2**self.depth:
            raise ValueError(
                f"input_size: {self.input_size} gives {self.heatmap_size}x{self.heatmap_size} heatmaps, too small "
                f"for an hourglass of depth {self.depth} (needs input_size >= {STRIDE * 2**self.depth})"
            )

    @property
    def heatmap_size(self) -> int:
        """Side of the output heatmaps, ``input_size / 4``."""
        return self.input_size // STRIDE

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "ModelConfig":
        """Builds a config from a dict; unknown keys raise ``ValueError`` naming them."""
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"model config: unknown keys {sorted(unknown)}; expected {sorted(cls.__dataclass_fields__)}")
        return cls(**data)


class Residual(nn.Module):
    """Pre-activation bottleneck residual module ``in_ch -> out_ch`` (same resolution)."""

    def __init__(self, in_ch: int, out_ch: int):
        super().__init__()
        mid = max(out_ch // 2, 1)
        self.bn1 = nn.BatchNorm2d(in_ch)
        self.conv1 = nn.Conv2d(in_ch, mid, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(mid)
        self.conv2 = nn.Conv2d(mid, mid, 3, padding=1, bias=False)
        self.bn3 = nn.BatchNorm2d(mid)
        self.conv3 = nn.Conv2d(mid, out_ch, 1)
        self.skip = nn.Identity() if in_ch == out_ch else nn.Conv2d(in_ch, out_ch, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.conv1(F.relu(self.bn1(x)))
        y = self.conv2(F.relu(self.bn2(y)))
        y = self.conv3(F.relu(self.bn3(y)))
        return y + self.skip(x)


class Hourglass(nn.Module):
    """One hourglass of ``depth`` levels with ``channels`` features throughout (recursive)."""

    def __init__(self, depth: int, channels: int):
        super().__init__()
        self.up1 = Residual(channels, channels)
        self.low1 = Residual(channels, channels)
        self.low2 = Hourglass(depth - 1, channels) if depth > 1 else Residual(channels, channels)
        self.low3 = Residual(channels, channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        up = self.up1(x)
        low = self.low3(self.low2(self.low1(F.max_pool2d(x, 2))))
        return up + F.interpolate(low, size=up.shape[-2:], mode="nearest")


class StackedHourglass(nn.Module):
    """Stacked hourglass: ``(B, 3, S, S)`` float crops -> list of ``(B, K, S/4, S/4)`` heatmaps, one per stack.

    Input: RGB crops scaled to [0, 1] (``uint8 / 255``); the network normalises
    them itself (subtracts 0.5), so callers need no statistics.

    Args:
        num_stacks, num_keypoints, channels, depth, input_size: see :class:`ModelConfig`.

    Example:
        >>> net = StackedHourglass(num_stacks=2, channels=32, input_size=64).eval()
        >>> [tuple(h.shape) for h in net(torch.zeros(1, 3, 64, 64))]
        [(1, 12, 16, 16), (1, 12, 16, 16)]
    """

    def __init__(
        self,
        num_stacks: int = 2,
        num_keypoints: int = NUM_KEYPOINTS,
        channels: int = 64,
        depth: int = 4,
        input_size: int = 128,
    ):
        super().__init__()
        self.config = ModelConfig(num_stacks, num_keypoints, channels, depth, input_size)
        C, half = channels, channels // 2
        self.stem = nn.Sequential(
            nn.Conv2d(3, half, 7, stride=2, padding=3, bias=False),
            nn.BatchNorm2d(half),
            nn.ReLU(inplace=True),
            Residual(half, half),
            nn.MaxPool2d(2),
            Residual(half, C),
            Residual(C, C),
        )
        self.hourglasses = nn.ModuleList(Hourglass(depth, C) for _ in range(num_stacks))
        self.features = nn.ModuleList(
            nn.Sequential(Residual(C, C), nn.Conv2d(C, C, 1, bias=False), nn.BatchNorm2d(C), nn.ReLU(inplace=True))
            for _ in range(num_stacks)
        )
        self.heads = nn.ModuleList(nn.Conv2d(C, num_keypoints, 1) for _ in range(num_stacks))
        self.merge_features = nn.ModuleList(nn.Conv2d(C, C, 1) for _ in range(num_stacks - 1))
        self.merge_heatmaps = nn.ModuleList(nn.Conv2d(num_keypoints, C, 1) for _ in range(num_stacks - 1))

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        S = self.config.input_size
        if x.ndim != 4 or x.shape[1] != 3 or x.shape[2] != S or x.shape[3] != S:
            raise ValueError(f"input: expected shape (B, 3, {S}, {S}), got {tuple(x.shape)}")
        x = self.stem(x - 0.5)
        outputs = []
        for i in range(self.config.num_stacks):
            feat = self.features[i](self.hourglasses[i](x))
            heat = self.heads[i](feat)
            outputs.append(heat)
            if i < self.config.num_stacks - 1:
                x = x + self.merge_features[i](feat) + self.merge_heatmaps[i](heat)
        return outputs


def torch_device(device=None) -> torch.device:
    """The torch device ``device`` names (None: CUDA when there is one, else the CPU), checked: a name torch does
    not know, or a device this machine does not have (CUDA or MPS without one), is a one-line error.

    Raises:
        InputError: (field ``device``) what is wrong.
    """
    if device is None:
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        chosen = torch.device(device)
    except (RuntimeError, TypeError) as exc:
        raise InputError("device", f"expected cpu, cuda, cuda:N or mps, got {device!r}") from None
    available = {"cpu": True, "cuda": torch.cuda.is_available(),
                 "mps": bool(getattr(torch.backends, "mps", None) and torch.backends.mps.is_available())}
    if not available.get(chosen.type, False):
        raise InputError("device", f"{device!r}: this machine has no such device for the network (cpu"
                                   + ", cuda" * available["cuda"] + ", mps" * available["mps"] + ")")
    if chosen.type == "cuda" and chosen.index is not None and chosen.index >= torch.cuda.device_count():
        raise InputError("device", f"{device!r}: this machine has {torch.cuda.device_count()} CUDA device(s)")
    return chosen


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


class WeightsError(InputError):
    """A weights or checkpoint file that cannot be used; ``field`` is the file's path.

    Raised for a missing, empty, truncated or non-torch file, one that holds
    pickled code (refused by ``torch.load(..., weights_only=True)``), one that is
    not a vfactor weights file, non-finite tensors, and tensors that do not
    match the file's (or the shipped weights') SHA-256 checksum. The message is
    one line; the commands report it under the option that gave the file
    (``--weights``, ``--resume``).
    """


def default_weights_path() -> Path:
    """Where the shipped weights live in the package (``vfactor/net/weights/keypoints.pt``); may be absent."""
    return Path(__file__).resolve().parent / "weights" / "keypoints.pt"


def weights_digest(state_dict: dict, model: dict | None = None) -> str:
    """SHA-256 (hex) of a network: its :class:`ModelConfig` dict and every tensor's name, dtype, shape and bytes.

    The free-form metadata (``config`` of :func:`save_weights`, e.g. the
    covariance calibration) is not covered, so that storing a calibration
    leaves the digest as it was.

    Args:
        state_dict: ``{name: tensor}``.
        model: the architecture (``ModelConfig.to_dict()``); None for none.
    """
    digest = hashlib.sha256(json.dumps(model, sort_keys=True).encode())
    for name in sorted(state_dict):
        tensor = state_dict[name].detach().to("cpu").contiguous().reshape(-1)
        digest.update(f"\0{name}\0{tensor.dtype}\0{tuple(state_dict[name].shape)}\0".encode())
        digest.update(tensor.view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def read_torch_file(path) -> object:
    """``torch.load(path, map_location="cpu", weights_only=True)`` with every failure a one-line :class:`WeightsError`.

    Only the zip archives that ``torch.save`` writes are read; no code is
    unpickled (a file that asks for any is refused, naming the object).

    Raises:
        WeightsError: missing, a folder, empty, unreadable, not a zip archive
            (a truncated file has no zip directory), or refused / failed by ``torch.load``.
    """
    path = Path(path)
    where = str(path)
    if not path.exists():
        raise WeightsError(where, "no such file")
    if path.is_dir():
        raise WeightsError(where, "is a folder, not a weights file")
    try:
        size = path.stat().st_size
        is_zip = zipfile.is_zipfile(path)
    except OSError as exc:
        raise WeightsError(where, f"cannot read it: {exc.strerror or exc}") from None
    if size == 0:
        raise WeightsError(where, "empty file")
    if not is_zip:
        raise WeightsError(where, f"not a torch.save archive ({size} bytes without a zip directory): truncated, "
                           "or not a weights file")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for a damaged archive; all are bad input
        text = str(exc)
        found = re.search(r"(?:Unsupported global|GLOBAL):?\s*(?:GLOBAL\s+)?([\w.]+)", text)
        if "weights only" in text.lower() or found:
            name = f" ({found.group(1)})" if found else ""
            raise WeightsError(where, f"refused: it holds pickled code or objects{name}, not only tensors and "
                               "plain values (read with torch.load(weights_only=True))") from None
        first = next((line.strip() for line in text.splitlines() if line.strip()), "")
        raise WeightsError(where, f"damaged torch.save archive ({type(exc).__name__}: {first[:200]})") from None


def check_state_dict(state_dict, where: str, sha256: str | None = None, model: dict | None = None) -> None:
    """Checks a loaded ``state_dict``: tensors only, all finite, and the checksum when one is given.

    Args:
        state_dict: what the file holds under ``state_dict``.
        where: the file, for the messages.
        sha256: the expected :func:`weights_digest` (the file's own, or the
            shipped weights'); None: not checked.
        model: the architecture dict the digest covers.

    Raises:
        WeightsError: not a dict of tensors, a non-finite value (naming the
            tensor and how many), or a checksum mismatch.
    """
    if not isinstance(state_dict, dict) or not all(
            isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state_dict.items()):
        raise WeightsError(where, "state_dict: expected a dict of named tensors")
    for name, tensor in state_dict.items():
        if tensor.is_floating_point() or tensor.is_complex():
            bad = int((~torch.isfinite(tensor)).sum())
            if bad:
                raise WeightsError(where, f"tensor {name!r} holds {bad} NaN or infinite value(s) of {tensor.numel()}")
    if sha256 is not None:
        actual = weights_digest(state_dict, model)
        if actual != sha256:
            raise WeightsError(where, f"the tensors do not match the SHA-256 checksum (expected {sha256[:16]}..., "
                               f"got {actual[:16]}...): the file is corrupted")


def save_weights(model: StackedHourglass, path, config: dict | None = None) -> Path:
    """Writes the model's weights with a small header (no pickled code).

    The file is a ``torch.save`` of a dict of plain types and tensors only::

        {"format": "vfactor-stacked-hourglass", "version": 1,
         "model": ModelConfig as a dict, "config": extra metadata (JSON-like),
         "sha256": weights_digest(state_dict, model), "state_dict": {name: tensor}}

    so :func:`load_weights` reads it with ``torch.load(..., weights_only=True)``
    and checks the tensors against the stored checksum.

    Args:
        model: the network (its :class:`ModelConfig` is stored).
        path: file to write (conventionally ``*.pt``); parent folders are created.
        config: extra metadata, e.g. the training config, the crop convention
            (``{"crop": {"square": True, "margin": 0.1}}``) or validation
            scores; must be JSON-like (dicts, lists, str, int, float, bool, None).

    Returns:
        The path written.
    """
    if not isinstance(model, StackedHourglass):
        raise TypeError(f"model: expected a StackedHourglass, got {type(model).__name__}")
    extra = dict(config or {})
    _check_plain(extra, "config")
    state = {k: v.detach().to("cpu").clone() for k, v in model.state_dict().items()}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    architecture = model.config.to_dict()
    payload = {
        "format": WEIGHTS_FORMAT,
        "version": _WEIGHTS_VERSION,
        "model": architecture,
        "config": extra,
        "sha256": weights_digest(state, architecture),
        "state_dict": state,
    }
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)
    return path


def load_weights(path, map_location="cpu", with_config: bool = False):
    """Rebuilds a :class:`StackedHourglass` from a file written by :func:`save_weights`.

    Loaded with ``torch.load(..., weights_only=True)`` (:func:`read_torch_file`):
    no code is unpickled. Every tensor must be finite and match the file's
    SHA-256 checksum (``sha256``; files written before it was stored have none)
    and, for the shipped weights, :data:`SHIPPED_WEIGHTS_SHA256`. The model is
    returned in ``eval()`` mode on ``map_location``.

    Args:
        path: weights file.
        map_location: device for the tensors (default CPU).
        with_config: also return the file's extra metadata dict.

    Returns:
        The model, or ``(model, config)`` when ``with_config``.

    Raises:
        WeightsError: (a ``ValueError``) an unreadable, damaged or refused file
            (:func:`read_torch_file`), not a vfactor weights file, an unknown
            version, a bad header, non-finite or corrupted tensors, or weights
            that do not fit the stored architecture.
    """
    where = str(path)
    payload = read_torch_file(path)
    if not isinstance(payload, dict) or payload.get("format") != WEIGHTS_FORMAT:
        raise WeightsError(where, f"not a vfactor keypoint-network weights file (format {WEIGHTS_FORMAT!r} expected)")
    if payload.get("version") != _WEIGHTS_VERSION:
        raise WeightsError(where, f"weights version {payload.get('version')!r}, expected {_WEIGHTS_VERSION}")
    architecture, extra, own = payload.get("model"), payload.get("config", {}), payload.get("sha256")
    if not isinstance(architecture, dict):
        raise WeightsError(where, "model: expected the architecture as a dict")
    if not isinstance(extra, dict) or not (own is None or isinstance(own, str)):
        raise WeightsError(where, "config: expected a dict, sha256: a hex string")
    try:
        config = ModelConfig.from_dict(architecture)
    except (TypeError, ValueError) as exc:
        raise WeightsError(where, f"model: {exc}") from None
    state = payload.get("state_dict")
    check_state_dict(state, where, own, architecture)
    if Path(path).resolve() == default_weights_path():
        check_state_dict(state, f"{where} (the shipped weights)", SHIPPED_WEIGHTS_SHA256, architecture)
    model = StackedHourglass(**config.to_dict())
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        first = str(exc).splitlines()[0] if str(exc) else ""
        raise WeightsError(where, f"weights do not fit the stored architecture: {first}") from None
    model.to(map_location).eval()
    if with_config:
        return model, dict(extra)
    return model


def _check_plain(value, where: str) -> None:
    """Raises ``TypeError`` unless ``value`` is made of JSON-like plain types."""
    if value is None or isinstance(value, (str, bool, int, float)):
        return
    if isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _check_plain(v, f"{where}[{i}]")
        return
    if isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, str):
                raise TypeError(f"{where}: keys must be strings, got {k!r}")
            _check_plain(v, f"{where}.{k}")
        return
    raise TypeError(f"{where}: expected JSON-like plain values, got {type(value).__name__}")
