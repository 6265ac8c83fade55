"""Image files as the keypoint network and the overlays take them: 8-bit RGB, whatever the file's depth.

Roadside and industrial cameras often record 10, 12 or 14 bits per pixel,
stored in 16-bit PNG or TIFF files. OpenCV's ``IMREAD_COLOR`` keeps the top 8
of the 16 bits, so 12-bit data (0-4095) came out almost black (0-15).
:func:`read_rgb` scales a 16-bit image by the bit depth its data use: the
smallest of 10, 12, 14 and 16 bits that holds its largest value (a 12-bit
image's 4095 becomes 255). It is a property of each image, so a dark frame of
a camera whose other frames use 12 bits may be read as 10-bit (brighter);
the network is trained on images of many exposures. Grey images become three
equal channels, an alpha channel is dropped, and a floating-point image
(OpenEXR, float TIFF) is read as 0-1 (clipped). EXIF orientation is applied,
as ``IMREAD_COLOR`` does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["read_rgb", "to_uint8", "SIXTEEN_BIT_DEPTHS"]

#: The bit depths a 16-bit image's data may use; the smallest that holds its largest value is taken.
SIXTEEN_BIT_DEPTHS = (10, 12, 14, 16)


def to_uint8(image: np.ndarray) -> np.ndarray:
    """An image of any depth as 8 bits (see the module's docstring); an 8-bit image is returned as it is."""
    image = np.asarray(image)
    if image.dtype == np.uint8:
        return image
    if image.dtype == np.uint16:
        top = int(image.max()) if image.size else 0
        bits = next((b for b in SIXTEEN_BIT_DEPTHS if top < 2 ** b), 16)
        return np.rint(image.astype(np.float32) * (255.0 / (2 ** bits - 1))).astype(np.uint8)
    if np.issubdtype(image.dtype, np.floating):
        return np.rint(np.clip(np.nan_to_num(image.astype(np.float32)), 0.0, 1.0) * 255.0).astype(np.uint8)
    raise ValueError(f"unsupported pixel type {image.dtype} (expected 8- or 16-bit integers or floating point)")


def read_rgb(path: str | Path) -> np.ndarray | None:
    """The image file at ``path`` as (H, W, 3) uint8 RGB, or None when OpenCV cannot decode it.

    Raises:
        OSError: the file cannot be read.
        ValueError: a pixel type other than 8- or 16-bit integers or floating point (32-bit integers).
    """
    import cv2  # noqa: PLC0415  (imported where an image is read: import vfactor stays free of OpenCV's GUI)

    # decoded from its bytes: OpenCV's imread prints a warning of its own for a file it cannot read
    data = np.fromfile(str(path), np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR) if data.size else None
    if image is None:
        return None
    image = to_uint8(image)
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    return np.ascontiguousarray(image[..., ::-1])
