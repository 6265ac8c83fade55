"""Crops of a region of interest resized to the network's input (numpy and OpenCV only, no torch).

Conventions are those of :mod:`vfactor.heatmaps`: image pixel ``(u, v)`` has
its centre at integer coordinates; a ROI ``(x0, y0, x1, y1)`` is given by its
pixel *edges*. A crop of side ``S`` of the ROI maps image pixel ``u`` to crop
pixel ``c = (u - x0 + 0.5) / sx - 0.5`` with ``sx = (x1 - x0) / S`` (the same
affine map as :func:`vfactor.heatmaps.image_to_heatmap` with shape ``(S, S)``).
"""

from __future__ import annotations

import cv2
import numpy as np

from vfactor.heatmaps import heatmap_to_image, image_to_heatmap

__all__ = ["crop_roi", "expand_roi", "image_to_crop", "crop_to_image", "check_roi_in_image", "MIN_ROI_INSIDE"]

#: Least fraction of a given box's area that must lie inside the image (docs/reliability.md). A box may reach
#: outside (a vehicle at the border: zero padding, as in training), but a box mostly or wholly outside holds no
#: vehicle, and a huge one (``--roi 0 0 1e7 1e7``) would make a crop buffer of terabytes.
MIN_ROI_INSIDE = 0.25


def check_roi_in_image(roi, width: int, height: int) -> tuple[float, float, float, float]:
    """Checks that a box lies enough inside a ``width x height`` image; returns it as floats.

    Raises:
        ValueError: the box is malformed, or less than :data:`MIN_ROI_INSIDE` of its area (or less than one
            pixel across) lies inside the image; the message says how much does.
    """
    x0, y0, x1, y1 = _check_roi(roi)
    w, h = min(x1, width) - max(x0, 0.0), min(y1, height) - max(y0, 0.0)
    inside = max(w, 0.0) * max(h, 0.0) / ((x1 - x0) * (y1 - y0))
    if w < 1 or h < 1 or not inside >= MIN_ROI_INSIDE:
        raise ValueError(f"the box [{x0:g}, {y0:g}, {x1:g}, {y1:g}] leaves the {width}x{height} image: "
                         f"{inside:.2%} of it is inside, at least {MIN_ROI_INSIDE:.0%} (and a pixel across) is needed")
    return x0, y0, x1, y1


def expand_roi(roi, margin: float = 0.0, square: bool = False) -> tuple[float, float, float, float]:
    """Grows a box about its centre: each side by ``margin`` times its length, then to a square.

    Args:
        roi: ``(x0, y0, x1, y1)``, pixel edges, ``x1 > x0``, ``y1 > y0``.
        margin: fraction of the width (height) added on the left and on the
            right (top and bottom); 0.1 makes a box 20% wider and taller.
        square: then grow the shorter side to the longer one.

    Returns:
        The new ``(x0, y0, x1, y1)`` (floats).
    """
    x0, y0, x1, y1 = _check_roi(roi)
    if not np.isfinite(margin) or margin < 0:
        raise ValueError(f"margin: expected a number >= 0, got {margin!r}")
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    w, h = (x1 - x0) * (1 + 2 * margin), (y1 - y0) * (1 + 2 * margin)
    if square:
        w = h = max(w, h)
    return (cx - 0.5 * w, cy - 0.5 * h, cx + 0.5 * w, cy + 0.5 * h)


def crop_roi(image: np.ndarray, roi, size: int, integer_roi: bool = True) -> tuple[np.ndarray, tuple]:
    """Resamples the ROI of an image to a ``size x size`` crop.

    The box may reach outside the image (zero padding there). When
    ``integer_roi`` (default) the ROI is first rounded outwards to whole pixel
    edges, so that shrinking can use area averaging (``cv2.INTER_AREA``, no
    aliasing); enlarging uses bilinear interpolation. The ROI actually used is
    returned: decode heatmaps of the crop with it.

    Args:
        image: (H, W, 3) or (H, W) image (any dtype OpenCV resizes, e.g. uint8).
        roi: ``(x0, y0, x1, y1)`` pixel edges.
        size: side of the square crop, pixels.
        integer_roi: round the ROI outwards to integers (else bilinear warp of
            the exact box).

    Returns:
        ``(crop, roi_used)``: the (size, size[, 3]) crop, same dtype as the image,
        and the box ``(x0, y0, x1, y1)`` that it covers.
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3) or 0 in img.shape[:2]:
        raise ValueError(f"image: expected shape (H, W, 3) or (H, W), got {img.shape}")
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 1:
        raise ValueError(f"size: expected a positive integer, got {size!r}")
    x0, y0, x1, y1 = _check_roi(roi)
    if integer_roi:
        x0, y0, x1, y1 = float(np.floor(x0)), float(np.floor(y0)), float(np.ceil(x1)), float(np.ceil(y1))
        ix0, iy0, ix1, iy1 = int(x0), int(y0), int(x1), int(y1)
        H, W = img.shape[:2]
        region = np.zeros((iy1 - iy0, ix1 - ix0) + img.shape[2:], dtype=img.dtype)
        sx0, sy0, sx1, sy1 = max(ix0, 0), max(iy0, 0), min(ix1, W), min(iy1, H)
        if sx1 > sx0 and sy1 > sy0:
            region[sy0 - iy0 : sy1 - iy0, sx0 - ix0 : sx1 - ix0] = img[sy0:sy1, sx0:sx1]
        shrink = region.shape[0] >= size and region.shape[1] >= size
        crop = cv2.resize(region, (int(size), int(size)), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    else:
        sx, sy = (x1 - x0) / size, (y1 - y0) / size
        # crop pixel c <- image u = x0 + (c + 0.5) sx - 0.5
        M = np.array([[sx, 0.0, x0 + 0.5 * sx - 0.5], [0.0, sy, y0 + 0.5 * sy - 0.5]])
        crop = cv2.warpAffine(
            img, M, (int(size), int(size)), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_CONSTANT, borderValue=0,
        )
    return crop, (x0, y0, x1, y1)


def image_to_crop(uv, roi, size: int) -> np.ndarray:
    """Image pixels ``(..., 2)`` to pixels of a ``size x size`` crop of ``roi``."""
    return image_to_heatmap(uv, roi, (size, size))


def crop_to_image(xy, roi, size: int) -> np.ndarray:
    """Pixels ``(..., 2)`` of a ``size x size`` crop of ``roi`` to image pixels."""
    return heatmap_to_image(xy, roi, (size, size))


def _check_roi(roi) -> tuple[float, float, float, float]:
    try:
        box = np.asarray(roi, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"roi: expected (x0, y0, x1, y1) numbers, got {roi!r}") from None
    if box.shape != (4,) or not np.all(np.isfinite(box)) or box[2] <= box[0] or box[3] <= box[1]:
        raise ValueError(f"roi: expected (x0, y0, x1, y1) finite with x1 > x0 and y1 > y0, got {roi!r}")
    return tuple(float(b) for b in box)
