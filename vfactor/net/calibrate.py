"""Calibration of the keypoint covariances against the network's held-out pixel errors.

:func:`vfactor.heatmaps.decode_heatmaps` returns, per keypoint, the covariance
of the heatmap blob (the inverse Hessian of the log-heatmap). That is the
spread of the blob, which a network trained on Gaussian targets of ``sigma``
heatmap pixels keeps at about ``sigma`` whether it is right or not: it ranks
keypoints, but its scale is the targets', not the error's. The projection
factors whiten residuals with these covariances, so they must be the
covariances of the real errors. :class:`CovarianceCalibration` maps a decoded
covariance ``S`` (image px^2) to a calibrated one::

    S_cal = exp(confidence_rate * (1 - confidence)) * (scale * S + diag((floor * w)^2, (floor * h)^2))

with ``confidence`` the heatmap peak in [0, 1] and ``w``, ``h`` the sides of
the box the heatmaps cover (the crop box, image pixels). Only what the
detector has at test time enters: the heatmap covariance, the confidence and
the box (not whether a keypoint is self-occluded). The identity is ``scale=1,
floor=0, confidence_rate=0``.

Measurement (:func:`measure_errors`): the network runs on held-out crops with
known keypoints; errors ``e = uv_pred - uv_true`` and covariances are taken
in image pixels through each crop's box (the renderer's ``rois``; the crop
itself when the data have none). Only keypoints inside the crop are measured,
in the groups of :mod:`vfactor.net.evaluate` (visible; self-occluded and not
visible; and all of them, those occluded by other objects too).

Fit (:func:`fit_calibration`): maximum likelihood of a mixture of a zero-mean
Gaussian with covariance ``S_cal`` (the errors the graph should weight) and a
uniform density over the box (gross errors: a wrong part, a left/right swap),
whose weight is fitted too. The gross errors, which the graph's robust loss
handles, thus neither inflate the fit nor get trimmed by a threshold that
depends on the fit itself. For a calibrated 2D Gaussian the squared
Mahalanobis distance ``d2 = e^T S_cal^-1 e`` is chi-square with 2 degrees of
freedom: median :data:`CHI2_2_MEDIAN` (1.386), mean 2, 95 % below
:data:`CHI2_2_95` (5.99); :func:`summarise` reports these per group.

The calibration is stored in a weights file's metadata under
:data:`METADATA_KEY` (:func:`write_calibration`, the weights untouched), where
:class:`vfactor.net.infer.KeypointDetector` reads it. ``python -m vfactor.net
calibrate`` measures, fits on half of the crops, reports on the other half
and, with ``--write``, stores the result (docs/network.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from vfactor.errors import check_numbers
from vfactor.heatmaps import decode_heatmaps
from vfactor.net.crop import crop_to_image
from vfactor.net.targets import in_crop

__all__ = [
    "CovarianceCalibration",
    "KeypointErrors",
    "measure_errors",
    "fit_calibration",
    "calibrate",
    "summarise",
    "write_calibration",
    "load_crops",
    "METADATA_KEY",
    "CHI2_2_MEDIAN",
    "CHI2_2_95",
]

#: Key of the calibration (:meth:`CovarianceCalibration.to_dict`) in a weights file's metadata.
METADATA_KEY = "covariance_calibration"
#: Median of chi-square(2), ``2 ln 2``: the median ``d2`` of calibrated 2D Gaussian errors.
CHI2_2_MEDIAN = 2.0 * math.log(2.0)
#: 95 % quantile of chi-square(2), ``-2 ln 0.05``.
CHI2_2_95 = -2.0 * math.log(0.05)
#: Bounds of the fitted weight of the uniform gross-error component.
_OUTLIER_BOUNDS = (1e-6, 0.5)
#: Upper bound of the fitted ``confidence_rate`` (exp(20) is already a factor of 5e8).
_MAX_RATE = 20.0
#: The optimiser works on ``100 * floor`` (floors are ~1e-2 of the box; keeps the variables ~1).
_FLOOR_UNIT = 1e-2


@dataclass(frozen=True)
class CovarianceCalibration:
    """Maps decoded heatmap covariances to calibrated pixel covariances (see the module docstring).

    ``S_cal = exp(confidence_rate * (1 - confidence)) * (scale * S + diag((floor * w)^2, (floor * h)^2))``.

    Attributes:
        scale: factor on the heatmap covariance ``S`` (> 0, dimensionless).
        floor: standard deviation added on each axis, as a fraction of the
            box's side along it (>= 0; 0.01 is 2 px on a 200-pixel box).
        confidence_rate: growth of the whole covariance as the confidence
            drops (>= 0): a factor ``exp(confidence_rate * (1 - confidence))``,
            1 at confidence 1.
        shape_sigma: metres (>= 0): the network's error shaped like a change of
            the vehicle's shape, per detection (``Detection.shape_sigma``, which
            the pipeline sets from it; fitted on solved rendered scenes by
            :func:`vfactor.net.shape_error.fit_shape_sigma`). Not part of the
            pixel covariances: :meth:`apply` and :attr:`is_identity` ignore it.
        bias_sigma: the network's error that repeats over a vehicle's frames and
            cameras, a rigid motion of the vehicle (``Detection.bias_sigma``:
            ``(roll, pitch, yaw)`` radians, ``(x, y, z)`` metres, body frame; fitted
            on tracks of rendered scenes by
            :func:`vfactor.net.bias_error.fit_bias_sigma`); None: not calibrated.
            Not part of the pixel covariances either.
    """

    scale: float = 1.0
    floor: float = 0.0
    confidence_rate: float = 0.0
    shape_sigma: float = 0.0
    bias_sigma: tuple | None = None

    def __post_init__(self):
        check_numbers("calibration", self, ("scale",))
        check_numbers("calibration", self, ("floor", "confidence_rate", "shape_sigma"), strict=False)
        for name in ("scale", "floor", "confidence_rate", "shape_sigma"):
            object.__setattr__(self, name, float(getattr(self, name)))
        if self.bias_sigma is not None:
            bias = np.asarray(self.bias_sigma, dtype=float)
            if bias.shape != (6,) or not np.all(np.isfinite(bias)) or np.any(bias < 0):
                raise ValueError(f"calibration.bias_sigma: expected 6 finite numbers >= 0 ([roll, pitch, yaw] "
                                 f"radians, [x, y, z] metres), got {self.bias_sigma!r}")
            object.__setattr__(self, "bias_sigma", tuple(float(x) for x in bias))

    @property
    def is_identity(self) -> bool:
        """True when :meth:`apply` returns covariances unchanged."""
        return self.scale == 1.0 and self.floor == 0.0 and self.confidence_rate == 0.0

    def detection_fields(self) -> dict:
        """What a detection found with weights of this calibration carries (:class:`vfactor.observations.Detection`'s
        fields, and ``vfactor detect``'s output): ``covariance_calibrated``, ``shape_sigma`` and ``bias_sigma``
        (None: none)."""
        return {"covariance_calibrated": not self.is_identity, "shape_sigma": self.shape_sigma or None,
                "bias_sigma": self.bias_sigma}

    def apply(self, covariance, confidence, box_size) -> np.ndarray:
        """Calibrated covariances.

        Args:
            covariance: (..., 2, 2) decoded covariances, image px^2 (NaN blocks
                for keypoints not found stay NaN).
            confidence: confidences in [0, 1] broadcasting to ``covariance``'s
                leading shape (values outside are clipped).
            box_size: side of the box the heatmaps cover, image pixels: a
                scalar (a square box) or ``(..., 2)`` ``(width, height)``
                broadcasting to ``covariance``'s leading shape.

        Returns:
            (..., 2, 2) float64 calibrated covariances, px^2.
        """
        cov = np.asarray(covariance, dtype=float)
        if cov.ndim < 2 or cov.shape[-2:] != (2, 2):
            raise ValueError(f"covariance: expected shape (..., 2, 2), got {cov.shape}")
        lead = cov.shape[:-2]
        conf = np.clip(np.broadcast_to(np.asarray(confidence, dtype=float), lead), 0.0, 1.0)
        wh = np.asarray(box_size, dtype=float)
        if wh.ndim == 0:
            wh = np.array([wh, wh])
        try:
            wh = np.broadcast_to(wh, lead + (2,))
        except ValueError:
            raise ValueError(f"box_size: expected a scalar or (..., 2) (width, height) matching covariance's "
                             f"{lead}, got shape {np.shape(box_size)}") from None
        gain = np.exp(self.confidence_rate * (1.0 - conf))
        floor = (self.floor * wh) ** 2
        return gain[..., None, None] * (self.scale * cov + floor[..., :, None] * np.eye(2))

    def to_dict(self) -> dict:
        """The fields as plain floats (``bias_sigma`` a list of them, where calibrated; for a weights file's
        metadata)."""
        out = {f.name: float(getattr(self, f.name)) for f in fields(self) if f.name != "bias_sigma"}
        if self.bias_sigma is not None:
            out["bias_sigma"] = list(self.bias_sigma)
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "CovarianceCalibration":
        """From :meth:`to_dict`'s output; unknown keys raise ``ValueError`` naming them."""
        if not isinstance(data, dict):
            raise ValueError(f"calibration: expected a dict of {[f.name for f in fields(cls)]}, got "
                             f"{type(data).__name__}")
        names = {f.name for f in fields(cls)}
        unknown = set(data) - names
        if unknown:
            raise ValueError(f"calibration: unknown keys {sorted(unknown)}; expected {sorted(names)}")
        return cls(**data)

    @classmethod
    def from_metadata(cls, metadata: dict | None) -> "CovarianceCalibration | None":
        """The calibration stored in a weights file's metadata (:data:`METADATA_KEY`), or None."""
        if not metadata or metadata.get(METADATA_KEY) is None:
            return None
        return cls.from_dict(metadata[METADATA_KEY])


@dataclass(frozen=True)
class KeypointErrors:
    """Errors of the network on crops with known keypoints, one row per keypoint inside its crop.

    Attributes:
        error: (n, 2) ``uv_pred - uv_true``, image pixels; NaN where not found.
        covariance: (n, 2, 2) decoded (uncalibrated) covariances, image px^2; NaN where not found.
        confidence: (n,) heatmap peaks in [0, 1] (0: not found).
        box_size: (n, 2) ``(width, height)`` of the crop's box, image pixels.
        visible: (n,) the annotation's flag.
        self_occluded: (n,) self-occluded and not visible.
        crop: (n,) index of the crop in the data.
    """

    error: np.ndarray
    covariance: np.ndarray
    confidence: np.ndarray
    box_size: np.ndarray
    visible: np.ndarray
    self_occluded: np.ndarray
    crop: np.ndarray

    def __len__(self) -> int:
        return len(self.error)

    @property
    def found(self) -> np.ndarray:
        """(n,) True where the keypoint was found (finite error and covariance)."""
        return np.all(np.isfinite(self.error), axis=1) & np.all(np.isfinite(self.covariance), axis=(1, 2))

    def subset(self, mask) -> "KeypointErrors":
        """The rows selected by a boolean mask or an index array."""
        m = np.asarray(mask)
        return KeypointErrors(*(getattr(self, f.name)[m] for f in fields(self)))

    def groups(self) -> dict[str, np.ndarray]:
        """Row masks ``{"visible", "self_occluded", "all"}`` (all: every keypoint in the crop)."""
        return {"visible": self.visible, "self_occluded": self.self_occluded, "all": np.ones(len(self), bool)}


def load_crops(data, size: int | None = None):
    """Crops, keypoints, flags and boxes to measure on.

    Args:
        data: what :func:`vfactor.net.data.as_dataset` accepts (``.npz`` shards
            or folders, a :class:`vfactor.net.data.KeypointDataset`, the
            renderer's loaded dataset...). The crops' boxes in the full image
            are the ``rois`` (array attribute or shard key) when present.
        size: resize the crops to this side, pixels (the network's input);
            keypoints follow, boxes are unchanged.

    Returns:
        ``(dataset, rois)``: a :class:`vfactor.net.data.KeypointDataset` and its
        ``rois``, (N, 4) ``(x0, y0, x1, y1)`` boxes in image pixel edges, or
        None when the data have none.
    """
    from vfactor.net.data import as_dataset  # noqa: PLC0415

    ds = as_dataset(data, size=size)
    if size is not None:
        ds = ds.resized(size)
    return ds, ds.rois


def measure_errors(detector, data, rois=None, batch_size: int = 64) -> KeypointErrors:
    """Runs the network on crops with known keypoints and measures its errors in image pixels.

    Args:
        detector: a :class:`vfactor.net.infer.KeypointDetector`, a
            :class:`vfactor.net.model.StackedHourglass`, or a weights path.
            Heatmaps are decoded without any calibration (the raw heatmap
            covariances), with the detector's ``min_confidence``.
        data: see :func:`load_crops`.
        rois: (N, 4) boxes ``(x0, y0, x1, y1)`` the crops cover in the full
            image (image pixel edges); None: the data's own, else the crop
            itself (errors then in crop pixels; the fit does not depend on it).
        batch_size: crops per forward pass.

    Returns:
        :class:`KeypointErrors` of every keypoint inside its crop.
    """
    from vfactor.net.infer import KeypointDetector  # noqa: PLC0415 - infer imports this module

    if not isinstance(detector, KeypointDetector):
        detector = KeypointDetector(detector, calibration=CovarianceCalibration(), batch_size=batch_size)
    S = detector.input_size
    ds, own_rois = load_crops(data, size=S)
    if rois is None:
        rois = own_rois if own_rois is not None else np.tile([0.0, 0.0, float(S), float(S)], (len(ds), 1))
    rois = np.asarray(rois, float)
    if rois.shape != (len(ds), 4):
        raise ValueError(f"rois: expected shape ({len(ds)}, 4), got {rois.shape}")
    rows: dict[str, list] = {k: [] for k in ("error", "covariance", "confidence", "box_size", "visible",
                                             "self_occluded", "crop")}
    for start in range(0, len(ds), batch_size):
        heatmaps = detector.heatmaps(ds.images[start : start + batch_size])
        for j, hm in enumerate(heatmaps):
            i = start + j
            box = tuple(float(v) for v in rois[i])
            kp = decode_heatmaps(hm, roi=box, min_confidence=detector.min_confidence)
            inside = in_crop(ds.keypoints[i], S)
            truth = crop_to_image(ds.keypoints[i], box, S)
            vis = ds.visible[i] & inside
            rows["error"].append((kp.uv - truth)[inside])
            rows["covariance"].append(kp.covariance[inside])
            rows["confidence"].append(kp.confidence[inside])
            rows["box_size"].append(np.tile([box[2] - box[0], box[3] - box[1]], (int(inside.sum()), 1)))
            rows["visible"].append(vis[inside])
            rows["self_occluded"].append((ds.self_occluded[i] & inside & ~vis)[inside])
            rows["crop"].append(np.full(int(inside.sum()), i))
    shapes = {"error": (0, 2), "covariance": (0, 2, 2), "box_size": (0, 2)}
    out = {k: np.concatenate(v) if v else np.zeros(shapes.get(k, (0,))) for k, v in rows.items()}
    return KeypointErrors(out["error"].astype(float), out["covariance"].astype(float),
                          out["confidence"].astype(float), out["box_size"].astype(float),
                          out["visible"].astype(bool), out["self_occluded"].astype(bool), out["crop"].astype(int))


def fit_calibration(errors: KeypointErrors, floor: bool = True, confidence: bool = True) -> CovarianceCalibration:
    """Fits a :class:`CovarianceCalibration` to measured errors by robust maximum likelihood.

    The errors are modelled as a mixture: with probability ``1 - eps`` a
    zero-mean Gaussian with the calibrated covariance, with probability ``eps``
    uniform over the box (a gross error, density ``1 / (w h)``). ``scale``,
    ``floor``, ``confidence_rate`` and ``eps`` maximise the likelihood of the
    found keypoints (L-BFGS-B, from two starting points; in box-side units, so
    the fit does not depend on the image resolution).

    Args:
        errors: :func:`measure_errors`' output (keypoints not found are left out).
        floor: fit the floor (else 0).
        confidence: fit the confidence rate (else 0).

    Returns:
        The fitted calibration.

    Raises:
        ValueError: fewer than 10 found keypoints.
    """
    from scipy.optimize import minimize  # noqa: PLC0415

    e, S, conf = _normalised(errors)
    if len(e) < 10:
        raise ValueError(f"errors: need at least 10 found keypoints to fit a calibration, got {len(e)}")
    # Start: the scale that gives the median d2 of chi-square(2), the rest neutral.
    a0 = max(float(np.median(_mahalanobis2(S, e))) / CHI2_2_MEDIAN, 1e-12)
    b0 = 0.1 * math.sqrt(float(np.median(np.sum(e * e, axis=1))) / 2.0) / _FLOOR_UNIT if floor else 0.0

    def nll(x):
        a, b, c, eps = math.exp(x[0]), x[1] * _FLOOR_UNIT, x[2], x[3]
        C = np.exp(c * (1.0 - conf))[:, None, None] * (a * S + (b * b) * np.eye(2))
        det = C[:, 0, 0] * C[:, 1, 1] - C[:, 0, 1] ** 2
        d2 = _mahalanobis2(C, e, det)
        log_gauss = -0.5 * d2 - math.log(2.0 * math.pi) - 0.5 * np.log(det)
        return -float(np.sum(np.logaddexp(math.log1p(-eps) + log_gauss, math.log(eps))))  # uniform: density 1

    bounds = [(math.log(a0) - 20.0, math.log(a0) + 20.0), (0.0, None) if floor else (0.0, 0.0),
              (0.0, _MAX_RATE) if confidence else (0.0, 0.0), _OUTLIER_BOUNDS]
    best = None
    for c0 in ((0.0, 2.0) if confidence else (0.0,)):
        x0 = [math.log(a0) - c0 * float(np.median(1.0 - conf)), b0, c0, 0.05]
        res = minimize(nll, x0, method="L-BFGS-B", bounds=bounds)
        if best is None or res.fun < best.fun:
            best = res
    x = best.x
    return CovarianceCalibration(scale=math.exp(x[0]), floor=float(x[1]) * _FLOOR_UNIT,
                                 confidence_rate=float(x[2]))


def calibrate(detector, data, rois=None, floor: bool = True, confidence: bool = True) -> CovarianceCalibration:
    """Measures the network's errors on ``data`` (:func:`measure_errors`) and fits a calibration to all of them."""
    return fit_calibration(measure_errors(detector, data, rois), floor=floor, confidence=confidence)


def summarise(errors: KeypointErrors, calibration: CovarianceCalibration | None = None,
              alpha: float = 0.1) -> dict[str, dict]:
    """Statistics of the errors and of their squared Mahalanobis distances, per group.

    Args:
        errors: :func:`measure_errors`' output.
        calibration: applied to the covariances first (None: the identity, the raw heatmap covariances).
        alpha: PCK threshold, fraction of the box side (its larger side).

    Returns:
        ``{group: stats}`` for the groups of :meth:`KeypointErrors.groups`; stats:
        ``n`` keypoints, ``found``, ``pck`` (a keypoint not found counts as
        wrong), ``error_px`` (median ``|e|``, image pixels), ``error_box``
        (median ``|e|`` / box side), and over the found keypoints ``d2_median``,
        ``d2_mean``, ``d2_mean_correct`` (over those within ``alpha``:
        without the gross errors), ``within_95`` (fraction with ``d2 <=``
        :data:`CHI2_2_95`) and ``within_95_correct``.
    """
    cal = calibration or CovarianceCalibration()
    found = errors.found
    side = errors.box_size.max(axis=1)
    dist = np.linalg.norm(errors.error, axis=1)
    correct = np.where(found, dist <= alpha * side, False)
    cov = cal.apply(errors.covariance, errors.confidence, errors.box_size)
    d2 = np.full(len(errors), np.nan)
    d2[found] = _mahalanobis2(cov[found], errors.error[found])
    out = {}
    for name, mask in errors.groups().items():
        f, c = mask & found, mask & correct
        out[name] = {
            "n": int(mask.sum()),
            "found": int(f.sum()),
            "pck": _stat(np.mean, correct[mask]),
            "error_px": _stat(np.median, dist[f]),
            "error_box": _stat(np.median, dist[f] / side[f]),
            "d2_median": _stat(np.median, d2[f]),
            "d2_mean": _stat(np.mean, d2[f]),
            "d2_mean_correct": _stat(np.mean, d2[c]),
            "within_95": _stat(np.mean, d2[f] <= CHI2_2_95),
            "within_95_correct": _stat(np.mean, d2[c] <= CHI2_2_95),
        }
    return out


def write_calibration(path, calibration: CovarianceCalibration, extra: dict | None = None) -> Path:
    """Stores a calibration in a weights file's metadata; the weights and the rest of the header are kept.

    The file (:func:`vfactor.net.model.save_weights`) is read with
    :func:`vfactor.net.model.read_torch_file` (``weights_only=True``), its ``config`` gets
    ``{METADATA_KEY: calibration.to_dict()}`` (and ``extra``, JSON-like), and it
    is written back atomically.

    Args:
        path: weights file.
        calibration: what to store.
        extra: more metadata to store beside it (e.g. how it was measured).

    Returns:
        The path.
    """
    import torch  # noqa: PLC0415

    from vfactor.net.model import WEIGHTS_FORMAT, WeightsError, _check_plain, read_torch_file  # noqa: PLC0415

    path = Path(path)
    payload = read_torch_file(path)
    if not isinstance(payload, dict) or payload.get("format") != WEIGHTS_FORMAT:
        raise WeightsError(str(path), f"not a vfactor keypoint-network weights file (format {WEIGHTS_FORMAT!r} expected)")
    if not isinstance(calibration, CovarianceCalibration):
        raise TypeError(f"calibration: expected a CovarianceCalibration, got {type(calibration).__name__}")
    config = dict(payload.get("config", {}))
    config.update(extra or {})
    config[METADATA_KEY] = calibration.to_dict()
    _check_plain(config, "config")
    payload["config"] = config
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)
    return path


# ----------------------------------------------------------------- internals
def _normalised(errors: KeypointErrors):
    """Found keypoints' errors and covariances divided by the box sides (per axis), and confidences."""
    f = errors.found
    wh = errors.box_size[f]
    e = errors.error[f] / wh
    S = errors.covariance[f] / (wh[:, :, None] * wh[:, None, :])
    return e, S, np.clip(errors.confidence[f], 0.0, 1.0)


def _mahalanobis2(C: np.ndarray, e: np.ndarray, det: np.ndarray | None = None) -> np.ndarray:
    """``e^T C^-1 e`` for (n, 2, 2) ``C`` and (n, 2) ``e`` (closed-form 2x2 inverse)."""
    if det is None:
        det = C[:, 0, 0] * C[:, 1, 1] - C[:, 0, 1] * C[:, 1, 0]
    num = C[:, 1, 1] * e[:, 0] ** 2 - (C[:, 0, 1] + C[:, 1, 0]) * e[:, 0] * e[:, 1] + C[:, 0, 0] * e[:, 1] ** 2
    return num / det


def _stat(fn, values: Any) -> float:
    values = np.asarray(values, float)
    return float(fn(values)) if values.size else float("nan")
