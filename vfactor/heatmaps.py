"""Keypoint heatmaps: decoding to pixels, confidences and 2x2 covariances (numpy only).

A keypoint network outputs one heatmap per keypoint (12, in the fixed order of
:mod:`vfactor.keypoints`) over a region of interest (ROI) of the image. This
module turns a heatmap stack into what the projection factors need: the
keypoint's pixel ``(u, v)``, a confidence in [0, 1] and a 2x2 pixel covariance
(px^2) that weights the factor.

Pixel conventions (both OpenCV's: integer coordinates at pixel *centres*):

* Heatmap coordinates ``(x, y)``: heatmap pixel ``[row, col]`` has its centre at
  ``(x, y) = (col, row)``.
* The ROI ``(x0, y0, x1, y1)`` is the box the heatmaps cover, given by its
  *edges* in image pixels: image pixel column ``k`` spans ``[k, k + 1)`` in edge
  coordinates, so a ROI ``(0, 0, W, H)`` is a whole W x H image. A heatmap of
  width ``w`` splits the box into columns of width ``sx = (x1 - x0) / w``:
  heatmap column ``c`` covers edge coordinates ``[x0 + c*sx, x0 + (c+1)*sx)``
  and its centre is at image pixel ``u = x0 + (c + 0.5) * sx - 0.5``. The same
  holds for rows with ``sy = (y1 - y0) / h``. See :func:`heatmap_to_image`
  and its inverse :func:`image_to_heatmap`.

The mapping is affine with Jacobian ``J = diag(sx, sy)``, so a heatmap
covariance ``S`` becomes ``J S J^T`` in image pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "DecodedKeypoints",
    "decode_heatmaps",
    "render_gaussian_heatmap",
    "heatmap_to_image",
    "image_to_heatmap",
    "extend_clipped_roi",
    "edges_at_border",
    "clipped_by_border",
    "clip_roi_to_image",
    "CLIPPED_EXTENSION",
]

#: Pixels below this fraction of the peak are left out of the log-quadratic fit
#: (their logarithm is dominated by noise).
_FIT_FLOOR = 1e-2
#: Number of coefficients of the 2D quadratic fitted to the log-heatmap.
_N_COEFFS = 6
#: Fewest pixels the fit needs: 6 would fit the noise exactly; 9 leaves some redundancy.
_MIN_FIT_PIXELS = 9
#: Pixels within this many noise standard deviations of zero are left out too.
_NOISE_SIGMAS = 3.0
#: Re-fits without pixels whose weighted residual exceeds this many noise sigmas.
_OUTLIER_SIGMAS = 4.0
_OUTLIER_PASSES = 3
#: Noise level assumed at least (relative to the peak) when rejecting outliers.
_MIN_NOISE = 1e-3


@dataclass(frozen=True)
class DecodedKeypoints:
    """Keypoints decoded from a heatmap stack, in image pixels.

    Attributes:
        uv: (K, 2) pixels ``(u, v)`` (OpenCV convention); NaN where not found.
        confidence: (K,) in [0, 1]: the heatmap's peak value, clipped; 0 where
            not found (peak below ``min_confidence``).
        covariance: (K, 2, 2) pixel covariances (px^2) from the heatmaps'
            spread; NaN blocks where not found.
    """

    uv: np.ndarray
    confidence: np.ndarray
    covariance: np.ndarray


def decode_heatmaps(
    heatmaps: np.ndarray,
    roi: tuple[float, float, float, float] | None = None,
    min_confidence: float = 0.05,
    window: int = 3,
) -> DecodedKeypoints:
    """Decodes keypoint heatmaps to image pixels, confidences and covariances.

    Per heatmap:

    1. Peak: the arg-max pixel; ``confidence`` is its value clipped to [0, 1].
       Below ``min_confidence`` the keypoint counts as not found (confidence 0,
       ``uv`` and covariance NaN).
    2. Sub-pixel peak and covariance: a weighted least-squares fit of a 2D
       quadratic ``q(d) = a + g.d + 0.5 d^T H d`` to ``log h`` over the pixels
       of the ``(2*window+1)^2`` window around the arg-max that are connected
       to it and above a floor (1% of the peak, and 3 noise sigmas; the noise
       is the heatmap's robust spread, 1.4826 * MAD). Each row is weighted by
       ``h / peak``, the inverse standard deviation of ``log h`` under additive
       noise; pixels the fit cannot explain (over 4 noise sigmas) are dropped
       one at a time and the fit redone. The peak is at ``d* = -H^-1 g`` and
       the covariance is ``-H^-1``, the inverse Hessian of the log-heatmap (the
       Laplace approximation).

       Why this and not a weighted centroid / second moments: for a Gaussian
       heatmap ``h = A exp(-0.5 (x-mu)^T S^-1 (x-mu))`` the log is exactly
       quadratic, so the fit returns ``mu`` and ``S`` exactly, whatever the
       sub-pixel offset, anisotropy or rotation, and whether or not the window
       contains the whole blob; moments in a window are biased by its
       truncation and by any floor, and a centroid is pulled toward the window's
       centre. Only the peak's neighbourhood is used, so a second blob further
       away (another vehicle) does not bias it.
    3. Fallback, when the fit is ill-posed (fewer than 9 usable pixels, as for
       blobs sharper than ~0.6 heatmap px or drowned in noise; a flat top; a
       Hessian that is not negative definite; or a fitted peak farther from the
       arg-max, in Mahalanobis distance, than sampling and noise allow):
       weighted centroid and second moments of the clipped heatmap in the 3x3
       neighbourhood, plus the 1/12 px^2 variance of pixel quantisation. This is
       coarser (errors of ~0.2 heatmap px).
    4. Mapping to image pixels with the ROI (see the module docstring): ``uv =
       (x0, y0) + (xy + 0.5) * (sx, sy) - 0.5`` and covariance ``J S J^T`` with
       ``J = diag(sx, sy)``.

    Args:
        heatmaps: (K, H, W) stack (K = 12 for vehicles, fixed keypoint order) or
            a single (H, W) heatmap; real numbers, finite. Values are expected
            in [0, 1] on a ~0 background, as networks trained on Gaussian
            targets output them.
        roi: ``(x0, y0, x1, y1)`` box the heatmaps cover, in image pixel edges
            (``x1 > x0``, ``y1 > y0``). ``None``: results stay in heatmap pixel
            coordinates (the same as a ROI ``(0, 0, W, H)``).
        min_confidence: peaks below this value are "not found".
        window: half-size of the fitting window, heatmap pixels (>= 1).

    Returns:
        :class:`DecodedKeypoints` with ``uv`` (K, 2), ``confidence`` (K,) and
        ``covariance`` (K, 2, 2); for a single (H, W) heatmap the leading axis
        is dropped: (2,), () and (2, 2).

    Raises:
        ValueError: wrong shape or dtype, non-finite values, bad ROI or window.

    Example:
        >>> h = render_gaussian_heatmap([10.3, 7.6], [[2.0, 0.5], [0.5, 1.0]], (24, 32))
        >>> d = decode_heatmaps(h)
        >>> np.round(d.uv, 6).tolist(), np.round(d.covariance, 6).tolist()
        ([10.3, 7.6], [[2.0, 0.5], [0.5, 1.0]])
    """
    stack = np.asarray(heatmaps)
    single = stack.ndim == 2
    if single:
        stack = stack[None]
    if stack.ndim != 3 or 0 in stack.shape:
        raise ValueError(f"heatmaps: expected shape (K, H, W) or (H, W), got {np.shape(heatmaps)}")
    if (
        stack.dtype == bool
        or not np.issubdtype(stack.dtype, np.number)
        or np.issubdtype(stack.dtype, np.complexfloating)
    ):
        raise ValueError(f"heatmaps: expected real numbers, got dtype {stack.dtype}")
    stack = stack.astype(float, copy=False)
    if not np.all(np.isfinite(stack)):
        raise ValueError("heatmaps: contains NaN or infinite values")
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
        raise ValueError(f"window: expected an integer >= 1, got {window!r}")
    if not np.isfinite(min_confidence) or min_confidence < 0:
        raise ValueError(f"min_confidence: expected a number >= 0, got {min_confidence!r}")
    n, h, w = stack.shape
    scale, offset = _roi_affine(roi, (h, w))

    uv = np.full((n, 2), np.nan)
    confidence = np.zeros(n)
    covariance = np.full((n, 2, 2), np.nan)
    for k in range(n):
        found = _decode_one(stack[k], min_confidence, int(window))
        if found is None:
            continue
        xy, cov, conf = found
        uv[k] = xy * scale + offset
        covariance[k] = cov * np.outer(scale, scale)
        confidence[k] = conf
    if single:
        return DecodedKeypoints(uv[0], confidence[0], covariance[0])
    return DecodedKeypoints(uv, confidence, covariance)


def render_gaussian_heatmap(
    uv_heatmap,
    covariance,
    shape: tuple[int, int],
    peak: float = 1.0,
) -> np.ndarray:
    """Renders ``peak * exp(-0.5 (x - mu)^T S^-1 (x - mu))`` on a heatmap grid.

    Args:
        uv_heatmap: (2,) centre ``mu = (x, y)`` in heatmap pixel coordinates
            (pixel ``[row, col]`` has its centre at ``(col, row)``); may be
            off-grid and outside the heatmap.
        covariance: (2, 2) symmetric positive-definite ``S``, heatmap px^2.
        shape: ``(H, W)`` of the heatmap.
        peak: value at the centre.

    Returns:
        (H, W) float64 heatmap.

    Raises:
        ValueError: bad centre, covariance or shape.
    """
    mu = np.asarray(uv_heatmap, dtype=float)
    S = np.asarray(covariance, dtype=float)
    if mu.shape != (2,) or not np.all(np.isfinite(mu)):
        raise ValueError(f"uv_heatmap: expected 2 finite numbers, got {uv_heatmap!r}")
    _check_covariance(S, "covariance")
    if len(shape) != 2 or not all(isinstance(s, (int, np.integer)) and s > 0 for s in shape):
        raise ValueError(f"shape: expected (H, W) positive integers, got {shape!r}")
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    d = np.stack([cols - mu[0], rows - mu[1]], axis=-1)
    P = np.linalg.inv(S)
    m = np.einsum("...i,ij,...j->...", d, P, d)
    return float(peak) * np.exp(-0.5 * m)


def heatmap_to_image(xy_heatmap, roi, shape: tuple[int, int]) -> np.ndarray:
    """Maps heatmap pixel coordinates to image pixels (OpenCV centre convention).

    ``u = x0 + (x + 0.5) * sx - 0.5`` with ``sx = (x1 - x0) / W``, likewise for
    ``v``; see the module docstring.

    Args:
        xy_heatmap: (..., 2) heatmap coordinates ``(x, y)`` (``x`` = column).
        roi: ``(x0, y0, x1, y1)`` box the heatmap covers, image pixel edges;
            ``None`` for the identity.
        shape: ``(H, W)`` of the heatmap.

    Returns:
        (..., 2) image pixels ``(u, v)``.
    """
    scale, offset = _roi_affine(roi, shape)
    return np.asarray(xy_heatmap, dtype=float) * scale + offset


def image_to_heatmap(uv_image, roi, shape: tuple[int, int]) -> np.ndarray:
    """Inverse of :func:`heatmap_to_image`: image pixels to heatmap coordinates.

    Use it to place training targets: ``render_gaussian_heatmap(image_to_heatmap(uv,
    roi, shape), S / outer(s, s), shape)``.
    """
    scale, offset = _roi_affine(roi, shape)
    return (np.asarray(uv_image, dtype=float) - offset) / scale


# ----------------------------------------------------------------- internals
def _roi_affine(roi, shape) -> tuple[np.ndarray, np.ndarray]:
    """Scale ``s`` and offset ``o`` such that image = heatmap * s + o."""
    h, w = int(shape[0]), int(shape[1])
    if roi is None:
        return np.ones(2), np.zeros(2)
    try:
        box = np.asarray(roi, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"roi: expected [x0, y0, x1, y1] numbers, got {roi!r}") from None
    if box.shape != (4,) or not np.all(np.isfinite(box)) or box[2] <= box[0] or box[3] <= box[1]:
        raise ValueError(f"roi: expected [x0, y0, x1, y1] finite with x1 > x0 and y1 > y0, got {roi!r}")
    scale = np.array([(box[2] - box[0]) / w, (box[3] - box[1]) / h])
    offset = box[:2] + 0.5 * scale - 0.5
    return scale, offset


def _check_covariance(S: np.ndarray, name: str) -> None:
    if S.shape != (2, 2) or not np.all(np.isfinite(S)):
        raise ValueError(f"{name}: expected a finite 2x2 matrix, got {S.tolist()}")
    if abs(S[0, 1] - S[1, 0]) > 1e-9 * np.abs(S).max():
        raise ValueError(f"{name}: expected a symmetric matrix, got {S.tolist()}")
    if S[0, 0] <= 0 or np.linalg.det(S) <= 0:
        raise ValueError(f"{name}: expected a positive-definite matrix, got {S.tolist()}")


def _decode_one(h: np.ndarray, min_confidence: float, window: int):
    """Peak ``(x, y)``, covariance (heatmap px) and confidence of one heatmap, or None."""
    row, col = np.unravel_index(int(np.argmax(h)), h.shape)
    peak = float(h[row, col])
    if peak <= 0 or peak < min_confidence:
        return None
    confidence = min(peak, 1.0)
    noise = _noise_level(h)
    floor = max(_FIT_FLOOR * peak, _NOISE_SIGMAS * noise)
    fit = _fit_log_quadratic(h, row, col, peak, window, floor, noise)
    if fit is None:
        fit = _moments(h, row, col)
    delta, cov = fit
    return np.array([col, row], dtype=float) + delta, cov, confidence


def _noise_level(h: np.ndarray) -> float:
    """Robust standard deviation of the heatmap's values (1.4826 * MAD), ~0 for a clean heatmap."""
    med = np.median(h)
    return float(1.4826 * np.median(np.abs(h - med)))


def _fit_log_quadratic(h, row, col, peak, window, floor, noise):
    """Offset of the peak from (col, row) and -H^-1 from a log-quadratic fit; None if ill-posed."""
    r0, r1 = max(row - window, 0), min(row + window + 1, h.shape[0])
    c0, c1 = max(col - window, 0), min(col + window + 1, h.shape[1])
    patch = h[r0:r1, c0:c1] / peak
    dy, dx = np.mgrid[r0 - row : r1 - row, c0 - col : c1 - col]
    use = _connected(patch > floor / peak, row - r0, col - c0)
    x, y, z = dx[use].astype(float), dy[use].astype(float), patch[use]
    A = np.stack([np.ones_like(x), x, y, 0.5 * x * x, x * y, 0.5 * y * y], axis=1)
    # Weight h / peak: std(log h) ~ noise / h, so the weighted residuals are ~ noise / peak.
    Aw, bw = A * z[:, None], np.log(z) * z
    keep = np.ones(len(z), dtype=bool)
    for _ in range(1 + _OUTLIER_PASSES):
        if np.count_nonzero(keep) < _MIN_FIT_PIXELS:
            return None
        coeffs, _, rank, _ = np.linalg.lstsq(Aw[keep], bw[keep], rcond=None)
        if rank < _N_COEFFS or noise <= 0:
            break
        # Drop pixels whose value the fit cannot explain (isolated noise spikes above the floor).
        # One at a time, the worst first, and only while enough pixels remain.
        residual = np.where(keep, np.abs(Aw @ coeffs - bw), 0.0)
        worst = int(np.argmax(residual))
        if residual[worst] <= _OUTLIER_SIGMAS * max(noise, _MIN_NOISE * peak) / peak:
            break
        if np.count_nonzero(keep) <= _MIN_FIT_PIXELS:
            break
        keep[worst] = False
    if rank < _N_COEFFS:
        return None
    _, gx, gy, hxx, hxy, hyy = coeffs
    P = -np.array([[hxx, hxy], [hxy, hyy]])  # information matrix, heatmap px^-2
    if P[0, 0] <= 0 or np.linalg.det(P) <= 0:
        return None
    cov = np.linalg.inv(P)
    cov = 0.5 * (cov + cov.T)
    delta = cov @ np.array([gx, gy])
    if not np.all(np.isfinite(delta)):
        return None
    # The arg-max pixel must be (nearly) the grid point closest to the fitted peak in
    # Mahalanobis distance: at most as far as a pixel corner (+-0.5, +-0.5), plus what
    # the noise can move the arg-max (a drop of _OUTLIER_SIGMAS noise sigmas).
    corner = 0.25 * (P[0, 0] + P[1, 1]) + 0.5 * abs(P[0, 1])
    slack = -2.0 * np.log(1.0 - min(0.9, _OUTLIER_SIGMAS * max(noise, _MIN_NOISE * peak) / peak))
    if delta @ P @ delta > corner + slack:
        return None
    return delta, cov


def _connected(mask: np.ndarray, row: int, col: int) -> np.ndarray:
    """The 8-connected part of ``mask`` that holds ``(row, col)`` (a small flood fill)."""
    out = np.zeros_like(mask)
    out[row, col] = True
    stack = [(row, col)]
    while stack:
        r, c = stack.pop()
        for rr in range(max(r - 1, 0), min(r + 2, mask.shape[0])):
            for cc in range(max(c - 1, 0), min(c + 2, mask.shape[1])):
                if mask[rr, cc] and not out[rr, cc]:
                    out[rr, cc] = True
                    stack.append((rr, cc))
    return out


def _moments(h, row, col):
    """Weighted centroid offset and second moments in the 3x3 neighbourhood (+1/12 px^2)."""
    r0, r1 = max(row - 1, 0), min(row + 2, h.shape[0])
    c0, c1 = max(col - 1, 0), min(col + 2, h.shape[1])
    wts = np.clip(h[r0:r1, c0:c1], 0.0, None)
    dy, dx = np.mgrid[r0 - row : r1 - row, c0 - col : c1 - col]
    wts = wts / wts.sum()
    mean = np.array([(wts * dx).sum(), (wts * dy).sum()])
    ex, ey = dx - mean[0], dy - mean[1]
    cov = np.array([[(wts * ex * ex).sum(), (wts * ex * ey).sum()], [(wts * ex * ey).sum(), (wts * ey * ey).sum()]])
    return mean, cov + np.eye(2) / 12.0


#: How far :func:`extend_clipped_roi` grows a box that stops at the image border beyond it, as a share of the box's
#: width (a left or right border) or height (top or bottom). The network was trained on boxes of the whole vehicle
#: (amodal), which reach beyond the image where it cuts the vehicle; a 2D detector's box stops at the border, and
#: there the network put the keypoints it cannot see inside that box (PCK@0.1 of cut vehicles' keypoints 0.23-0.56 on
#: five rendered track scenes, 0.37-0.67 with the box grown by this share; docs/network.md, "Boxes clipped by the
#: image border"). The keypoint network's detector (vfactor.net.infer) and its training crops (vfactor.render) use it.
CLIPPED_EXTENSION = 0.25


def extend_clipped_roi(roi, width: int, height: int, extension: float = CLIPPED_EXTENSION) -> tuple:
    """A box that stops at the border of a ``width x height`` image (an edge within a pixel of it: a 2D detector's
    box clipped by the image) grown beyond that border by ``extension`` times its width or height; other boxes, and
    edges inside the image or already beyond it, as they are.

    Args:
        roi: ``(x0, y0, x1, y1)``, pixel edges (the image spans ``-0.5 .. width - 0.5``).
        extension: share of the box's side (>= 0; 0 keeps every box).
    """
    x0, y0, x1, y1 = (float(v) for v in roi)
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f"roi: expected (x0, y0, x1, y1) with x1 > x0 and y1 > y0, got {roi!r}")
    if not np.isfinite(extension) or extension < 0:
        raise ValueError(f"extension: expected a number >= 0, got {extension!r}")
    w, h = (x1 - x0) * extension, (y1 - y0) * extension
    left, top, right, bottom = edges_at_border(roi, width, height)
    return (x0 - w if left else x0, y0 - h if top else y0, x1 + w if right else x1, y1 + h if bottom else y1)


def edges_at_border(roi, width: int, height: int) -> tuple[bool, bool, bool, bool]:
    """Which edges of a box ``(x0, y0, x1, y1)`` (pixel edges) lie within a pixel of the border of a ``width x
    height`` image (whose pixel edges span ``-0.5 .. width - 0.5``): left, top, right, bottom. A 2D detector's box
    of a vehicle the image border cuts stops there."""
    x0, y0, x1, y1 = (float(v) for v in roi)
    return (abs(x0 + 0.5) <= 1.0, abs(y0 + 0.5) <= 1.0, abs(x1 - (width - 0.5)) <= 1.0,
            abs(y1 - (height - 0.5)) <= 1.0)


def clipped_by_border(roi, image_size) -> bool:
    """Whether a box ``(x0, y0, x1, y1)`` (pixel edges) stops at the border of an image of ``(width, height)``
    pixels (:func:`edges_at_border`): a 2D detector's box of a vehicle the border cuts."""
    return any(edges_at_border(roi, *image_size))


def clip_roi_to_image(roi, width: int, height: int) -> np.ndarray:
    """(4,) the box ``(x0, y0, x1, y1)`` (pixel edges) clipped to a ``width x height`` image, whose pixel edges span
    ``-0.5 .. width - 0.5``: what a 2D detector gives of a vehicle the image border cuts."""
    return np.clip(np.asarray(roi, dtype=float), -0.5, [width - 0.5, height - 0.5, width - 0.5, height - 0.5])
