"""Keypoint training data in memory, from rendered samples, arrays or ``.npz`` shards, and its augmentation.

A training sample is a square crop around one vehicle with its 12 keypoints
(crop pixels, OpenCV centre convention, fixed order of :mod:`vfactor.keypoints`),
which of them are visible and which are self-occluded. The renderer
(:mod:`vfactor.render`) and the PASCAL3D+ loader (:mod:`vfactor.net.pascal3d`)
both produce :class:`Sample` records with these fields; :class:`KeypointDataset`
stacks them into arrays.

Augmentation (:func:`augment`) is numpy/OpenCV, driven by a generator seeded
from ``(seed, epoch, index)``, so a sample's augmentation does not depend on the
order, the batch or the data-loader worker that draws it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import cv2
import numpy as np

from vfactor.errors import check_numbers
from vfactor.keypoints import MIRROR_PERMUTATION, NUM_KEYPOINTS
from vfactor.net.crop import crop_roi, image_to_crop

__all__ = ["Sample", "KeypointDataset", "AugmentConfig", "augment", "sample_rng"]


@dataclass
class Sample:
    """One training crop: the fields of :class:`vfactor.render.Sample` that training reads.

    The renderer's samples carry more (cameras, wireframe, pose); training only
    reads ``image``, ``keypoints``, ``visible`` and ``self_occluded``, so either
    record works wherever samples are accepted. The PASCAL3D+ loader yields these.

    Attributes:
        image: (S, S, 3) uint8 RGB crop.
        keypoints: (12, 2) keypoints ``(u, v)`` in crop pixels; NaN where not annotated.
        visible: (12,) bool, inside the crop and hidden by nothing.
        self_occluded: (12,) bool, hidden by the vehicle's own body (still annotated).
        roi: ``(x0, y0, x1, y1)`` box of the source image the crop covers (pixel edges).
        meta: anything else (source file, object index...).
        occluded_by_other: (12,) bool, hidden by another object; None if unknown.
        in_crop: (12,) bool, annotated and inside the crop; None if not computed.
    """

    image: np.ndarray
    keypoints: np.ndarray
    visible: np.ndarray
    self_occluded: np.ndarray
    roi: tuple = (0.0, 0.0, 0.0, 0.0)
    meta: dict = field(default_factory=dict)
    occluded_by_other: np.ndarray | None = None
    in_crop: np.ndarray | None = None


class KeypointDataset:
    """Crops and annotations held as arrays (the whole set in memory: 128x128 crops take 49 kB each).

    The constructor takes the attributes below; ``visible`` defaults to all
    True, ``self_occluded`` to all False, ``rois`` to None. Wrong shapes (and
    non-finite ``rois``) raise ``ValueError`` naming the argument.

    Attributes:
        images: (N, S, S, 3) uint8.
        keypoints: (N, K, 2) float32 crop pixels (NaN: not annotated).
        visible: (N, K) bool.
        self_occluded: (N, K) bool.
        rois: (N, 4) float64 boxes ``(x0, y0, x1, y1)`` of the crops in their
            full images, image pixel edges; None when unknown.
    """

    def __init__(self, images, keypoints, visible=None, self_occluded=None, rois=None):
        images = np.asarray(images)
        if images.ndim != 4 or images.shape[3] != 3 or images.shape[1] != images.shape[2]:
            raise ValueError(f"images: expected shape (N, S, S, 3) (square RGB crops), got {images.shape}")
        if images.dtype != np.uint8:
            raise ValueError(f"images: expected dtype uint8, got {images.dtype}")
        n = len(images)
        keypoints = np.asarray(keypoints, dtype=np.float32)
        if keypoints.ndim != 3 or keypoints.shape[0] != n or keypoints.shape[2] != 2:
            raise ValueError(f"keypoints: expected shape ({n}, K, 2), got {keypoints.shape}")
        k = keypoints.shape[1]
        visible = np.ones((n, k), bool) if visible is None else np.asarray(visible, dtype=bool)
        self_occluded = np.zeros((n, k), bool) if self_occluded is None else np.asarray(self_occluded, dtype=bool)
        for name, arr in (("visible", visible), ("self_occluded", self_occluded)):
            if arr.shape != (n, k):
                raise ValueError(f"{name}: expected shape ({n}, {k}), got {arr.shape}")
        if rois is not None:
            try:
                rois = np.asarray(rois, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"rois: expected ({n}, 4) boxes (x0, y0, x1, y1), got {type(rois).__name__}") from None
            if rois.shape != (n, 4):
                raise ValueError(f"rois: expected shape ({n}, 4) boxes (x0, y0, x1, y1), got {rois.shape}")
            bad = np.flatnonzero(~np.all(np.isfinite(rois), axis=1))
            if bad.size:
                raise ValueError(f"rois: expected finite boxes, got NaN or inf in rows {bad[:5].tolist()}")
        self.images, self.keypoints, self.visible, self.self_occluded = images, keypoints, visible, self_occluded
        self.rois = rois

    def __len__(self) -> int:
        return len(self.images)

    @property
    def crop_size(self) -> int:
        return int(self.images.shape[1])

    @property
    def num_keypoints(self) -> int:
        return int(self.keypoints.shape[1])

    def resized(self, size: int) -> "KeypointDataset":
        """The same crops resampled to ``size x size``; ``self`` if already that size.

        Keypoints (crop pixels) are scaled with the crops; ``rois`` (full-image
        pixels) are unchanged: each crop still covers the same box of its image.
        """
        S = self.crop_size
        if size == S:
            return self
        box = (0.0, 0.0, float(S), float(S))
        images = np.stack([crop_roi(img, box, size)[0] for img in self.images])
        return KeypointDataset(images, image_to_crop(self.keypoints, box, size), self.visible, self.self_occluded,
                               self.rois)

    def subset(self, indices) -> "KeypointDataset":
        """The crops at ``indices`` (an index array or a boolean mask of length N), in that order, with their rows
        of every array (``rois`` included when known)."""
        idx = np.asarray(indices)
        return KeypointDataset(self.images[idx], self.keypoints[idx], self.visible[idx], self.self_occluded[idx],
                               None if self.rois is None else self.rois[idx])

    def sample(self, i: int):
        """Item ``i`` as a :class:`Sample` (ROI: the whole crop)."""
        s = self.crop_size
        return Sample(
            image=self.images[i], keypoints=self.keypoints[i], visible=self.visible[i],
            self_occluded=self.self_occluded[i], roi=(0.0, 0.0, float(s), float(s)), meta={"index": int(i)},
        )

    # ------------------------------------------------------------ constructors
    @classmethod
    def from_samples(cls, samples: Iterable, size: int | None = None) -> "KeypointDataset":
        """Stacks samples with fields ``image``, ``keypoints``, ``visible``, ``self_occluded``.

        Crops of another size than ``size`` (default: the first sample's) are
        resized, their keypoints scaled with them. The samples' ``roi`` is not
        read: the result's ``rois`` is None.
        """
        images, kps, vis, occ = [], [], [], []
        for i, s in enumerate(samples):
            img = np.asarray(s.image)
            kp = np.asarray(s.keypoints, dtype=float)
            if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] != img.shape[1]:
                raise ValueError(f"samples[{i}].image: expected a square (S, S, 3) crop, got {img.shape}")
            if size is None:
                size = img.shape[0]
            if img.shape[0] != size:
                kp = image_to_crop(kp, (0, 0, img.shape[1], img.shape[0]), size)
                img, _ = crop_roi(img, (0, 0, img.shape[1], img.shape[0]), size)
            images.append(img.astype(np.uint8, copy=False))
            kps.append(kp)
            vis.append(np.asarray(s.visible, dtype=bool))
            occ.append(np.asarray(s.self_occluded, dtype=bool))
        if not images:
            raise ValueError("samples: empty")
        return cls(np.stack(images), np.stack(kps), np.stack(vis), np.stack(occ))

    @classmethod
    def from_arrays(cls, arrays) -> "KeypointDataset":
        """From a mapping (e.g. an ``np.load`` of a shard) with ``images`` (or ``image``),
        ``keypoints``, and optionally ``visible``, ``self_occluded`` and ``rois``."""
        keys = set(arrays.keys()) if hasattr(arrays, "keys") else set()
        img_key = "images" if "images" in keys else "image" if "image" in keys else None
        if img_key is None or "keypoints" not in keys:
            raise ValueError(f"arrays: expected keys 'images' and 'keypoints', got {sorted(keys)}")
        get = lambda k: np.asarray(arrays[k]) if k in keys else None  # noqa: E731
        return cls(get(img_key), get("keypoints"), get("visible"), get("self_occluded"), get("rois"))

    @classmethod
    def from_npz(cls, paths) -> "KeypointDataset":
        """Concatenates ``.npz`` shards (a file, a folder of ``*.npz`` or a list of files).

        The result has ``rois`` only when every shard has a ``rois`` key.
        """
        files = _npz_files(paths)
        parts = []
        for f in files:
            with np.load(f, allow_pickle=False) as z:
                try:
                    parts.append(cls.from_arrays(z))
                except ValueError as exc:
                    raise ValueError(f"{f}: {exc}") from None
        return cls.concatenate(parts)

    @classmethod
    def concatenate(cls, parts: Sequence["KeypointDataset"]) -> "KeypointDataset":
        """The datasets one after the other (same crop size and keypoint count); ``rois`` only when every part has
        them."""
        if not parts:
            raise ValueError("concatenate: no datasets")
        rois = [p.rois for p in parts]
        return cls(
            np.concatenate([p.images for p in parts]), np.concatenate([p.keypoints for p in parts]),
            np.concatenate([p.visible for p in parts]), np.concatenate([p.self_occluded for p in parts]),
            np.concatenate(rois) if all(r is not None for r in rois) else None,
        )

    @classmethod
    def from_render(cls, n: int, seed: int = 0, size: int = 128, held_out: bool = False) -> "KeypointDataset":
        """Renders ``n`` samples in memory with :func:`vfactor.render.random_training_sample`
        (sample ``i`` from ``vfactor.render.sample_rng(seed, i, held_out)``, as ``make_dataset`` draws them)."""
        from vfactor.render import random_training_sample, sample_rng  # noqa: PLC0415 - optional sibling package

        return cls.from_samples(
            (random_training_sample(sample_rng(seed, i, held_out), size=size, held_out=held_out) for i in range(int(n))),
            size=size,
        )

    def save_npz(self, path) -> Path:
        """Writes one shard readable by :meth:`from_npz` (with a ``rois`` key when they are known)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = dict(images=self.images, keypoints=self.keypoints, visible=self.visible,
                      self_occluded=self.self_occluded)
        if self.rois is not None:
            arrays["rois"] = self.rois
        np.savez_compressed(path, **arrays)
        return path


def as_dataset(data: Any, size: int | None = None) -> KeypointDataset:
    """Turns what :func:`vfactor.net.train.train` accepts into a :class:`KeypointDataset`.

    Accepted: a :class:`KeypointDataset`; an object with array attributes
    ``images``, ``keypoints``, ``visible``, ``self_occluded`` (the renderer's
    :class:`vfactor.render.RenderedDataset`); a mapping of such arrays; a path
    (``.npz`` shard or folder of shards) or list of paths; a sequence of
    samples (objects with ``image``, ``keypoints``, ``visible``,
    ``self_occluded``). The crops' boxes come along as ``rois`` where the data
    have them (attribute, key or shard key ``rois``); samples give none.
    """
    if isinstance(data, KeypointDataset):
        return data
    if isinstance(data, (str, Path)):
        return KeypointDataset.from_npz(data)
    if isinstance(data, (list, tuple)) and data and all(isinstance(d, (str, Path)) for d in data):
        return KeypointDataset.from_npz(list(data))
    if all(hasattr(data, a) for a in ("images", "keypoints")) and not hasattr(data, "keys"):
        return KeypointDataset(data.images, data.keypoints, getattr(data, "visible", None),
                               getattr(data, "self_occluded", None), getattr(data, "rois", None))
    if hasattr(data, "keys"):
        return KeypointDataset.from_arrays(data)
    if isinstance(data, Iterable):
        return KeypointDataset.from_samples(data, size=size)
    raise TypeError(f"dataset: expected a KeypointDataset, samples, arrays or .npz paths, got {type(data).__name__}")


def _npz_files(paths) -> list[Path]:
    items = [paths] if isinstance(paths, (str, Path)) else list(paths)
    files: list[Path] = []
    for p in map(Path, items):
        if p.is_dir():
            found = sorted(p.glob("*.npz"))
            if not found:
                raise ValueError(f"{p}: no .npz shards in this folder")
            files.extend(found)
        elif p.is_file():
            files.append(p)
        else:
            raise ValueError(f"{p}: no such file or folder")
    if not files:
        raise ValueError("dataset: no .npz files given")
    return files


# ----------------------------------------------------------------- augmentation
@dataclass(frozen=True)
class AugmentConfig:
    """Random augmentation of a training crop (all draws uniform).

    Attributes:
        flip: probability of a left-right mirror (keypoints swapped with
            :data:`vfactor.keypoints.MIRROR_PERMUTATION`).
        scale: zoom factor drawn in ``[1 - scale, 1 + scale]`` about the crop centre.
        rotation_deg: in-plane rotation drawn in ``[-rotation_deg, rotation_deg]``.
        shift: translation drawn in ``[-shift, shift]`` times the crop side, per axis.
        brightness, contrast, saturation: factors drawn in ``[1 - x, 1 + x]``.
        channel_gain: per-channel gains in ``[1 - x, 1 + x]`` (colour cast).
        noise: standard deviation of added Gaussian pixel noise drawn in ``[0, noise]`` (of 1).
    """

    flip: float = 0.5
    scale: float = 0.15
    rotation_deg: float = 10.0
    shift: float = 0.05
    brightness: float = 0.3
    contrast: float = 0.3
    saturation: float = 0.3
    channel_gain: float = 0.1
    noise: float = 0.02

    def __post_init__(self):
        check_numbers("augment", self, self.__dataclass_fields__, strict=False)
        if self.flip > 1:
            raise ValueError(f"augment.flip: expected a probability in [0, 1], got {self.flip}")
        if self.scale >= 1:
            raise ValueError(f"augment.scale: expected < 1, got {self.scale}")


def sample_rng(seed: int, epoch: int, index: int) -> np.random.Generator:
    """The generator that augments sample ``index`` in ``epoch`` (independent of order and workers)."""
    return np.random.default_rng([int(seed), int(epoch), int(index)])


def augment(image: np.ndarray, keypoints: np.ndarray, visible: np.ndarray, self_occluded: np.ndarray,
            rng: np.random.Generator, config: AugmentConfig = AugmentConfig()):
    """Randomly mirrors, scales, rotates, shifts and recolours one crop.

    Args:
        image: (S, S, 3) uint8.
        keypoints: (K, 2) crop pixels (NaN allowed). With ``flip`` > 0, K must be
            12 in vfactor's order (left/right partners are swapped).
        visible, self_occluded: (K,) bools, permuted with the keypoints on a flip.
        rng: random generator (see :func:`sample_rng`).
        config: ranges.

    Returns:
        ``(image float32 (S, S, 3) in [0, 1], keypoints, visible, self_occluded)``.
        Keypoints pushed out of the crop stay where the transform puts them
        (their loss weight becomes 0, see :mod:`vfactor.net.targets`).
    """
    img = np.asarray(image)
    S = img.shape[0]
    kp = np.array(keypoints, dtype=np.float64)
    vis, occ = np.array(visible, dtype=bool), np.array(self_occluded, dtype=bool)

    if config.flip > 0 and rng.random() < config.flip:
        if len(kp) != NUM_KEYPOINTS:
            raise ValueError(f"keypoints: a flip needs the {NUM_KEYPOINTS} vehicle keypoints, got {len(kp)}")
        img = img[:, ::-1]
        kp[:, 0] = (S - 1) - kp[:, 0]
        kp, vis, occ = kp[MIRROR_PERMUTATION], vis[MIRROR_PERMUTATION], occ[MIRROR_PERMUTATION]

    s = 1.0 + rng.uniform(-config.scale, config.scale)
    a = math.radians(rng.uniform(-config.rotation_deg, config.rotation_deg))
    t = rng.uniform(-config.shift, config.shift, size=2) * S
    if s != 1.0 or a != 0.0 or np.any(t != 0):
        c = (S - 1) / 2.0
        R = s * np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        M = np.hstack([R, (np.array([c, c]) - R @ np.array([c, c]) + t)[:, None]])
        img = cv2.warpAffine(np.ascontiguousarray(img), M, (S, S), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE)
        kp = kp @ R.T + M[:, 2]

    out = np.ascontiguousarray(img, dtype=np.float32) / 255.0
    grey = out.mean(axis=2, keepdims=True)
    sat = 1.0 + rng.uniform(-config.saturation, config.saturation)
    out = grey + sat * (out - grey)
    con = 1.0 + rng.uniform(-config.contrast, config.contrast)
    out = out.mean() + con * (out - out.mean())
    out = out * (1.0 + rng.uniform(-config.brightness, config.brightness))
    out = out * (1.0 + rng.uniform(-config.channel_gain, config.channel_gain, size=3)).astype(np.float32)
    if config.noise > 0:
        out = out + rng.normal(0.0, rng.uniform(0.0, config.noise), size=out.shape).astype(np.float32)
    return np.clip(out, 0.0, 1.0).astype(np.float32), kp.astype(np.float32), vis, occ
