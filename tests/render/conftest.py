"""Fixtures for the rendering tests: a shared renderer (skipped where no EGL/moderngl) and scene helpers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vfactor.render.renderer import Light, RenderingUnavailable, get_context
from vfactor.sim.rig import pole_camera
from vfactor.sim.vehicles import road_pose
from vfactor.wireframe import PRESETS


@pytest.fixture(scope="session")
def gl_context():
    try:
        return get_context()
    except RenderingUnavailable as exc:
        pytest.skip(f"no OpenGL rendering here: {exc}")


#: Flat lighting: colours come out as albedo * 0.75 (vertical faces) .. 1.0 (horizontal), no shadows.
FLAT = Light(direction=(0.0, 0.0, 1.0), diffuse=0.0, ambient=1.0, sky=(1.0, 1.0, 1.0), shadows=False,
             contact_shadow=0.0)


def prius_on_road(yaw=0.4, x=1.0, y=-2.0):
    p = PRESETS["toyota_prius"]
    return p.wireframe(), road_pose(x, y, yaw, p.wheel_radius), p.wheel_radius


def camera_around(pose, azimuth_deg, height, distance, size=(640, 480), hfov_deg=40.0, dist=None):
    """A pole camera at ``azimuth_deg`` around the vehicle (0 = in front of it, 90 = on its left)."""
    t = pose.translation()
    yaw = pose.rotation().yaw()
    a = yaw + math.radians(azimuth_deg)
    return pole_camera("c", (t[0] + distance * math.cos(a), t[1] + distance * math.sin(a)), height,
                       target=(t[0], t[1], 0.6), hfov_deg=hfov_deg, image_size=size, dist=dist)


def blob_centroid(mask: np.ndarray, near_uv, radius: float = 12.0) -> np.ndarray:
    """Centroid (u, v) of the mask pixels within ``radius`` of ``near_uv``."""
    v, u = np.nonzero(mask)
    keep = np.hypot(u - near_uv[0], v - near_uv[1]) <= radius
    assert keep.any(), "no mask pixels near the point"
    return np.array([u[keep].mean(), v[keep].mean()])
