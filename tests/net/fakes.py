"""Stand-in networks with known outputs for the detector tests (import only where torch is available)."""

from __future__ import annotations

import numpy as np
import torch

from vfactor.heatmaps import render_gaussian_heatmap
from vfactor.net.model import StackedHourglass

S, H = 64, 16  # input side and heatmap side
PEAKS = np.array([[2.3 + 1.0 * k, 3.6 + 0.8 * k] for k in range(12)])  # heatmap pixels
COV = np.array([[1.2, 0.3], [0.3, 0.8]])  # heatmap px^2


class FixedHeatmaps(StackedHourglass):
    """Outputs the same known Gaussians (peaks ``PEAKS``, covariance ``COV``) whatever the crop."""

    def forward(self, x):
        hm = np.stack([render_gaussian_heatmap(p, COV, (H, H), peak=0.9) for p in PEAKS]).astype(np.float32)
        return [torch.from_numpy(hm).expand(len(x), -1, -1, -1)]


def fixed_net() -> FixedHeatmaps:
    return FixedHeatmaps(num_stacks=1, channels=8, depth=2, input_size=S)
