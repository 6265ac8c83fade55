"""Pictures of what the cameras saw and what vfactor estimated.

Two kinds of output:

- Raster overlays in a camera's image (``cv2``, BGR ``uint8``):
  :func:`draw_view` draws a stand-in for the camera image when there is no
  photo (sky, the road plane ``z = 0`` with a 1 m grid), :func:`draw_overlay`
  draws the observed keypoints, the estimated and the true wireframes and the
  heatmaps on top of it (or of a photo), :func:`write_overlays` writes one such
  picture per camera for a frame.
- A figure of the estimates (``matplotlib``, PNG): :func:`plot_estimates`
  shows the camera rig and the vehicles in 3D, a top-down view of the vehicles
  with their position-covariance ellipses, and one panel per vehicle with the
  ellipse at its true size in centimetres; :func:`plot_trajectories` shows
  tracking results over many frames: each track's trajectory with heading
  arrows and position ellipses, and its uncertainty (and error, given the
  truth) against time, beside the frame-by-frame estimates.

Everything is projected with :meth:`vfactor.camera.Camera.project`, so lens
distortion is honoured; points behind a camera (depth below 0.1 m) are never
drawn. Matplotlib is used through its Agg canvas directly: importing vfactor or
calling these functions never changes the pyplot backend of the caller.

Colours are fixed across all pictures: wheel layer orange, light layer cyan,
roof layer magenta; the true wireframe dashed white on dark (raster) or dashed
black (figures); observed keypoints coloured red (low confidence) to green
(high confidence).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import cv2
import gtsam
import numpy as np

from vfactor.camera import Camera
from vfactor.images import read_rgb
from vfactor.keypoints import NUM_KEYPOINTS, WIREFRAME_EDGES, layer_of
from vfactor.observations import Detection, Frame, resolve_path
from vfactor.result import VehicleResult
from vfactor.wireframe import Wireframe

log = logging.getLogger(__name__)

__all__ = [
    "LAYER_COLORS_BGR",
    "LAYER_COLORS_RGB",
    "draw_view",
    "draw_overlay",
    "position_covariance_world",
    "plot_estimates",
    "plot_trajectories",
    "write_overlays",
]

#: Colour of each wireframe layer in raster overlays (BGR, 0..255).
LAYER_COLORS_BGR: dict[str, tuple[int, int, int]] = {
    "wheel": (0, 140, 255),
    "light": (216, 180, 0),
    "roof": (160, 48, 210),
}

#: The same colours for matplotlib (RGB, 0..1).
LAYER_COLORS_RGB: dict[str, tuple[float, float, float]] = {
    name: (b[2] / 255.0, b[1] / 255.0, b[0] / 255.0) for name, b in LAYER_COLORS_BGR.items()
}

_NEAR = 0.1  # metres: nearest depth drawn
_MAX_SIDE_PANELS = 12
#: Overlays write each observed keypoint's index only up to this many vehicles in a frame (beyond, they clutter).
_MAX_NUMBERED_VEHICLES = 3
_SKY_TOP = np.array([200.0, 140.0, 80.0])  # BGR
_SKY_HORIZON = np.array([235.0, 215.0, 190.0])
_GROUND = np.array([105.0, 105.0, 105.0])
_GROUND_HAZE = np.array([175.0, 170.0, 165.0])
_GRID = np.array([205.0, 205.0, 205.0])
_TRUTH_BGR = (255, 255, 255)
_ELLIPSE_RGB = (0.84, 0.10, 0.16)
_EDGE_SAMPLES = 12  # points per wireframe edge (distortion bends straight edges)


# ----------------------------------------------------------------- projection
def _resolve_size(camera: Camera, image_size=None) -> tuple[int, int]:
    """(width, height) from the argument, the camera, or the principal point."""
    if image_size is not None:
        w, h = image_size
    elif camera.image_size is not None:
        w, h = camera.image_size
    else:
        # The principal point of an ideal camera is the image centre: cx = (W - 1) / 2.
        w, h = int(round(2 * camera.K[0, 2] + 1)), int(round(2 * camera.K[1, 2] + 1))
    w, h = int(w), int(h)
    if w <= 0 or h <= 0:
        raise ValueError(f"image_size: expected positive (width, height), got {(w, h)}")
    return w, h


def _max_valid_r2(camera: Camera, size: tuple[int, int]) -> float:
    """Largest squared normalised radius that projects without the distortion folding back.

    A polynomial lens model is only monotonic out to some radius; points beyond
    it land back inside the image at wrong places. We accept radii up to 1.5x
    the image corners' radius, and never beyond the first turning point of
    ``r_d(r)``.
    """
    if not camera.has_distortion:
        return math.inf
    w, h = size
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=float)
    r_corner = float(np.sqrt((camera.undistort_pixels(corners) ** 2).sum(1)).max())
    r = np.linspace(0.0, 3.0 * max(r_corner, 1e-3), 3001)
    r_d = _distorted_radius(camera, r)
    turning = np.nonzero(np.diff(r_d) <= 0)[0]
    r_max = 1.5 * r_corner
    if len(turning):
        r_max = min(r_max, r[turning[0]])
    return r_max * r_max


def _distorted_radius(camera: Camera, r: np.ndarray) -> np.ndarray:
    """The lens's radial map: distorted normalised radius of normalised radii ``r`` (tangential,
    thin-prism and tilt terms left out).

    Pinhole: ``r (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)``; fisheye:
    ``theta_d(atan r)`` (docs/conventions.md).
    """
    d = camera.kernel_lens()[1]
    r2 = r * r
    if camera.model == "fisheye":
        theta = np.arctan(r)
        t2 = theta * theta
        return theta * (1 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))))
    k1, k2, k3, k4, k5, k6 = d[0], d[1], d[4], d[5], d[6], d[7]
    return r * (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))


def _project_valid(camera: Camera, world_p: np.ndarray, size: tuple[int, int], r2_max: float):
    """Projects world points; returns uv (N, 2), depth (N,) and a mask of drawable points."""
    camera_p = camera.to_camera(np.asarray(world_p, dtype=float).reshape(-1, 3))
    depth = camera_p[:, 2]
    valid = depth > _NEAR
    uv = np.full((len(camera_p), 2), np.nan)
    if np.any(valid):
        c = camera_p[valid]
        uv[valid], _ = camera.project_camera_points(c, jacobian=False)
        r2 = (c[:, 0] ** 2 + c[:, 1] ** 2) / c[:, 2] ** 2
        ok = r2 <= r2_max
        idx = np.nonzero(valid)[0]
        valid[idx[~ok]] = False
    w, h = size
    with np.errstate(invalid="ignore"):
        valid &= (np.abs(uv[:, 0] - w / 2) < 2 * w) & (np.abs(uv[:, 1] - h / 2) < 2 * h)
    return uv, depth, valid


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in a 1-D mask."""
    m = np.concatenate([[False], mask.astype(bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]))


def _edge_polylines(camera, points_world, size, r2_max, edges=WIREFRAME_EDGES):
    """For each edge (i, j): a list of (M, 2) pixel polylines of its drawable parts."""
    points_world = np.asarray(points_world, dtype=float)
    t = np.linspace(0.0, 1.0, _EDGE_SAMPLES)[:, None]
    out = []
    for i, j in edges:
        samples = points_world[i] * (1 - t) + points_world[j] * t
        uv, _, valid = _project_valid(camera, samples, size, r2_max)
        out.append(((i, j), [uv[a:b] for a, b in _runs(valid) if b - a >= 2]))
    return out


# -------------------------------------------------------------------- drawing
_SHIFT = 4  # sub-pixel bits for cv2 drawing


def _fixed(uv: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(uv) * (1 << _SHIFT)).astype(np.int32)


def _polyline(img, uv, colour, thickness=1):
    if len(uv) >= 2:
        cv2.polylines(img, [_fixed(uv).reshape(-1, 1, 2)], False, colour, thickness, cv2.LINE_AA, _SHIFT)


def _dashed(img, uv, colour, thickness=1, dash=9.0, gap=6.0, outline=None):
    """Draws a dashed polyline (the dash pattern runs along its arc length)."""
    uv = np.asarray(uv, dtype=float)
    if len(uv) < 2:
        return
    seg = np.linalg.norm(np.diff(uv, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] < 1e-6:
        return
    n = max(int(s[-1]), 2)
    si = np.linspace(0.0, s[-1], n + 1)
    pts = np.stack([np.interp(si, s, uv[:, 0]), np.interp(si, s, uv[:, 1])], axis=1)
    on = (si % (dash + gap)) < dash
    for a, b in _runs(on):
        if b - a >= 2:
            if outline is not None:
                _polyline(img, pts[a:b], outline, thickness + 2)
            _polyline(img, pts[a:b], colour, thickness)


def _text(img, text, org, scale=0.5, colour=(255, 255, 255), thickness=1):
    """Text with a dark outline, readable on any background."""
    org = (int(round(org[0])), int(round(org[1])))
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thickness + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thickness, cv2.LINE_AA)


def _label_box(img, lines, corner="tl", scale=0.6, pad=6, alpha=0.55):
    """A block of text lines on a translucent dark box in a corner of the image."""
    h, w = img.shape[:2]
    sizes = [cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, scale, 1) for t in lines]
    line_h = max(s[0][1] + s[1] for s in sizes) + 4
    box_w = max(s[0][0] for s in sizes) + 2 * pad
    box_h = line_h * len(lines) + 2 * pad
    x0 = pad if corner in ("tl", "bl") else w - pad - box_w
    y0 = pad if corner in ("tl", "tr") else h - pad - box_h
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x0 + box_w, w), min(y0 + box_h, h)
    roi = img[y0:y1, x0:x1]
    roi[:] = (roi * (1 - alpha)).astype(np.uint8)
    for k, t in enumerate(lines):
        baseline_y = y0 + pad + line_h * (k + 1) - 4
        cv2.putText(img, t, (x0 + pad, baseline_y), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return (x0, y0, x1, y1)


def _vehicle_anchor(camera: Camera, size, keypoints_world, detection) -> tuple[float, float] | None:
    """Where a vehicle's label goes in an image: above the middle of its projected estimate, else of its
    observed keypoints; None when neither is in view."""
    if keypoints_world is not None:
        uv, _, valid = _project_valid(camera, _check_points(keypoints_world, "keypoints_world"), size,
                                      _max_valid_r2(camera, size))
        if np.any(valid):
            return float(uv[valid, 0].mean()), float(uv[valid, 1].min())
    if detection is not None:
        kp, conf = np.asarray(detection.keypoints, dtype=float), np.asarray(detection.confidence, dtype=float)
        seen = np.isfinite(conf) & (conf > 0) & np.all(np.isfinite(kp), axis=1)
        if np.any(seen):
            return float(kp[seen, 0].mean()), float(kp[seen, 1].min())
    return None


def _draw_tags(img, tags, scale, placed: list | None = None) -> list:
    """Labels on dark tags above their anchors, moved up (or down at the top edge) until no two overlap.

    Args:
        img: the BGR image, drawn on.
        tags: (text, (u, v) anchor) pairs.
        scale: font scale.
        placed: tag rectangles ``(x0, y0, x1, y1)`` already on the image (extended in place).

    Returns:
        The rectangles of every tag on the image.
    """
    H, W = img.shape[:2]
    placed = [] if placed is None else placed
    font, thick, pad = cv2.FONT_HERSHEY_SIMPLEX, 2, 4
    for text, (u, v) in sorted(tags, key=lambda tag: tag[1][1]):
        (tw, th), base = cv2.getTextSize(text, font, scale * 0.8, thick)
        w, h = tw + 2 * pad, th + base + 2 * pad
        x0 = int(np.clip(u - w / 2, 0, max(W - w, 0)))
        y0 = int(v - 10 - h)
        step = -(h + 2)
        for _ in range(4 * len(placed) + 2):
            if y0 < 0:
                y0, step = int(v + 10), h + 2  # no room above: below the anchor, moving down
            rect = (x0, y0, x0 + w, y0 + h)
            if not any(rect[0] < q[2] and q[0] < rect[2] and rect[1] < q[3] and q[1] < rect[3] for q in placed):
                break
            y0 += step
        y0 = int(np.clip(y0, 0, max(H - h, 0)))
        rect = (x0, y0, x0 + w, y0 + h)
        roi = img[rect[1]:rect[3], rect[0]:rect[2]]
        roi[:] = (roi * 0.25).astype(np.uint8)
        cv2.rectangle(img, rect[:2], (rect[2] - 1, rect[3] - 1), (235, 235, 235), 1, cv2.LINE_AA)
        cv2.putText(img, text, (x0 + pad, y0 + pad + th), font, scale * 0.8, (255, 255, 255), thick, cv2.LINE_AA)
        placed.append(rect)
    return placed


def _font_scale(size: tuple[int, int]) -> float:
    return float(np.clip(min(size) / 900.0, 0.35, 1.2))


def _confidence_colour(c: float) -> tuple[int, int, int]:
    """Red (0) -> yellow (0.5) -> green (1), BGR."""
    c = float(np.clip(c, 0.0, 1.0))
    hsv = np.uint8([[[int(round(60 * c)), 230, 255]]])
    b, g, r = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0]
    return int(b), int(g), int(r)


def _pixel_rays_world(camera: Camera, size: tuple[int, int], step: int = 1):
    """World-frame ray directions of a (sub-sampled) pixel grid, shape (h', w', 3)."""
    w, h = size
    us = np.arange(0, w, step, dtype=float)
    vs = np.arange(0, h, step, dtype=float)
    uu, vv = np.meshgrid(us, vs)
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1)
    if camera.has_distortion:
        xy = camera.undistort_pixels(uv)
    else:
        xy = (uv - camera.K[:2, 2]) @ np.linalg.inv(camera.K[:2, :2]).T
    rays_camera = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    rays_world = rays_camera @ camera.world_T_camera[:3, :3].T
    return rays_world.reshape(len(vs), len(us), 3)


def draw_view(camera: Camera, image_size: tuple[int, int] | None = None, grid_range: float = 80.0) -> np.ndarray:
    """Draws a stand-in for the camera's image: sky, the road plane and a 1 m grid.

    The ground is the plane ``z = 0`` (world frame), shaded grey and fading to a
    haze with distance; the sky shades from pale at the horizon to blue. The
    grid has a line every metre, and a stronger one every 5 m; every line is
    projected with the camera's own model (distortion included), only where it
    lies in front of the camera, and fades out where its lines would crowd
    closer than a few pixels. The camera name is written in the top-left
    corner.

    Args:
        camera: the camera.
        image_size: ``(width, height)`` in pixels; defaults to
            ``camera.image_size``, else to twice the principal point.
        grid_range: grid lines are drawn out to this horizontal distance from
            the camera, metres.

    Returns:
        (H, W, 3) ``uint8`` BGR image.

    Example:
        >>> import numpy as np
        >>> from vfactor.camera import Camera
        >>> T = np.eye(4); T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]; T[2, 3] = 5.0
        >>> cam = Camera("cam0", [[500, 0, 319.5], [0, 500, 239.5], [0, 0, 1]], T, image_size=(640, 480))
        >>> draw_view(cam).shape
        (480, 640, 3)
    """
    size = _resolve_size(camera, image_size)
    w, h = size
    center = camera.center
    rays = _pixel_rays_world(camera, size)
    norm = np.linalg.norm(rays, axis=2)
    dz = rays[..., 2] / norm
    # Ground where the ray meets z = 0 in front of the camera.
    with np.errstate(divide="ignore", invalid="ignore"):
        t_hit = -center[2] / rays[..., 2]
    ground = np.isfinite(t_hit) & (t_hit > 0)
    dist = np.where(ground, t_hit * norm, np.inf)
    haze = 1.0 - np.exp(-dist / 120.0)
    ground_col = _GROUND * (1 - haze[..., None]) + _GROUND_HAZE * haze[..., None]
    elev = np.clip(np.abs(dz), 0.0, 1.0) ** 0.6
    sky_col = _SKY_HORIZON * (1 - elev[..., None]) + _SKY_TOP * elev[..., None]
    img = np.where(ground[..., None], ground_col, sky_col)
    img = np.clip(img, 0, 255).astype(np.uint8)

    if center[2] > 0 and np.any(ground):
        _draw_ground_grid(img, camera, size, grid_range)

    scale = _font_scale(size)
    _label_box(img, [camera.name], corner="tl", scale=scale * 1.1)
    return img


def _draw_ground_grid(img, camera: Camera, size, grid_range: float) -> None:
    """Draws the 1 m / 5 m grid of the plane z = 0 into ``img`` (in place)."""
    w, h = size
    r2_max = _max_valid_r2(camera, size)
    center = camera.center
    # Extent: where a coarse grid of pixel rays meets the ground within range.
    rays = _pixel_rays_world(camera, size, step=max(1, min(w, h) // 40)).reshape(-1, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_hit = -center[2] / rays[:, 2]
    hit = np.isfinite(t_hit) & (t_hit > 0)
    pts = center[:2] + t_hit[hit, None] * rays[hit, :2]
    pts = pts[np.linalg.norm(pts - center[:2], axis=1) <= grid_range]
    if len(pts) == 0:
        return
    lo = np.floor(pts.min(0)) - 1
    hi = np.ceil(pts.max(0)) + 1
    step = 0.1
    layers = {False: np.zeros(img.shape[:2], dtype=np.uint8), True: np.zeros(img.shape[:2], dtype=np.uint8)}
    for axis in (0, 1):  # axis 0: lines x = k, running along y; axis 1: lines y = k
        other = 1 - axis
        ks = np.arange(lo[axis], hi[axis] + 1)
        s = np.arange(lo[other], hi[other] + step / 2, step)
        for k in ks:
            major = int(k) % 5 == 0
            spacing_m = 5.0 if major else 1.0
            line = np.zeros((len(s), 3))
            line[:, axis] = k
            line[:, other] = s
            nxt = line.copy()
            nxt[:, axis] = k + spacing_m
            uv, _, valid = _project_valid(camera, line, size, r2_max)
            uv2, _, valid2 = _project_valid(camera, nxt, size, r2_max)
            horizontal = np.linalg.norm(line[:, :2] - center[:2], axis=1)
            valid &= horizontal <= grid_range
            # Pixel spacing to the neighbouring line: fade lines out where they crowd.
            spacing_px = np.where(valid2, np.linalg.norm(uv2 - uv, axis=1), np.inf)
            spacing_px = np.nan_to_num(spacing_px, nan=0.0)
            alpha = np.clip((spacing_px - 6.0) / 16.0, 0.0, 1.0)
            # ... and with distance, like the ground's haze.
            alpha *= np.exp(-horizontal / 120.0) * np.clip((grid_range - horizontal) / (0.2 * grid_range), 0.0, 1.0)
            level = np.ceil(alpha * 4).astype(int)  # 0..4
            level[~valid] = 0
            for lv in range(1, 5):
                for a, b in _runs(level == lv):
                    a0, b1 = max(a - 1, 0), min(b + 1, len(s))  # overlap the neighbouring runs
                    seg = uv[a0:b1][valid[a0:b1]]
                    _polyline(layers[major], seg, int(64 * lv - 1), 1)
    for major, layer in layers.items():
        a = (layer.astype(float) / 255.0)[..., None] * (0.85 if major else 0.45)
        img[:] = np.clip(img * (1 - a) + _GRID * a, 0, 255).astype(np.uint8)


def _as_bgr(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 2:
        return cv2.cvtColor(img.astype(np.uint8), cv2.COLOR_GRAY2BGR)
    if img.ndim == 3 and img.shape[2] == 3:
        return img.astype(np.uint8, copy=True)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img.astype(np.uint8), cv2.COLOR_BGRA2BGR)
    raise ValueError(f"image: expected shape (H, W), (H, W, 3) or (H, W, 4), got {img.shape}")


def _check_points(points, name: str) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.shape != (NUM_KEYPOINTS, 3):
        raise ValueError(f"{name}: expected shape (12, 3), got {p.shape}")
    return p


def _blend_heatmaps(img, heatmaps, roi) -> None:
    """Blends the per-keypoint maximum of the heatmaps into ``img`` over ``roi`` (in place)."""
    if isinstance(heatmaps, (str, Path)):
        heatmaps = np.load(heatmaps)
    hm = np.asarray(heatmaps, dtype=float)
    if hm.ndim != 3 or hm.shape[0] != NUM_KEYPOINTS:
        raise ValueError(f"heatmaps: expected shape (12, H, W), got {hm.shape}")
    hm = np.nan_to_num(np.clip(hm, 0.0, None))
    peak = hm.reshape(NUM_KEYPOINTS, -1).max(1)
    hm = hm / np.where(peak > 0, peak, 1.0)[:, None, None]
    combined = hm.max(0).astype(np.float32)
    H, W = img.shape[:2]
    if roi is None:
        roi = (0.0, 0.0, float(W), float(H))
    try:
        x0, y0, x1, y1 = (float(v) for v in roi)
    except (TypeError, ValueError):
        raise ValueError(f"roi: expected (x0, y0, x1, y1) numbers, got {roi!r}") from None
    if not (np.isfinite([x0, y0, x1, y1]).all() and x1 > x0 and y1 > y0):
        raise ValueError(f"roi: expected finite (x0, y0, x1, y1) with x1 > x0 and y1 > y0, got {roi!r}")
    hh, ww = combined.shape
    sx, sy = (x1 - x0) / ww, (y1 - y0) / hh
    # vfactor.heatmaps' convention: the roi gives pixel *edges*; heatmap column c
    # covers [x0 + c sx, x0 + (c+1) sx) and its centre is image pixel x0 + (c + 0.5) sx - 0.5.
    M = np.float32([[sx, 0, x0 + 0.5 * sx - 0.5], [0, sy, y0 + 0.5 * sy - 0.5]])
    warped = cv2.warpAffine(combined, M, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    colour = cv2.applyColorMap(np.clip(warped * 255, 0, 255).astype(np.uint8), cv2.COLORMAP_INFERNO).astype(float)
    alpha = (0.75 * np.clip(warped, 0, 1) ** 0.7)[..., None]
    img[:] = np.clip(img * (1 - alpha) + colour * alpha, 0, 255).astype(np.uint8)
    p0 = (int(round(x0)), int(round(y0)))
    p1 = (int(round(x1)) - 1, int(round(y1)) - 1)
    cv2.rectangle(img, p0, p1, (40, 40, 40), 3, cv2.LINE_AA)
    cv2.rectangle(img, p0, p1, (0, 200, 255), 1, cv2.LINE_AA)


def draw_overlay(
    image: np.ndarray,
    camera: Camera,
    detection: Detection | None = None,
    keypoints_world: np.ndarray | None = None,
    truth_keypoints_world: np.ndarray | None = None,
    heatmaps: np.ndarray | str | Path | None = None,
    roi: Sequence[float] | None = None,
    label: str | None = None,
    legend: bool = True,
    keypoint_numbers: bool = True,
) -> np.ndarray:
    """Draws keypoints, wireframes and heatmaps of one vehicle on a camera image.

    Layers, bottom to top: (d) the heatmaps, (c) the true wireframe (thin,
    dashed white with a dark outline), (b) the estimated wireframe (solid, one
    colour per layer: wheel orange, light cyan, roof magenta; the layer
    quadrilaterals thicker than the struts between layers, a dot at each
    keypoint), (a) the observed keypoints (filled circles, red to green and
    larger with confidence, with their index). Unseen keypoints
    (confidence 0) are skipped; wireframe parts behind the camera are clipped
    away. Edges are sampled, so lens distortion bends them as it should.

    Args:
        image: (H, W, 3) BGR ``uint8`` image (a photo or :func:`draw_view`);
            (H, W) grey and (H, W, 4) BGRA are converted. Never modified.
        camera: the camera that took ``image``.
        detection: the keypoints this camera observed, or ``None``.
        keypoints_world: (12, 3) estimated keypoints in the world frame, metres.
        truth_keypoints_world: (12, 3) true keypoints in the world frame, metres.
        heatmaps: (12, h, w) heatmaps (or the path of a ``.npy`` file holding
            them); the per-keypoint maximum, each normalised to its peak, is
            blended in with an inferno colour map over ``roi``.
        roi: ``(x0, y0, x1, y1)`` box the heatmaps cover, in image pixel
            edges as in :mod:`vfactor.heatmaps` (``(0, 0, W, H)`` is the whole
            image); defaults to ``detection.heatmaps_roi`` or ``detection.roi``, else to the whole image.
        label: text written in a tag above the vehicle (e.g. its track id).
        legend: whether to draw a small legend in the bottom-left corner.
        keypoint_numbers: whether to write each observed keypoint's index beside it.

    Returns:
        A new (H, W, 3) ``uint8`` BGR image.

    Raises:
        ValueError: an input has the wrong shape.
    """
    img = _as_bgr(image)
    H, W = img.shape[:2]
    size = (W, H)
    scale = _font_scale(size)
    r2_max = _max_valid_r2(camera, size)
    legend_items = []

    if heatmaps is not None:
        if roi is None and detection is not None:
            roi = detection.heatmaps_roi if detection.heatmaps_roi is not None else detection.roi
        _blend_heatmaps(img, heatmaps, roi)
        legend_items.append(("heatmap", None))

    if truth_keypoints_world is not None:
        truth = _check_points(truth_keypoints_world, "truth_keypoints_world")
        for _, lines in _edge_polylines(camera, truth, size, r2_max):
            for uv in lines:
                _dashed(img, uv, _TRUTH_BGR, 1, outline=(30, 30, 30))
        legend_items.append(("truth", None))

    if keypoints_world is not None:
        est = _check_points(keypoints_world, "keypoints_world")
        for (i, j), lines in _edge_polylines(camera, est, size, r2_max):
            same_layer = layer_of(i) == layer_of(j)
            colour = LAYER_COLORS_BGR[layer_of(max(i, j))]
            for uv in lines:
                _polyline(img, uv, colour, 2 if same_layer else 1)
        uv, _, valid = _project_valid(camera, est, size, r2_max)
        for k in np.nonzero(valid)[0]:
            cv2.circle(img, tuple(_fixed(uv[k])), 3 << _SHIFT, LAYER_COLORS_BGR[layer_of(k)], -1, cv2.LINE_AA, _SHIFT)
        legend_items.append(("estimate", None))

    if detection is not None:
        kp = np.asarray(detection.keypoints, dtype=float)
        conf = np.asarray(detection.confidence, dtype=float)
        if kp.shape != (NUM_KEYPOINTS, 2) or conf.shape != (NUM_KEYPOINTS,):
            raise ValueError(
                f"detection: expected keypoints (12, 2) and confidence (12,), got {kp.shape} and {conf.shape}"
            )
        seen = np.isfinite(conf) & (conf > 0) & np.all(np.isfinite(kp), axis=1)
        radius_base = max(3.0, 0.006 * min(W, H))
        for k in np.nonzero(seen)[0]:
            c = float(np.clip(conf[k], 0, 1))
            r = radius_base * (0.6 + 0.8 * c)
            centre = tuple(_fixed(kp[k]))
            cv2.circle(img, centre, int(round((r + 1.5) * (1 << _SHIFT))), (0, 0, 0), -1, cv2.LINE_AA, _SHIFT)
            cv2.circle(img, centre, int(round(r * (1 << _SHIFT))), _confidence_colour(c), -1, cv2.LINE_AA, _SHIFT)
            if keypoint_numbers:
                _text(img, str(k), (kp[k, 0] + r + 2, kp[k, 1] - r), scale * 0.55, (255, 255, 255), 1)
        legend_items.append(("observed", None))

    if label:
        anchor = _vehicle_anchor(camera, size, keypoints_world, detection)
        if anchor is not None:
            _draw_tags(img, [(label, anchor)], scale)

    if legend and legend_items:
        _draw_legend(img, [name for name, _ in legend_items], scale)
    return img


def _draw_legend(img, items, scale) -> None:
    """A legend of the drawn layers in the bottom-left corner (in place)."""
    H, W = img.shape[:2]
    s = scale * 0.6
    rows = []
    if "observed" in items:
        rows.append(("observed keypoint (red: low, green: high confidence)", "obs"))
    if "estimate" in items:
        rows.append(("estimate: wheel / light / roof layer", "est"))
    if "truth" in items:
        rows.append(("ground truth", "truth"))
    if "heatmap" in items:
        rows.append(("keypoint heatmaps (box: ROI)", "hm"))
    line_h = int(cv2.getTextSize("Ag", cv2.FONT_HERSHEY_SIMPLEX, s, 1)[0][1] * 2.0) + 2
    sym_w = int(3.2 * line_h)
    text_w = max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, s, 1)[0][0] for t, _ in rows)
    pad = 6
    box_w, box_h = sym_w + text_w + 3 * pad, line_h * len(rows) + 2 * pad
    x0, y0 = pad, H - pad - box_h
    if x0 + box_w > W or y0 < 0:
        return
    roi = img[y0 : y0 + box_h, x0 : x0 + box_w]
    roi[:] = (roi * 0.4).astype(np.uint8)
    for k, (text, kind) in enumerate(rows):
        cy = y0 + pad + line_h * k + line_h // 2
        sx = x0 + pad
        if kind == "obs":
            for n, c in enumerate((0.1, 0.5, 1.0)):
                cx = sx + int((n + 0.5) * sym_w / 3)
                r = int(line_h * (0.18 + 0.14 * c))
                cv2.circle(img, (cx, cy), r + 1, (0, 0, 0), -1, cv2.LINE_AA)
                cv2.circle(img, (cx, cy), r, _confidence_colour(c), -1, cv2.LINE_AA)
        elif kind == "est":
            for n, name in enumerate(("wheel", "light", "roof")):
                a = sx + int(n * sym_w / 3) + 2
                cv2.line(img, (a, cy), (a + sym_w // 3 - 4, cy), LAYER_COLORS_BGR[name], 2, cv2.LINE_AA)
        elif kind == "truth":
            _dashed(img, np.array([[sx, cy], [sx + sym_w, cy]], float), _TRUTH_BGR, 1, dash=6, gap=4)
        elif kind == "hm":
            bar = np.linspace(0, 255, sym_w).astype(np.uint8)[None, :]
            bar = cv2.applyColorMap(np.repeat(bar, max(line_h // 3, 2), 0), cv2.COLORMAP_INFERNO)
            ya = cy - bar.shape[0] // 2
            img[ya : ya + bar.shape[0], sx : sx + sym_w] = bar
        org = (sx + sym_w + pad, cy + line_h // 4)
        cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, s, (255, 255, 255), 1, cv2.LINE_AA)


# --------------------------------------------------------------- covariances
def position_covariance_world(world_T_vehicle: gtsam.Pose3, pose_covariance: np.ndarray) -> np.ndarray:
    """World-frame 3x3 covariance of a vehicle's position from its pose covariance.

    GTSAM's pose covariance is ordered rotation then translation, in the body
    frame (right perturbation ``T exp(xi)``): the translation block rotates into
    the world as ``R cov[3:6, 3:6] R^T``.

    Args:
        world_T_vehicle: the vehicle pose.
        pose_covariance: (6, 6) covariance in GTSAM's convention (rad, m).

    Returns:
        (3, 3) covariance of the position in the world frame, m^2.
    """
    cov = np.asarray(pose_covariance, dtype=float)
    if cov.shape != (6, 6):
        raise ValueError(f"pose_covariance: expected shape (6, 6), got {cov.shape}")
    R = world_T_vehicle.rotation().matrix()
    out = R @ cov[3:6, 3:6] @ R.T
    return 0.5 * (out + out.T)


def _eig_sorted(cov: np.ndarray):
    """Eigen-decomposition with eigenvalues descending and clipped at 0."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    order = np.argsort(vals)[::-1]
    return np.clip(vals[order], 0.0, None), vecs[:, order]


def _ellipse_xy(cov2: np.ndarray, k: float, n: int = 100) -> np.ndarray:
    """(n, 2) points of the k-sigma ellipse of a 2x2 covariance, centred at 0."""
    vals, vecs = _eig_sorted(cov2)
    a = np.linspace(0, 2 * np.pi, n)
    circle = np.stack([np.cos(a), np.sin(a)], axis=1)
    return (circle * (k * np.sqrt(vals))) @ vecs.T


def _nice_factor(x: float) -> float:
    """Largest of 1, 2, 5 x 10^n not above ``x`` (at least 1)."""
    if not np.isfinite(x) or x <= 1:
        return 1.0
    e = math.floor(math.log10(x))
    for m in (5, 2, 1):
        if m * 10**e <= x:
            return float(m * 10**e)
    return float(10**e)


# -------------------------------------------------------------------- figures
def _new_figure(figsize):
    """A matplotlib figure on an Agg canvas (pyplot's global backend untouched)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=110)
    FigureCanvasAgg(fig)
    return fig


def _camera_frustum_world(camera: Camera, size, depth: float) -> np.ndarray:
    """(4, 3) world points of the image corners at ``depth`` metres in front of the camera."""
    w, h = size
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=float)
    xy = camera.undistort_pixels(corners)
    cam_p = np.concatenate([xy, np.ones((4, 1))], axis=1) * depth
    return cam_p @ camera.world_T_camera[:3, :3].T + camera.center


def _draw_wireframe_3d(ax, pts, truth=False, alpha=1.0):
    for i, j in WIREFRAME_EDGES:
        seg = pts[[i, j]]
        if truth:
            ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], color="0.15", lw=0.9, ls=(0, (3, 2)), alpha=alpha)
        else:
            same = layer_of(i) == layer_of(j)
            ax.plot(
                seg[:, 0], seg[:, 1], seg[:, 2], color=LAYER_COLORS_RGB[layer_of(max(i, j))], lw=2.0 if same else 1.1
            )


def _draw_wireframe_xy(ax, pts, truth=False):
    for i, j in WIREFRAME_EDGES:
        seg = pts[[i, j]]
        if truth:
            ax.plot(seg[:, 0], seg[:, 1], color="0.15", lw=0.9, ls=(0, (3, 2)), zorder=3)
        else:
            same = layer_of(i) == layer_of(j)
            ax.plot(
                seg[:, 0], seg[:, 1], color=LAYER_COLORS_RGB[layer_of(max(i, j))], lw=2.0 if same else 1.0, zorder=4
            )


def _draw_cameras_xy(ax, cameras: Mapping[str, Camera], xlim, ylim) -> tuple[int, int]:
    """Draws the cameras in a top-down panel: a square and its viewing direction
    when inside the view, else an arrow at the border pointing at the camera,
    with its name and distance from the view centre.

    Returns:
        The numbers of cameras drawn inside and outside the view.
    """
    from matplotlib.patches import FancyArrowPatch

    mid = np.array([0.5 * (xlim[0] + xlim[1]), 0.5 * (ylim[0] + ylim[1])])
    hx, hy = 0.5 * (xlim[1] - xlim[0]), 0.5 * (ylim[1] - ylim[0])
    h = min(hx, hy)
    counts = [0, 0]
    for cam in cameras.values():
        c = cam.center[:2]
        axis = cam.world_T_camera[:3, 2][:2]
        axis = axis / max(np.linalg.norm(axis), 1e-9)
        inside = xlim[0] <= c[0] <= xlim[1] and ylim[0] <= c[1] <= ylim[1]
        counts[0 if inside else 1] += 1
        if inside:
            ax.plot(*c, marker="s", color="k", ms=6, zorder=8)
            ax.add_patch(
                FancyArrowPatch(c, c + 0.12 * h * axis, arrowstyle="-|>", mutation_scale=10, color="k", zorder=8)
            )
            ax.annotate(cam.name, c, xytext=(5, 5), textcoords="offset points", fontsize=9, zorder=8)
        else:
            d = c - mid
            dist = np.linalg.norm(cam.center - np.array([*mid, 0.0]))
            # Where the line from the view centre to the camera leaves the view.
            scale_t = min((hx * 0.84) / abs(d[0]) if d[0] else np.inf, (hy * 0.84) / abs(d[1]) if d[1] else np.inf)
            b = mid + d * scale_t
            u_dir = d / np.linalg.norm(d)
            ax.add_patch(
                FancyArrowPatch(
                    b - 0.06 * h * u_dir, b + 0.04 * h * u_dir, arrowstyle="-|>", mutation_scale=12,
                    color="0.3", lw=1.2, zorder=8,
                )
            )
            ha = "right" if u_dir[0] > 0.3 else "left" if u_dir[0] < -0.3 else "center"
            va = "top" if u_dir[1] > 0.3 else "bottom" if u_dir[1] < -0.3 else "center"
            ax.annotate(
                f"{cam.name}\n{dist:.0f} m", b - 0.09 * h * u_dir, fontsize=8.5, color="0.25", ha=ha, va=va,
                zorder=8, bbox=dict(fc="white", ec="none", alpha=0.75, pad=1.0),
            )
    return counts[0], counts[1]


def plot_estimates(
    cameras: Mapping[str, Camera],
    results: Iterable[VehicleResult],
    truth: Mapping[str, tuple[gtsam.Pose3, Wireframe]] | None,
    path: str | Path,
    title: str | None = None,
    sigma: float = 3.0,
) -> Path:
    """Writes a PNG figure of the camera rig, the estimated vehicles and their uncertainty.

    Panels:

    - 3D: each camera (its centre, a small frustum and its optical axis down to
      the road), each estimated wireframe (layer colours), the true wireframe
      dashed when ``truth`` is given, and the ``sigma``-sigma ellipsoid of each
      vehicle's position as a wire ellipsoid.
    - Top-down (x-y), zoomed on the vehicles: wireframes, a heading arrow
      (body x) per vehicle, the ``sigma``-sigma position ellipse, and each
      camera (or, when it lies outside the view, an arrow at the border
      pointing at it with its distance).
    - One small panel per vehicle (up to twelve, six to a row) with the
      ellipse at its true size in centimetres around the estimate and the
      true position when known.
    - A table of every vehicle (those without a pose too, with their status):
      body type, the 1-sigma standard deviations along the ellipse's axes,
      the vertical and yaw standard deviations, and the offset of the true
      position (cm and Mahalanobis) when known.

    Position ellipses are metres-scale pictures of centimetre-scale
    uncertainties: in the 3D and top-down panels they are magnified by a round
    factor (stated in the legend) so that they can be seen; the per-vehicle
    panels are at true scale.

    Covariances: ``VehicleResult.pose_covariance`` is in GTSAM's convention
    (rotation then translation, body frame); the world position covariance is
    ``R cov[3:6, 3:6] R^T`` (:func:`position_covariance_world`) and the yaw
    standard deviation is ``sqrt(cov[2, 2])`` (valid for small roll and pitch).

    Args:
        cameras: camera name -> camera.
        results: the estimates (results without a pose are listed, not drawn).
        truth: vehicle id -> (true ``world_T_vehicle``, true wireframe), or ``None``.
        path: PNG file to write (its folder is created).
        title: figure title.
        sigma: the ellipses and the ellipsoid show ``sigma`` standard deviations.

    Returns:
        The path written.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import FancyArrowPatch, Polygon

    path = Path(path)
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma: expected a positive number, got {sigma}")
    results = list(results)
    truth = dict(truth or {})
    drawn = [r for r in results if r.world_T_vehicle is not None and r.wireframe is not None]

    est_pts = {r.id: r.keypoints_world for r in drawn}
    truth_pts = {vid: wf.in_world(pose) for vid, (pose, wf) in truth.items()}
    pos_cov = {}
    for r in drawn:
        if r.pose_covariance is not None and np.all(np.isfinite(r.pose_covariance)):
            pos_cov[r.id] = position_covariance_world(r.world_T_vehicle, r.pose_covariance)

    # Magnification of the ellipses so that the largest one spans ~a quarter of a car length.
    vehicle_size = np.median([r.wireframe.diagonal for r in drawn]) if drawn else 4.0
    largest = max((sigma * np.sqrt(_eig_sorted(c)[0][0]) for c in pos_cov.values()), default=0.0)
    mag = _nice_factor(0.25 * vehicle_size / largest) if largest > 0 else 1.0

    n_side = min(len(drawn), _MAX_SIDE_PANELS)
    cols = min(n_side, 6)
    panel_rows = math.ceil(n_side / cols) if n_side else 0
    table_rows = len(results)
    heights = [7.0] + ([2.6 * panel_rows] if panel_rows else []) + ([0.5 + 0.26 * (table_rows + 1)] if table_rows else [])
    fig = _new_figure((15.5, sum(heights) + 0.9))
    outer = fig.add_gridspec(len(heights), 1, height_ratios=heights, hspace=0.28, left=0.04, right=0.985,
                             top=1 - 0.55 / (sum(heights) + 0.9), bottom=0.15 / (sum(heights) + 0.9))
    gs = outer[0].subgridspec(1, 2, width_ratios=[1.15, 1.0], wspace=0.18)
    ax3 = fig.add_subplot(gs[0, 0], projection="3d")
    ax2 = fig.add_subplot(gs[0, 1])

    # ---------------------------------------------------------------- 3D panel
    all_pts = [p for p in est_pts.values()] + [p for p in truth_pts.values()]
    vehicle_cloud = np.concatenate(all_pts) if all_pts else np.zeros((1, 3))
    cam_centres = np.array([c.center for c in cameras.values()]) if cameras else np.zeros((0, 3))
    cloud = np.concatenate([vehicle_cloud, cam_centres]) if len(cam_centres) else vehicle_cloud
    span = float(np.max(np.ptp(cloud, axis=0))) if len(cloud) > 1 else 10.0
    span = max(span, 5.0)
    # Ground grid (z = 0).
    lo = np.floor(cloud[:, :2].min(0) / 5) * 5 - 2
    hi = np.ceil(cloud[:, :2].max(0) / 5) * 5 + 2
    for x in np.arange(lo[0], hi[0] + 1e-9, 5.0):
        ax3.plot([x, x], [lo[1], hi[1]], [0, 0], color="0.85", lw=0.6, zorder=0)
    for y in np.arange(lo[1], hi[1] + 1e-9, 5.0):
        ax3.plot([lo[0], hi[0]], [y, y], [0, 0], color="0.85", lw=0.6, zorder=0)
    for cam in cameras.values():
        size = _resolve_size(cam)
        c = cam.center
        fr = _camera_frustum_world(cam, size, depth=0.06 * span)
        for k in range(4):
            ax3.plot(*np.stack([c, fr[k]]).T, color="0.25", lw=0.8)
            ax3.plot(*np.stack([fr[k], fr[(k + 1) % 4]]).T, color="0.25", lw=0.8)
        axis = cam.world_T_camera[:3, 2]
        t_ground = -c[2] / axis[2] if axis[2] < -1e-6 else 0.5 * span
        t_ground = min(t_ground, 1.5 * span)
        end = c + t_ground * axis
        ax3.plot(*np.stack([c, end]).T, color="0.4", lw=0.8, ls=":")
        ax3.scatter(*c, color="k", s=18, depthshade=False)
        ax3.text(*(c + [0, 0, 0.04 * span]), cam.name, fontsize=9, ha="center")
    for vid, pts in truth_pts.items():
        _draw_wireframe_3d(ax3, pts, truth=True)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 20), np.linspace(0, np.pi, 11))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
    for r in drawn:
        _draw_wireframe_3d(ax3, est_pts[r.id])
        p = r.world_T_vehicle.translation()
        if r.id in pos_cov:
            vals, vecs = _eig_sorted(pos_cov[r.id])
            ell = (sphere * (mag * sigma * np.sqrt(vals))) @ vecs.T + p
            ax3.plot_wireframe(ell[..., 0], ell[..., 1], ell[..., 2], color=_ELLIPSE_RGB, lw=0.5, alpha=0.8)
        top = est_pts[r.id][:, 2].max()
        ax3.text(p[0], p[1], top + 0.6, r.id, fontsize=10, fontweight="bold", ha="center")
    ranges = np.ptp(np.concatenate([cloud, [[lo[0], lo[1], 0], [hi[0], hi[1], 0]]]), axis=0)
    ax3.set_box_aspect(np.maximum(ranges, 0.08 * ranges.max()), zoom=1.0)
    from matplotlib.ticker import MaxNLocator

    ax3.zaxis.set_major_locator(MaxNLocator(3, integer=True))
    ax3.set_xlim(lo[0], hi[0])
    ax3.set_ylim(lo[1], hi[1])
    ax3.set_zlim(0, max(cloud[:, 2].max(), 1.0) * 1.05)
    ax3.set_xlabel("x [m]")
    ax3.set_ylabel("y [m]")
    ax3.set_zlabel("z [m]")
    ax3.view_init(elev=28, azim=-60)
    ax3.set_title("Camera rig and vehicles (3D)", fontsize=11)

    # ------------------------------------------------------------ top-down panel
    if all_pts:
        vlo, vhi = vehicle_cloud[:, :2].min(0), vehicle_cloud[:, :2].max(0)
    else:
        vlo, vhi = np.zeros(2), np.zeros(2)
    mid = 0.5 * (vlo + vhi)
    half = max(0.5 * float(np.max(vhi - vlo)) + 2.5, 5.0)
    xlim, ylim = (mid[0] - half, mid[0] + half), (mid[1] - half, mid[1] + half)
    ax2.set_xlim(*xlim)
    ax2.set_ylim(*ylim)
    ax2.set_aspect("equal")
    ax2.grid(True, color="0.88", lw=0.6)
    ax2.set_axisbelow(True)
    for vid, pts in truth_pts.items():
        _draw_wireframe_xy(ax2, pts, truth=True)
    for r in drawn:
        pts = est_pts[r.id]
        _draw_wireframe_xy(ax2, pts)
        T = r.world_T_vehicle.matrix()
        p, fwd = T[:3, 3], T[:3, 0]
        L = 0.35 * r.wireframe.diagonal
        ax2.add_patch(
            FancyArrowPatch(
                p[:2], p[:2] + L * fwd[:2] / max(np.linalg.norm(fwd[:2]), 1e-9),
                arrowstyle="-|>", mutation_scale=14, color="0.1", lw=1.3, zorder=6,
            )
        )
        if r.id in pos_cov:
            e = _ellipse_xy(pos_cov[r.id][:2, :2], sigma * mag) + p[:2]
            ax2.add_patch(Polygon(e, closed=True, fc=(*_ELLIPSE_RGB, 0.18), ec=_ELLIPSE_RGB, lw=1.4, zorder=5))
        ax2.plot(*p[:2], "o", color="0.1", ms=3, zorder=7)
        y_top = pts[:, 1].max()
        ax2.annotate(
            r.id, (p[0], y_top), xytext=(0, 8), textcoords="offset points",
            ha="center", fontsize=10, fontweight="bold", zorder=8,
        )
    _draw_cameras_xy(ax2, cameras, xlim, ylim)
    ax2.set_xlabel("x [m]")
    ax2.set_ylabel("y [m]")
    ax2.set_title("Top view (x-y)", fontsize=11)

    handles = [
        Line2D([], [], color=LAYER_COLORS_RGB["wheel"], lw=2, label="wheel layer"),
        Line2D([], [], color=LAYER_COLORS_RGB["light"], lw=2, label="light layer"),
        Line2D([], [], color=LAYER_COLORS_RGB["roof"], lw=2, label="roof layer"),
    ]
    if truth_pts:
        handles.append(Line2D([], [], color="0.15", lw=0.9, ls=(0, (3, 2)), label="ground truth"))
    if pos_cov:
        mag_txt = f", magnified \u00d7{mag:g}" if mag > 1 else ""
        handles.append(
            Polygon(
                [[0, 0]], closed=True, fc=(*_ELLIPSE_RGB, 0.18), ec=_ELLIPSE_RGB,
                label=f"position {sigma:g}\u03c3 ellipse (3D: ellipsoid){mag_txt}",
            )
        )
    handles.append(Line2D([], [], color="0.1", marker=r"$\rightarrow$", ls="", ms=12, label="heading (body x)"))
    # below the 3D panel, where it covers no vehicle however many there are
    ax3.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.06), ncol=3, fontsize=8.5, framealpha=0.9)

    # --------------------------------------------------------- per-vehicle panels
    rows_of_table = {}
    if n_side:
        panels = outer[1].subgridspec(panel_rows, 6, wspace=0.45, hspace=0.5)
        for k, r in enumerate(drawn[:n_side]):
            ax = fig.add_subplot(panels[k // cols, k % cols])
            rows_of_table[r.id] = _plot_uncertainty_panel(ax, r, pos_cov.get(r.id), truth.get(r.id), sigma)
    if table_rows:
        ax_table = fig.add_subplot(outer[-1])
        ax_table.axis("off")
        header = ["vehicle", "status", "body type", "1\u03c3 position (cm)", "major axis", "1\u03c3 height",
                  "1\u03c3 yaw", "truth off", "Mahalanobis"]
        cells = []
        for r in results:
            row = rows_of_table.get(r.id) or _uncertainty_row(r, pos_cov.get(r.id), truth.get(r.id))
            status = getattr(r.status, "value", str(r.status))
            cells.append([r.id, status + (f": {r.message[:40]}" if r.message and not r.ok else ""),
                          r.body_type or "-", *row])
        table = ax_table.table(cellText=cells, colLabels=header, loc="upper center", cellLoc="center")
        table.auto_set_font_size(False)
        table.set_fontsize(8.5)
        table.scale(1.0, 1.15)
        ax_table.set_title(f"Per vehicle: position uncertainty ({sigma:g}\u03c3 shaded, 1\u03c3 dashed in the panels "
                           "above, at true scale), offset of the truth", fontsize=9.5, loc="left")
    if len(drawn) > n_side:
        fig.text(0.985, 0.005, f"uncertainty panels for the first {n_side} of {len(drawn)} vehicles", ha="right",
                 va="bottom", fontsize=8.5, color="0.3")
    fig.suptitle(title or "Vehicle pose and shape estimates", fontsize=13, y=1 - 0.12 / (sum(heights) + 0.9))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def _uncertainty_row(result: VehicleResult, cov_world, truth_entry) -> list[str]:
    """The table cells of one vehicle: 1-sigma position ellipse (cm), its major axis, height and yaw sigmas,
    the truth's offset (cm) and Mahalanobis distance."""
    if result.world_T_vehicle is None:
        return ["-"] * 6
    cells = ["no covariance", "-", "-", "-"]
    if cov_world is not None:
        cov_cm = cov_world * 1e4
        vals, vecs = _eig_sorted(cov_cm[:2, :2])
        std = np.sqrt(vals)
        angle = math.degrees(math.atan2(vecs[1, 0], vecs[0, 0])) % 180.0
        yaw_std = math.degrees(math.sqrt(max(float(result.pose_covariance[2, 2]), 0.0)))
        cells = [f"{std[0]:.1f} \u00d7 {std[1]:.1f}", f"{angle:.0f}\u00b0 to x",
                 f"{math.sqrt(max(cov_cm[2, 2], 0)):.1f} cm", f"{yaw_std:.2f}\u00b0"]
    off, maha = "-", "-"
    if truth_entry is not None:
        d_cm = (np.asarray(truth_entry[0].translation()) - result.world_T_vehicle.translation()) * 100.0
        off = f"{np.linalg.norm(d_cm):.1f} cm"
        if cov_world is not None:
            try:
                maha = f"{float(np.sqrt(d_cm @ np.linalg.solve(cov_world * 1e4, d_cm))):.1f}\u03c3 (3D)"
            except np.linalg.LinAlgError:
                pass
    return cells + [off, maha]


def _plot_uncertainty_panel(ax, result: VehicleResult, cov_world, truth_entry, sigma: float) -> list[str]:
    """The position ellipse of one vehicle at true scale, in cm around the estimate; returns its table cells."""
    from matplotlib.patches import Polygon

    ax.set_title(f"{result.id} (top view, cm)", fontsize=9)
    ax.set_aspect("equal")
    ax.grid(True, color="0.88", lw=0.6)
    ax.set_axisbelow(True)
    ax.tick_params(labelsize=7.5)
    ax.axhline(0, color="0.7", lw=0.6)
    ax.axvline(0, color="0.7", lw=0.6)
    extent = 1.0
    if cov_world is not None:
        cov_cm = cov_world * 1e4
        e_k = _ellipse_xy(cov_cm[:2, :2], sigma)
        e_1 = _ellipse_xy(cov_cm[:2, :2], 1.0)
        ax.add_patch(Polygon(e_k, closed=True, fc=(*_ELLIPSE_RGB, 0.15), ec=_ELLIPSE_RGB, lw=1.3))
        ax.plot(e_1[:, 0], e_1[:, 1], color=_ELLIPSE_RGB, lw=0.8, ls="--")
        vals, vecs = _eig_sorted(cov_cm[:2, :2])
        for s, v in zip(np.sqrt(vals), vecs.T):
            ax.plot([-s * v[0], s * v[0]], [-s * v[1], s * v[1]], color=_ELLIPSE_RGB, lw=0.8)
        extent = max(extent, float(np.abs(e_k).max()))
    else:
        ax.text(0.5, 0.5, "no covariance", transform=ax.transAxes, ha="center", va="center", fontsize=8)
    if truth_entry is not None:
        d_cm = (np.asarray(truth_entry[0].translation()) - result.world_T_vehicle.translation()) * 100.0
        ax.plot(d_cm[0], d_cm[1], marker="x", color="k", ms=7, mew=1.6, ls="")
        extent = max(extent, float(np.abs(d_cm[:2]).max()))
    lim = 1.2 * extent
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    return _uncertainty_row(result, cov_world, truth_entry)


# ---------------------------------------------------------------- trajectories
#: Track colours of :func:`plot_trajectories`: distinct from the layer colours
#: (orange, cyan, magenta), the ellipse red and the truth's near-black.
_TRACK_COLORS = (
    "#1f5fbf",  # blue
    "#2a9d3a",  # green
    "#7b3fa0",  # purple
    "#8c564b",  # brown
    "#0f7c7c",  # teal
    "#9a8a00",  # olive
    "#5a5a5a",  # grey
    "#1b2f6b",  # navy
)
_TRUTH_RGB = "0.15"


def _vehicles_of(frame) -> list:
    """The VehicleResults of a FrameResult (or of a plain list of them)."""
    if frame is None:
        return []
    return list(frame.vehicles if hasattr(frame, "vehicles") else frame)


def _truth_pose_wireframe(entry):
    """(pose, wireframe) of a VehicleTruth or of a (pose, wireframe) pair."""
    if hasattr(entry, "world_T_vehicle"):
        return entry.world_T_vehicle, entry.wireframe
    pose, wireframe = entry
    return pose, wireframe


def _has_pose(r) -> bool:
    """Whether a VehicleResult is drawn: its status is ok and it has a pose."""
    return r.world_T_vehicle is not None and r.ok


def _track_series(frames, n: int) -> dict:
    """Per track id: arrays over the n frames (NaN where the vehicle has no pose).

    Keys: ``pos`` (n, 3) m, ``fwd`` (n, 2) unit heading in x-y, ``cov`` (n, 3, 3)
    world position covariance m^2, ``pos_std`` (n,) cm (sqrt of the largest
    eigenvalue), ``yaw_std`` (n,) deg, ``last`` the last VehicleResult with a pose.
    """
    out: dict[str, dict] = {}

    def new():
        return {
            "pos": np.full((n, 3), np.nan),
            "fwd": np.full((n, 2), np.nan),
            "cov": np.full((n, 3, 3), np.nan),
            "pos_std": np.full(n, np.nan),
            "yaw_std": np.full(n, np.nan),
            "last": None,
            "missing": {},
        }

    for f, frame in enumerate(frames):
        for r in _vehicles_of(frame):
            s = out.setdefault(r.id, new())
            if not _has_pose(r):
                status = getattr(r.status, "value", r.status)
                s["missing"][status] = s["missing"].get(status, 0) + 1
                continue
            T = r.world_T_vehicle.matrix()
            s["pos"][f] = T[:3, 3]
            fwd = T[:2, 0]
            s["fwd"][f] = fwd / max(np.linalg.norm(fwd), 1e-9)
            if r.wireframe is not None:
                s["last"] = r
            cov = None if r.pose_covariance is None else np.asarray(r.pose_covariance, dtype=float)
            if cov is not None and cov.shape == (6, 6) and np.all(np.isfinite(cov)):
                c = position_covariance_world(r.world_T_vehicle, cov)
                s["cov"][f] = c
                s["pos_std"][f] = 100.0 * math.sqrt(_eig_sorted(c)[0][0])
                R = T[:3, :3]
                # Right perturbation R Exp(w): the world-frame rotation error is R w; yaw is its z part.
                s["yaw_std"][f] = math.degrees(math.sqrt(max(float((R @ cov[:3, :3] @ R.T)[2, 2]), 0.0)))
    return out


def _frame_times(frames) -> tuple[np.ndarray, str]:
    """The frames' times (s), or their indices when times are missing or not increasing."""
    n = len(frames)
    try:
        t = np.array([float(getattr(f, "t")) for f in frames])
    except (AttributeError, TypeError, ValueError):
        t = None
    if t is None or not np.all(np.isfinite(t)) or (n > 1 and not np.all(np.diff(t) > 0)):
        return np.arange(n, dtype=float), "frame"
    return t, "time [s]"


def _fit_limits(lo, hi, aspect: float):
    """x and y limits around the box [lo, hi] with width / height = ``aspect`` (metres per metre)."""
    mid = 0.5 * (lo + hi)
    w, h = hi - lo
    if w / h < aspect:
        w = h * aspect
    else:
        h = w / aspect
    return (mid[0] - w / 2, mid[0] + w / 2), (mid[1] - h / 2, mid[1] + h / 2)


def _ellipse_frames(valid: np.ndarray, every: int) -> list[int]:
    """Frames of a track that get an ellipse and a heading arrow: every ``every``-th
    frame with a pose, counted from the track's first, and its last frame."""
    idx = np.nonzero(valid)[0]
    if len(idx) == 0:
        return []
    picked = list(idx[::every])
    if idx[-1] != picked[-1] and len(idx) - 1 - (len(picked) - 1) * every >= max(every / 2, 1):
        picked.append(idx[-1])
    return [int(i) for i in picked]


def plot_trajectories(
    cameras: Mapping[str, Camera],
    frames: Sequence,
    path: str | Path,
    truth: Sequence[Mapping[str, object] | None] | None = None,
    title: str | None = None,
    sigma: float = 3.0,
    ellipse_every: int = 5,
    frame_by_frame: Sequence | None = None,
) -> Path:
    """Writes a PNG figure of tracking results: trajectories, uncertainty and error over time.

    Panels:

    - Top-down (x-y) view: per track (``VehicleResult.id``), the estimated
      trajectory of the body origin (``world_T_vehicle.translation()``) as a
      line with a marker per frame, in a colour of its own; a heading arrow
      (body x) and the ``sigma``-sigma position ellipse every
      ``ellipse_every`` frames of the track (and at its last frame); the
      final estimated wireframe (layer colours) at the last pose, labelled
      with the id; the true trajectory dashed (and the true final wireframe)
      when ``truth`` is given; the ``frame_by_frame`` estimates as faint dots
      when given; and the cameras (or arrows at the border pointing at them
      with their distance, when they lie outside the view). Ellipses are
      magnified by a round factor stated in the legend when they would be
      too small to see, as in :func:`plot_estimates`.
    - Position uncertainty against time: the 1-sigma standard deviation of
      the position along its worst axis, ``sqrt`` of the largest eigenvalue
      of the world position covariance, in cm.
    - Heading uncertainty against time: the 1-sigma standard deviation of
      the yaw, in degrees (the z part of the world-frame rotation
      covariance ``R cov[0:3, 0:3] R^T``).
    - When ``truth`` is given: the position error (distance between the
      estimated and the true body origin, 3D) against time, in cm, with its
      median per track in the legend.

    In the time panels, the ``frame_by_frame`` results are drawn dotted in
    the track's colour, so the reader sees what tracking gained. Vehicles
    without a pose in a frame (status ``degenerate`` or ``failed``) are
    skipped: their track shows a break there, and a note under the figure
    counts them.

    Args:
        cameras: camera name -> camera.
        frames: the tracking result, one :class:`~vfactor.result.FrameResult`
            per frame in time order (their ``t`` is the time axis; frame
            indices are used when the times are not increasing).
        path: PNG file to write (its folder is created).
        truth: per frame (aligned with ``frames``), vehicle id ->
            :class:`vfactor.sim.VehicleTruth` or ``(world_T_vehicle,
            Wireframe)``; a frame may be ``None``.
        title: figure title.
        sigma: the ellipses show ``sigma`` standard deviations.
        ellipse_every: an ellipse and a heading arrow every this many frames
            of a track (a positive integer).
        frame_by_frame: the per-frame independent estimates of the same
            frames (e.g. :func:`vfactor.solve.solve_scene`), aligned with
            ``frames``.

    Returns:
        The path written.

    Raises:
        ValueError: ``sigma`` not a positive number, ``ellipse_every`` not a
            positive integer, or ``truth`` / ``frame_by_frame`` not as long
            as ``frames``.
    """
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.lines import Line2D
    from matplotlib.patches import FancyArrowPatch, Polygon

    path = Path(path)
    try:
        sigma = float(sigma)
    except (TypeError, ValueError):
        raise ValueError(f"sigma: expected a positive number, got {sigma!r}") from None
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma: expected a positive number, got {sigma}")
    if isinstance(ellipse_every, bool) or not isinstance(ellipse_every, (int, np.integer)) or ellipse_every < 1:
        raise ValueError(f"ellipse_every: expected a positive integer, got {ellipse_every!r}")
    ellipse_every = int(ellipse_every)
    frames = list(frames)
    n = len(frames)
    if truth is not None:
        truth = list(truth)
        if len(truth) != n:
            raise ValueError(f"truth: expected one entry per frame ({n}), got {len(truth)}")
    if frame_by_frame is not None:
        frame_by_frame = list(frame_by_frame)
        if len(frame_by_frame) != n:
            raise ValueError(f"frame_by_frame: expected one entry per frame ({n}), got {len(frame_by_frame)}")

    times, time_label = _frame_times(frames)
    est = _track_series(frames, n)
    fbf = _track_series(frame_by_frame, n) if frame_by_frame is not None else {}
    true_pos: dict[str, np.ndarray] = {}
    true_last: dict[str, tuple] = {}
    for f, entry in enumerate(truth or []):
        for vid, item in dict(entry or {}).items():
            pose, wireframe = _truth_pose_wireframe(item)
            true_pos.setdefault(vid, np.full((n, 3), np.nan))[f] = np.asarray(pose.translation(), dtype=float)
            true_last[vid] = (pose, wireframe)
    ids = list(dict.fromkeys([*est, *fbf, *true_pos]))
    colour = {vid: _TRACK_COLORS[k % len(_TRACK_COLORS)] for k, vid in enumerate(ids)}
    has_truth = bool(true_pos)
    has_fbf = bool(fbf)
    # Tracks with at least one pose (others appear only in the note under the figure).
    tracked_ids = [vid for vid in ids if vid in est and np.isfinite(est[vid]["pos"]).any()]

    # --------------------------------------------------------- view of the map
    cloud = [s["pos"][:, :2] for s in [*est.values(), *fbf.values()]] + [p[:, :2] for p in true_pos.values()]
    final_pts = {vid: s["last"].keypoints_world for vid, s in est.items() if s["last"] is not None}
    true_final_pts = {vid: wf.in_world(pose) for vid, (pose, wf) in true_last.items()}
    cloud += [p[:, :2] for p in final_pts.values()] + [p[:, :2] for p in true_final_pts.values()]
    cloud = np.concatenate(cloud) if cloud else np.zeros((0, 2))
    cloud = cloud[np.all(np.isfinite(cloud), axis=1)]
    if len(cloud) == 0:
        cloud = np.zeros((1, 2))
    lo, hi = cloud.min(0) - 2.5, cloud.max(0) + 2.5
    lo, hi = np.minimum(lo, 0.5 * (lo + hi) - 4.0), np.maximum(hi, 0.5 * (lo + hi) + 4.0)
    # Take the cameras into the view when that does not shrink the vehicles too much.
    if cameras:
        cams = np.array([c.center[:2] for c in cameras.values()])
        clo, chi = np.minimum(lo, cams.min(0) - 2.0), np.maximum(hi, cams.max(0) + 2.0)
        if np.max(chi - clo) <= 1.3 * np.max(hi - lo):
            lo, hi = clo, chi
    wide = (hi[0] - lo[0]) >= 1.25 * (hi[1] - lo[1])

    # ------------------------------------------------------------------ layout
    n_time = 3 if has_truth else 2
    if wide:
        fig = _new_figure((16.0, 10.0))
        gs = fig.add_gridspec(2, 1, height_ratios=[1.55, 1.0], hspace=0.22, left=0.055, right=0.985,
                              top=0.93, bottom=0.085)
        top = gs[0].subgridspec(1, 2, width_ratios=[1.0, 0.25], wspace=0.02)
        ax = fig.add_subplot(top[0, 0])
        ax_legend = fig.add_subplot(top[0, 1])
        bottom = gs[1].subgridspec(1, n_time, wspace=0.28)
        tax = [fig.add_subplot(bottom[0, k]) for k in range(n_time)]
    else:
        fig = _new_figure((16.0, 10.0))
        gs = fig.add_gridspec(1, 2, width_ratios=[1.25, 1.0], wspace=0.16, left=0.05, right=0.985,
                              top=0.93, bottom=0.085)
        left = gs[0].subgridspec(2, 1, height_ratios=[1.0, 0.2], hspace=0.1)
        ax = fig.add_subplot(left[0, 0])
        ax_legend = fig.add_subplot(left[1, 0])
        right = gs[1].subgridspec(n_time, 1, hspace=0.42)
        tax = [fig.add_subplot(right[k, 0]) for k in range(n_time)]
    ax_legend.axis("off")
    box = ax.get_position()
    fw, fh = fig.get_size_inches()
    xlim, ylim = _fit_limits(lo, hi, (box.width * fw) / (box.height * fh))
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, color="0.88", lw=0.6)
    ax.set_axisbelow(True)

    # ------------------------------------------------------------ map content
    diag = {vid: s["last"].wireframe.diagonal for vid, s in est.items() if s["last"] is not None}
    vehicle_size = float(np.median(list(diag.values()))) if diag else 4.5
    picks = {vid: _ellipse_frames(np.all(np.isfinite(s["pos"]), axis=1), ellipse_every) for vid, s in est.items()}
    largest = 0.0
    for vid, s in est.items():
        for f in picks[vid]:
            if np.all(np.isfinite(s["cov"][f])):
                largest = max(largest, sigma * math.sqrt(_eig_sorted(s["cov"][f][:2, :2])[0][0]))
    mag = _nice_factor(0.25 * vehicle_size / largest) if largest > 0 else 1.0

    for vid, p in true_pos.items():
        ax.plot(p[:, 0], p[:, 1], color=_TRUTH_RGB, lw=1.1, ls=(0, (4, 3)), zorder=3)
    for vid, pts in true_final_pts.items():
        _draw_wireframe_xy(ax, pts, truth=True)
    for vid, s in fbf.items():
        ax.plot(s["pos"][:, 0], s["pos"][:, 1], ls="", marker="o", ms=4.5, color=colour[vid], alpha=0.4,
                mec="none", zorder=2)
    for vid, pts in final_pts.items():
        _draw_wireframe_xy(ax, pts)
    for vid, s in est.items():
        p = s["pos"]
        ax.plot(p[:, 0], p[:, 1], color=colour[vid], lw=1.8, marker="o", ms=3.2, zorder=6)
        L = 0.3 * diag.get(vid, vehicle_size)
        for f in picks[vid]:
            c = s["cov"][f]
            if np.all(np.isfinite(c)):
                e = _ellipse_xy(c[:2, :2], sigma * mag) + p[f, :2]
                ax.add_patch(Polygon(e, closed=True, fc=(*_ELLIPSE_RGB, 0.14), ec=_ELLIPSE_RGB, lw=1.1, zorder=5))
            ax.add_patch(
                FancyArrowPatch(
                    p[f, :2], p[f, :2] + L * s["fwd"][f], arrowstyle="-|>", mutation_scale=11,
                    color=colour[vid], lw=1.3, zorder=7,
                )
            )
        valid = np.nonzero(np.all(np.isfinite(p), axis=1))[0]
        if len(valid):
            first = valid[0]
            ax.plot(*p[first, :2], marker="o", ms=7.5, mfc="white", mec=colour[vid], mew=1.8, zorder=7)
            ax.annotate(
                f"{times[first]:g} s" if time_label.startswith("time") else f"frame {first}", p[first, :2],
                xytext=(0, -9), textcoords="offset points", ha="center", va="top", fontsize=8, color=colour[vid],
                zorder=9, bbox=dict(fc="white", ec="none", alpha=0.7, pad=0.5),
            )
            anchor = final_pts[vid] if vid in final_pts else p[valid[-1]][None]
            ax.annotate(
                vid, (float(np.mean(anchor[:, 0])), float(anchor[:, 1].max())), xytext=(0, 6),
                textcoords="offset points", ha="center", va="bottom", fontsize=11, fontweight="bold",
                color=colour[vid], zorder=9, bbox=dict(fc="white", ec="none", alpha=0.7, pad=0.8),
            )
    cams_inside, cams_outside = _draw_cameras_xy(ax, cameras, xlim, ylim)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Trajectories, top view (x-y)", fontsize=11, loc="left")
    if not ids:
        ax.text(0.5, 0.5, "no vehicle estimates", transform=ax.transAxes, ha="center", va="center",
                fontsize=12, color="0.4")

    # ------------------------------------------------------------------ legend
    handles, labels = [], []
    for vid in tracked_ids:
        k = int(np.all(np.isfinite(est[vid]["pos"]), axis=1).sum())
        handles.append(Line2D([], [], color=colour[vid], lw=1.8, marker="o", ms=3.2))
        labels.append(f"{vid}: tracked ({k} frame{'s' if k != 1 else ''})")
    if any(s["last"] is not None for s in est.values()):
        handles.append(Line2D([], [], color="0.4", marker="o", ms=7.5, mfc="white", mew=1.8, ls=""))
        labels.append("start of a track")
    if has_fbf:
        handles.append(
            tuple(Line2D([], [], color=colour[vid], marker="o", ms=4.5, alpha=0.4, mec="none", ls="")
                  for vid in list(fbf)[:3])
        )
        labels.append("frame-by-frame estimates")
    if has_truth:
        handles.append(Line2D([], [], color=_TRUTH_RGB, lw=1.1, ls=(0, (4, 3))))
        labels.append("ground truth")
    if any(np.isfinite(s["cov"]).any() for s in est.values()):
        handles.append(Polygon([[0, 0]], closed=True, fc=(*_ELLIPSE_RGB, 0.14), ec=_ELLIPSE_RGB))
        mag_txt = f",\nmagnified \u00d7{mag:g}" if mag > 1 else ""
        labels.append(f"position {sigma:g}\u03c3 ellipse{mag_txt}\n(every {ellipse_every} frames)")
    if est:
        handles.append(Line2D([], [], color="0.3", marker=r"$\rightarrow$", ls="", ms=12))
        labels.append("heading (body x)")
    if final_pts:
        handles.append(tuple(Line2D([], [], color=LAYER_COLORS_RGB[k], lw=2) for k in ("wheel", "light", "roof")))
        labels.append("final wireframe:\nwheel / light / roof")
    if cams_inside:
        handles.append(Line2D([], [], color="k", marker="s", ms=6, ls=""))
        labels.append("camera (and its viewing direction)")
    if cams_outside:
        handles.append(Line2D([], [], color="0.3", marker=r"$\nearrow$", ls="", ms=12))
        labels.append("direction to a camera outside\nthe view (distance from its centre)")
    if handles:
        ax_legend.legend(
            handles, labels, loc="upper left" if wide else "upper center", fontsize=9, frameon=False,
            handler_map={tuple: HandlerTuple(ndivide=None, pad=0.3)}, ncol=1 if wide else 3,
            handlelength=2.6, labelspacing=0.9, borderaxespad=0.0,
        )

    # ------------------------------------------------------------- time panels
    def series(ax_t, key, ylabel, panel_title, show_legend):
        drawn = False
        values = []
        for vid in ids:
            if vid in fbf and np.isfinite(fbf[vid][key]).any():
                ax_t.plot(times, fbf[vid][key], color=colour[vid], lw=1.0, ls=(0, (1.5, 1.5)), marker="o", ms=2.5,
                          alpha=0.75, zorder=3)
                values.append(fbf[vid][key])
                drawn = True
            if vid in est and np.isfinite(est[vid][key]).any():
                ax_t.plot(times, est[vid][key], color=colour[vid], lw=1.8, marker="o", ms=3.2, zorder=4)
                values.append(est[vid][key])
                drawn = True
        _style_time_axis(ax_t, ylabel, panel_title, time_label, values, allow_log=True,
                         headroom=1.3 if show_legend else 1.12)
        if not drawn:
            ax_t.text(0.5, 0.5, "no covariances", transform=ax_t.transAxes, ha="center", va="center",
                      color="0.45", fontsize=10)
        elif show_legend:
            _time_legend(ax_t, tracked_ids, colour, has_fbf)

    series(tax[0], "pos_std", "1\u03c3 [cm]", "Position uncertainty (1\u03c3, worst axis)", True)
    series(tax[1], "yaw_std", "1\u03c3 [deg]", "Heading uncertainty (1\u03c3 yaw)", False)
    if has_truth:
        ax_e = tax[2]
        values, handles, labels = [], [], []
        for vid in ids:
            if vid not in true_pos:
                continue
            for source, style in ((fbf, "fbf"), (est, "est")):
                if vid not in source:
                    continue
                err = 100.0 * np.linalg.norm(source[vid]["pos"] - true_pos[vid], axis=1)
                if not np.isfinite(err).any():
                    continue
                if style == "fbf":
                    h, = ax_e.plot(times, err, color=colour[vid], lw=1.0, ls=(0, (1.5, 1.5)), marker="o", ms=2.5,
                                   alpha=0.75, zorder=3)
                    name = "frame-by-frame"
                else:
                    h, = ax_e.plot(times, err, color=colour[vid], lw=1.8, marker="o", ms=3.2, zorder=4)
                    name = "tracked"
                values.append(err)
                handles.append(h)
                labels.append(f"{vid} {name}: median {np.nanmedian(err):.1f} cm")
        _style_time_axis(ax_e, "error [cm]", "Position error vs. ground truth (3D)", time_label, values,
                         headroom=1.15 + 0.08 * len(handles))
        if handles:
            order = sorted(range(len(handles)), key=lambda k: (labels[k].split(" ")[0], "frame" in labels[k]))
            ax_e.legend([handles[k] for k in order], [labels[k] for k in order], fontsize=8, loc="best",
                        framealpha=0.9)
        else:
            ax_e.text(0.5, 0.5, "no estimate with a true pose", transform=ax_e.transAxes, ha="center",
                      va="center", color="0.45", fontsize=10)

    # -------------------------------------------------------------------- notes
    notes = []
    for vid in ids:
        missing = {**est.get(vid, {}).get("missing", {})}
        if missing:
            parts = ", ".join(f"{cnt} {status}" for status, cnt in missing.items())
            notes.append(f"{vid}: {parts}")
    if notes:
        fig.text(0.01, 0.012, "Frames without a pose (gaps in the tracks): " + "; ".join(notes), fontsize=9,
                 color="0.3")
    fig.suptitle(title or "Vehicle tracks: trajectories and uncertainty", fontsize=13, y=0.985)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def _style_time_axis(ax, ylabel, panel_title, time_label, values, allow_log: bool = False, headroom=1.12) -> None:
    """Grid, labels, and a y range from 0 to ``headroom`` times the largest value
    (with ``allow_log``, a log scale when the values span more than 20x)."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    ax.set_title(panel_title, fontsize=10.5, loc="left")
    ax.set_xlabel(time_label, fontsize=9)
    ax.set_ylabel(ylabel, fontsize=9)
    ax.tick_params(labelsize=8.5)
    ax.grid(True, color="0.88", lw=0.6)
    ax.set_axisbelow(True)
    v = np.concatenate([np.ravel(x) for x in values]) if values else np.zeros(0)
    v = v[np.isfinite(v) & (v > 0)]
    if allow_log and len(v) and v.max() / v.min() > 20.0:
        ax.set_yscale("log")
        ax.yaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f"{y:g}"))
        ax.yaxis.set_minor_formatter(FuncFormatter(lambda y, _: ""))
    elif len(v):
        ax.set_ylim(0.0, headroom * v.max())


def _time_legend(ax, ids, colour, has_fbf) -> None:
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colour[vid], lw=1.8, marker="o", ms=3.2, label=f"{vid} tracked") for vid in ids]
    if has_fbf:
        handles.append(Line2D([], [], color="0.35", lw=1.0, ls=(0, (1.5, 1.5)), marker="o", ms=2.5,
                              label="frame-by-frame"))
    ax.legend(handles=handles, fontsize=8, loc="best", framealpha=0.9)


# ------------------------------------------------------------------ overlays
def write_overlays(
    out_dir: str | Path,
    scene_cameras: Mapping[str, Camera],
    frame: Frame,
    results,
    truth: Mapping[str, tuple[gtsam.Pose3, Wireframe]] | None = None,
    base_dir: str | Path | None = None,
    show_heatmaps: bool = True,
) -> list[Path]:
    """Writes one overlay PNG per camera for a frame: ``<out_dir>/overlay_<camera>.png``.

    The background is the frame's image for that camera when the frame names
    one and it can be read, else :func:`draw_view`. On it, for every vehicle
    (estimated or only detected): that camera's detection, the estimated
    wireframe, the true wireframe when ``truth`` is given, and the detection's
    heatmaps when it names a readable file and ``show_heatmaps`` is set. Each
    vehicle's id is on a tag above it, tags moved apart so that none hides
    another; keypoint indices are written only when at most
    :data:`_MAX_NUMBERED_VEHICLES` vehicles are in the frame.

    Args:
        out_dir: output folder (created).
        scene_cameras: camera name -> camera.
        frame: the frame (its detections and optional images).
        results: the frame's :class:`VehicleResult` list (or a
            :class:`~vfactor.result.FrameResult`).
        truth: vehicle id -> (true pose, true wireframe), or ``None``.
        base_dir: folder that relative image and heatmap paths start from
            (the scene's ``base_dir``).
        show_heatmaps: whether to blend in detection heatmaps.

    Returns:
        The paths written, in the order of ``scene_cameras``.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if hasattr(results, "vehicles"):
        results = results.vehicles
    results = list(results)
    truth = dict(truth or {})
    base_dir = Path(base_dir) if base_dir is not None else None
    by_id = {r.id: r for r in results}
    ids = list(dict.fromkeys([r.id for r in results] + frame.vehicle_ids() + list(truth)))
    written = []
    for name, camera in scene_cameras.items():
        img = None
        image = (frame.images or {}).get(name)
        image_path = resolve_path(image, base_dir) if image else None
        if image_path is not None:
            try:
                img = read_rgb(image_path)
            except (OSError, ValueError):
                img = None
            if img is not None:
                img = np.ascontiguousarray(img[..., ::-1])  # drawn in OpenCV's BGR
            else:
                log.warning("frame image for camera %r not readable: %s; drawing a stand-in", name, image_path)
        if img is None:
            img = draw_view(camera)
        else:
            _label_box(img, [name], corner="tl", scale=_font_scale(img.shape[1::-1]) * 1.1)
        tags = []
        for vid in ids:
            result = by_id.get(vid)
            detection = next((d for d in frame.detections if d.vehicle == vid and d.camera == name), None)
            est = result.keypoints_world if result is not None else None
            tr = truth[vid][1].in_world(truth[vid][0]) if vid in truth else None
            heat = None
            if show_heatmaps and detection is not None and detection.heatmaps:
                hp = resolve_path(detection.heatmaps, base_dir)
                if hp is not None and hp.is_file():
                    heat = np.load(hp)
                else:
                    log.warning("heatmaps of %r in camera %r not found: %s", vid, name, hp)
            if detection is None and est is None and tr is None:
                continue
            img = draw_overlay(
                img, camera, detection=detection, keypoints_world=est, truth_keypoints_world=tr,
                heatmaps=heat, legend=False, keypoint_numbers=len(ids) <= _MAX_NUMBERED_VEHICLES,
            )
            anchor = _vehicle_anchor(camera, img.shape[1::-1], est, detection)
            if anchor is not None:
                tags.append((vid, anchor))
        scale = _font_scale(img.shape[1::-1])
        _draw_tags(img, tags, scale)  # last, so that no vehicle's lines cover another's label
        _label_box(img, [f"t = {frame.t:.2f} s"], corner="tr", scale=scale * 0.8)
        _draw_legend(img, ["observed", "estimate"] + (["truth"] if truth else []), scale)
        path = out_dir / f"overlay_{name}.png"
        if not cv2.imwrite(str(path), img):
            raise OSError(f"could not write {path}")
        written.append(path)
    return written
