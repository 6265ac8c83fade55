"""PCK@alpha of the box size, visible and self-occluded keypoints apart."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vfactor.net.evaluate import pck, score_predictions


def test_pck_counts_hits_within_alpha_of_the_box():
    truth = np.zeros((1, 4, 2))
    pred = np.array([[[12.0, 0.0], [12.9, 0.0], [np.nan, np.nan], [0.0, 13.0]]])
    value, n = pck(pred, truth, np.ones((1, 4), bool), box_size=128, alpha=0.1)  # threshold 12.8 px
    assert n == 4 and value == 0.25
    assert pck(pred, truth, np.array([[True, False, False, False]]), 128)[0] == 1.0
    assert pck(pred, truth, np.array([[False, True, True, True]]), 128)[0] == 0.0
    value, n = pck(pred, truth, np.zeros((1, 4), bool), 128)
    assert n == 0 and math.isnan(value)


def test_scores_split_visible_and_self_occluded_and_ignore_outside():
    truth = np.array([[[10.0, 10.0], [20.0, 20.0], [30.0, 30.0], [70.0, 10.0]]])
    pred = truth + np.array([[[1.0, 0.0], [9.0, 0.0], [2.0, 2.0], [0.0, 0.0]]])
    vis = np.array([[True, True, False, True]])
    occ = np.array([[False, False, True, False]])
    s = score_predictions(pred, truth, vis, occ, crop_size=64, alpha=0.1)  # 6.4 px; keypoint 3 is outside
    assert (s.pck_visible, s.n_visible) == (0.5, 2)
    assert (s.pck_self_occluded, s.n_self_occluded) == (1.0, 1)
    assert (s.pck_all, s.n_all) == (pytest.approx(2 / 3), 3)
