"""Statistics of vehicle shapes: the mean-shape prior and the HWC bounds.

Both are learnt from the nine PASCAL3D+ car CAD models (scaled to metres by a
wheelbase) and, for the bounds, from the presets too, so that vans and pickups
stay inside the hinge limits.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations

import numpy as np

from vfactor.keypoints import LAYERS, MIRROR_PERMUTATION
from vfactor.wireframe import PRESETS, Wireframe, pascal3d_shapes

__all__ = ["ShapePrior", "HwcBounds", "default_shape_prior", "default_hwc_bounds", "DISTANCE_PAIRS"]

#: All 66 keypoint pairs (i < j) whose distance the HWC distance factor bounds.
DISTANCE_PAIRS: np.ndarray = np.array(list(combinations(range(12), 2)))
DISTANCE_PAIRS.setflags(write=False)


@dataclass(frozen=True)
class ShapePrior:
    """Gaussian prior on the 36 body-frame keypoint coordinates (metres).

    Attributes:
        mean: (12, 3) mean shape, exactly left/right symmetric.
        covariance: (36, 36) covariance of the flattened shape (row-major
            ``[x0, y0, z0, x1, ...]``), positive definite.
    """

    mean: np.ndarray
    covariance: np.ndarray

    @property
    def wireframe(self) -> Wireframe:
        return Wireframe(self.mean)

    def sqrt_information(self) -> np.ndarray:
        """(36, 36) upper-triangular R with ``R^T R = covariance^-1`` (computed once, read-only)."""
        cached = self.__dict__.get("_sqrt_information")
        if cached is None:
            cached = np.linalg.cholesky(np.linalg.inv(self.covariance)).T
            cached.setflags(write=False)
            self.__dict__["_sqrt_information"] = cached
        return cached


@lru_cache(maxsize=8)
def default_shape_prior(
    wheelbase: float = 2.75, wheelbase_sigma: float = 0.20, floor_sigma: float = 0.04
) -> ShapePrior:
    """Mean shape and spread from the nine PASCAL3D+ cars.

    The normalised shapes (wheelbase units) are symmetrised, their mean and
    covariance are scaled by a wheelbase ``s ~ N(wheelbase, wheelbase_sigma^2)``:
    ``cov = E[s^2] cov_n + var(s) mean_n mean_n^T``, and an isotropic floor
    ``floor_sigma^2`` keeps the matrix positive definite (nine samples span at
    most eight directions).

    Args:
        wheelbase: mean wheelbase, metres.
        wheelbase_sigma: standard deviation of the wheelbase, metres.
        floor_sigma: isotropic standard deviation added to every coordinate, metres.
    """
    shapes = pascal3d_shapes()
    shapes = 0.5 * (shapes + shapes[:, MIRROR_PERMUTATION] * [1.0, -1.0, 1.0])
    flat = shapes.reshape(len(shapes), 36)
    mean_n = flat.mean(0)
    cov_n = np.cov(flat, rowvar=False)
    second = wheelbase**2 + wheelbase_sigma**2
    cov = second * cov_n + wheelbase_sigma**2 * np.outer(mean_n, mean_n) + floor_sigma**2 * np.eye(36)
    mean = (wheelbase * mean_n).reshape(12, 3)
    mean.setflags(write=False)
    cov.setflags(write=False)
    return ShapePrior(mean=mean, covariance=cov)


@dataclass(frozen=True)
class HwcBounds:
    """Bounds of the hierarchical wireframe constraint (metres, or ratios).

    Attributes:
        distance: (66, 2) ``[min, max]`` for every pair in :data:`DISTANCE_PAIRS`.
        width_ratio: layer name -> ``(min, max)`` of front width / back width
            (the trapezoid of the light and roof layers).
        layer_offset: layer name -> (2, 2) ``[[x_min, x_max], [z_min, z_max]]``
            of the layer centroid relative to the wheel-layer centroid.
    """

    distance: np.ndarray
    width_ratio: dict
    layer_offset: dict

    @classmethod
    def from_wireframes(cls, wireframes, margin: float = 0.15) -> "HwcBounds":
        """Bounds spanning ``wireframes``, widened by ``margin`` of each range's size (at least 5 cm)."""
        pts = np.array([w.vehicle_p_keypoints for w in wireframes])
        d = np.linalg.norm(pts[:, DISTANCE_PAIRS[:, 0]] - pts[:, DISTANCE_PAIRS[:, 1]], axis=2)
        distance = _widen(d.min(0), d.max(0), margin, 0.05)
        width_ratio, layer_offset = {}, {}
        wheel_centroid = pts[:, list(LAYERS["wheel"])].mean(1)
        for name in ("light", "roof"):
            lf, rf, lb, rb = LAYERS[name]
            ratio = np.linalg.norm(pts[:, lf] - pts[:, rf], axis=1) / np.linalg.norm(pts[:, lb] - pts[:, rb], axis=1)
            lo, hi = _widen(ratio.min(), ratio.max(), margin, 0.05)
            width_ratio[name] = (float(lo), float(hi))
            off = pts[:, list(LAYERS[name])].mean(1) - wheel_centroid
            lo, hi = _widen(off[:, [0, 2]].min(0), off[:, [0, 2]].max(0), margin, 0.10)
            layer_offset[name] = np.stack([lo, hi], axis=1)
        distance.setflags(write=False)
        return cls(distance=distance, width_ratio=width_ratio, layer_offset=layer_offset)


def _widen(lo, hi, margin, minimum):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pad = np.maximum(margin * (hi - lo), minimum)
    return np.stack([lo - pad, hi + pad], axis=-1)


@lru_cache(maxsize=1)
def default_hwc_bounds() -> HwcBounds:
    """HWC bounds from the PASCAL3D+ cars at wheelbases 2.4-3.1 m and all presets."""
    wireframes = [Wireframe(s * wb) for s in pascal3d_shapes() for wb in (2.4, 3.1)]
    wireframes += [p.wireframe() for p in PRESETS.values()]
    return HwcBounds.from_wireframes(wireframes)
