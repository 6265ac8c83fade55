"""The keypoint network: a stacked hourglass that turns vehicle crops into 12 keypoint heatmaps (PyTorch).

Needs the ``net`` extra (``pip install -c constraints.txt -e ".[net]"``).
``vfactor`` itself never imports this package (nor torch); import it explicitly.

* :class:`StackedHourglass`, :func:`save_weights`, :func:`load_weights` (:mod:`vfactor.net.model`)
* :func:`heatmap_targets`, :func:`keypoint_weights` (:mod:`vfactor.net.targets`)
* :class:`TrainConfig`, :func:`train` (:mod:`vfactor.net.train`)
* :class:`KeypointDetector` (:mod:`vfactor.net.infer`)
* :class:`CovarianceCalibration`, :func:`calibrate`, :func:`write_calibration` (:mod:`vfactor.net.calibrate`)
* :class:`KeypointDataset`, :class:`AugmentConfig` (:mod:`vfactor.net.data`)
* :func:`load_pascal3d` (:mod:`vfactor.net.pascal3d`)

See ``docs/network.md``.
"""

from __future__ import annotations

from vfactor.net.calibrate import (
    CovarianceCalibration,
    KeypointErrors,
    calibrate,
    fit_calibration,
    measure_errors,
    write_calibration,
)
from vfactor.net.crop import crop_roi, expand_roi
from vfactor.net.data import AugmentConfig, KeypointDataset, Sample
from vfactor.net.evaluate import PCKResult, score_predictions
from vfactor.net.infer import Detection, KeypointDetector, benchmark_inference, default_weights_path
from vfactor.net.model import ModelConfig, StackedHourglass, count_parameters, load_weights, save_weights
from vfactor.net.pascal3d import load_pascal3d
from vfactor.net.targets import heatmap_targets, keypoint_weights
from vfactor.net.train import TrainConfig, TrainResult, evaluate_model, train

__all__ = [
    "StackedHourglass",
    "ModelConfig",
    "save_weights",
    "load_weights",
    "count_parameters",
    "heatmap_targets",
    "keypoint_weights",
    "TrainConfig",
    "TrainResult",
    "train",
    "evaluate_model",
    "KeypointDetector",
    "Detection",
    "default_weights_path",
    "benchmark_inference",
    "CovarianceCalibration",
    "KeypointErrors",
    "calibrate",
    "fit_calibration",
    "measure_errors",
    "write_calibration",
    "KeypointDataset",
    "AugmentConfig",
    "Sample",
    "PCKResult",
    "score_predictions",
    "crop_roi",
    "expand_roi",
    "load_pascal3d",
]
