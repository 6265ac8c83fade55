"""Camera rigs for simulation: pole-mounted cameras looking down at the road.

Conventions (docs/conventions.md): world z up, the road is ``z = 0``; cameras use the
OpenCV frame (x right, y down, z forward) and are placed by ``world_T_camera``
(camera -> world, 4x4); pixels have their origin at the centre of the top-left
pixel, so the principal point of an ideal ``w x h`` camera is
``((w - 1) / 2, (h - 1) / 2)``.
"""

from __future__ import annotations

import math

import numpy as np

from vfactor.camera import Camera

__all__ = ["look_at", "intrinsics_from_hfov", "pole_camera", "intersection_rig"]


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Pose of a camera at ``eye`` whose optical axis points at ``target``.

    The camera's z axis points from ``eye`` to ``target``; its x axis (image
    right) is horizontal, ``z x up``; its y axis (image down) is ``z x x``, so
    that ``up`` appears upward in the image.

    Args:
        eye: (3,) camera centre in the world, metres.
        target: (3,) world point the camera looks at.
        up: (3,) world direction that should appear "up" in the image.

    Returns:
        4x4 ``world_T_camera`` (camera -> world).

    Raises:
        ValueError: ``eye`` equals ``target`` or the viewing direction is parallel to ``up``.

    Example:
        >>> T = look_at([0, -10, 5], [0, 0, 0])
        >>> bool(np.allclose(T[:3, 2], np.array([0, 10, -5]) / np.sqrt(125)))
        True
    """
    eye = np.asarray(eye, dtype=float).reshape(3)
    target = np.asarray(target, dtype=float).reshape(3)
    up = np.asarray(up, dtype=float).reshape(3)
    forward = target - eye
    distance = np.linalg.norm(forward)
    if distance < 1e-9:
        raise ValueError(f"look_at: eye and target coincide at {eye.tolist()}")
    z = forward / distance
    x = np.cross(z, up)
    norm_x = np.linalg.norm(x)
    if norm_x < 1e-9 * max(1.0, np.linalg.norm(up)):
        raise ValueError(f"look_at: viewing direction {z.tolist()} is parallel to up {up.tolist()}")
    x /= norm_x
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def intrinsics_from_hfov(hfov_deg: float, image_size: tuple[int, int]) -> np.ndarray:
    """Ideal pinhole ``K`` (square pixels, no skew) from a horizontal field of view.

    ``fx = fy = (w / 2) / tan(hfov / 2)``; the principal point is the image centre
    ``((w - 1) / 2, (h - 1) / 2)`` in vfactor's pixel convention.

    Args:
        hfov_deg: horizontal field of view, degrees, in (0, 180).
        image_size: ``(width, height)`` in pixels.

    Example:
        >>> K = intrinsics_from_hfov(90.0, (1280, 720))
        >>> round(float(K[0, 0]), 6), float(K[0, 2]), float(K[1, 2])
        (640.0, 639.5, 359.5)
    """
    if not 0.0 < hfov_deg < 180.0:
        raise ValueError(f"hfov_deg: expected a value in (0, 180), got {hfov_deg}")
    w, h = image_size
    f = 0.5 * w / math.tan(math.radians(hfov_deg) / 2.0)
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def pole_camera(
    name: str,
    pole_xy,
    height: float,
    target=(0.0, 0.0, 0.0),
    hfov_deg: float = 55.0,
    image_size: tuple[int, int] = (1280, 720),
    dist=None,
) -> Camera:
    """A camera on top of a pole at ``(x, y)``, ``height`` metres above the road, looking at ``target``.

    Args:
        name: camera name.
        pole_xy: (2,) foot of the pole on the road, world metres.
        height: camera height above the road (``z`` of its centre), metres.
        target: (3,) world point it looks at (image centre).
        hfov_deg: horizontal field of view, degrees.
        image_size: ``(width, height)`` in pixels.
        dist: optional OpenCV distortion ``[k1, k2, p1, p2(, k3)]``.
    """
    eye = np.array([pole_xy[0], pole_xy[1], height], dtype=float)
    return Camera(
        name=name,
        K=intrinsics_from_hfov(hfov_deg, image_size),
        world_T_camera=look_at(eye, target),
        dist=np.zeros(5) if dist is None else dist,
        image_size=tuple(image_size),
    )


def intersection_rig(
    num_cameras: int = 2,
    distance: float = 18.0,
    height: float = 7.5,
    hfov_deg: float = 55.0,
    image_size: tuple[int, int] = (1280, 720),
    first_azimuth_deg: float = 225.0,
) -> dict[str, Camera]:
    """Cameras on the corners of an intersection, all looking at its centre (the origin).

    Two cameras stand on opposite corners (each sees the vehicle from its own
    side, with little overlap); three or four take successive corners
    (``first_azimuth_deg``, then +180, +90, +270 degrees).

    Args:
        num_cameras: 1 to 4.
        distance: horizontal distance of each pole from the centre, metres.
        height: camera height, metres.
        hfov_deg: horizontal field of view, degrees.
        image_size: ``(width, height)`` in pixels.
        first_azimuth_deg: azimuth of ``cam0``'s pole, degrees counter-clockwise from world x.

    Returns:
        camera name (``cam0``, ``cam1``, ...) -> :class:`Camera`.
    """
    if not 1 <= num_cameras <= 4:
        raise ValueError(f"num_cameras: expected 1 to 4, got {num_cameras}")
    offsets = (0.0, 180.0, 90.0, 270.0)
    cameras = {}
    for i in range(num_cameras):
        a = math.radians(first_azimuth_deg + offsets[i])
        name = f"cam{i}"
        cameras[name] = pole_camera(
            name, (distance * math.cos(a), distance * math.sin(a)), height, hfov_deg=hfov_deg, image_size=image_size
        )
    return cameras
