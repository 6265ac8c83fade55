"""The 12-keypoint vehicle wireframe, the PASCAL3D+ car shapes and vehicle presets.

A :class:`Wireframe` holds the 12 keypoints in the body frame (x forward, y
left, z up, origin at the centroid of the four wheel hubs), in metres and in
the fixed keypoint order of :mod:`vfactor.keypoints`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

import gtsam
import numpy as np

from vfactor.keypoints import LAYER_NAMES, LAYERS, MIRROR_PERMUTATION, NUM_KEYPOINTS

__all__ = [
    "Wireframe",
    "VehiclePreset",
    "PRESETS",
    "pascal3d_shapes",
    "template_shape",
    "preset",
    "symmetrised",
]


def symmetrised(points: np.ndarray) -> np.ndarray:
    """Averages each keypoint with the mirror image of its left/right partner (exact symmetry about y = 0).

    Args:
        points: (..., 12, 3) keypoints in the body frame (one shape or a stack).
    """
    points = np.asarray(points, dtype=float)
    return 0.5 * (points + points[..., MIRROR_PERMUTATION, :] * [1.0, -1.0, 1.0])


class Wireframe:
    """12 body-frame keypoints of one vehicle, metres (read-only).

    Args:
        vehicle_p_keypoints: (12, 3) keypoints in the body frame, fixed order.
    """

    __slots__ = ("_points",)

    def __init__(self, vehicle_p_keypoints):
        points = np.array(vehicle_p_keypoints, dtype=float)
        if points.shape != (NUM_KEYPOINTS, 3):
            raise ValueError(f"vehicle_p_keypoints: expected shape (12, 3), got {points.shape}")
        if not np.all(np.isfinite(points)):
            raise ValueError("vehicle_p_keypoints: contains NaN or infinite entries")
        points.setflags(write=False)
        self._points = points

    @property
    def vehicle_p_keypoints(self) -> np.ndarray:
        """(12, 3) keypoints in the body frame, metres."""
        return self._points

    def layer(self, name: str) -> np.ndarray:
        """(4, 3) points of a layer ("wheel", "light" or "roof")."""
        return self._points[list(LAYERS[name])]

    def layer_vectors(self) -> dict[str, np.ndarray]:
        """Each layer as a 12-vector ``[p_lf, p_rf, p_lb, p_rb]`` (the graph's storage)."""
        return {name: self.layer(name).ravel().copy() for name in LAYER_NAMES}

    @classmethod
    def from_layer_vectors(cls, layers: dict[str, np.ndarray]) -> "Wireframe":
        """Inverse of :meth:`layer_vectors`."""
        return cls(np.concatenate([np.asarray(layers[name], float).reshape(4, 3) for name in LAYER_NAMES]))

    def in_world(self, world_T_vehicle: gtsam.Pose3) -> np.ndarray:
        """(12, 3) keypoints in the world frame for a vehicle pose."""
        T = world_T_vehicle.matrix()
        return self._points @ T[:3, :3].T + T[:3, 3]

    def mirrored(self) -> "Wireframe":
        """The wireframe with left and right labels swapped and y negated (a true mirror image)."""
        return Wireframe(self._points[MIRROR_PERMUTATION] * [1.0, -1.0, 1.0])

    def scaled(self, factor: float) -> "Wireframe":
        return Wireframe(self._points * factor)

    @property
    def wheelbase(self) -> float:
        """Mean front-to-back wheel hub distance, metres."""
        p = self._points
        return 0.5 * (np.linalg.norm(p[0] - p[2]) + np.linalg.norm(p[1] - p[3]))

    @property
    def track(self) -> float:
        """Mean left-to-right wheel hub distance, metres."""
        p = self._points
        return 0.5 * (np.linalg.norm(p[0] - p[1]) + np.linalg.norm(p[2] - p[3]))

    @property
    def diagonal(self) -> float:
        """Diagonal of the keypoints' axis-aligned box, metres (a size scale)."""
        return float(np.linalg.norm(self._points.max(0) - self._points.min(0)))

    def __eq__(self, other):
        return isinstance(other, Wireframe) and np.array_equal(self._points, other._points)

    def __hash__(self):
        return hash(self._points.tobytes())

    def __repr__(self):
        return f"Wireframe(wheelbase={self.wheelbase:.3f} m, track={self.track:.3f} m)"


@lru_cache(maxsize=1)
def _pascal3d_data() -> dict:
    with resources.files("vfactor.data").joinpath("pascal3d_car_shapes.json").open("r", encoding="utf-8") as f:
        return json.load(f)


def pascal3d_shapes() -> np.ndarray:
    """The nine PASCAL3D+ car CAD models, (9, 12, 3), in wheelbase units.

    Multiply by a wheelbase in metres to get metric shapes. Source and licence:
    ``vfactor/data/pascal3d_car_shapes.json``.
    """
    data = _pascal3d_data()
    return np.array([m["keypoints_wheelbase_units"] for m in data["models"]], dtype=float)


def template_shape() -> np.ndarray:
    """Mean of the PASCAL3D+ shapes after exact left/right symmetrisation, (12, 3), wheelbase units."""
    mean = pascal3d_shapes().mean(axis=0)
    return 0.5 * (mean + mean[MIRROR_PERMUTATION] * [1.0, -1.0, 1.0])


@dataclass(frozen=True)
class VehiclePreset:
    """A vehicle with published exterior dimensions (metres).

    The wireframe is the PASCAL3D+ mean shape stretched to these dimensions:
    hubs at ``+-wheelbase/2`` and ``+-track/2``; the lights spaced over
    ``light_span`` of the length with the template's overhang split; the roof
    keypoints ``roof_gap`` below the overall height; the light layer scaled in
    height with the roof. ``rear_window_x`` (in wheelbases, body frame) moves the
    rear-window top, e.g. to the back of a pickup's cab.
    """

    name: str
    length: float
    width: float
    height: float
    wheelbase: float
    wheel_radius: float = 0.33
    track_over_width: float = 0.86
    light_span: float = 0.96
    roof_gap: float = 0.06
    rear_window_x: float | None = None
    windshield_x: float | None = None
    source: str = ""

    def wireframe(self) -> Wireframe:
        t = template_shape()
        wb = self.wheelbase
        p = t * wb
        p[:4, 0] = [0.5 * wb, 0.5 * wb, -0.5 * wb, -0.5 * wb]
        # x: wheels exactly at +-wb/2; lights over light_span * length with the template's overhang ratio.
        front_over = t[4, 0] - 0.5
        back_over = -0.5 - t[6, 0]
        extra = self.light_span * self.length - wb
        p[[4, 5], 0] = 0.5 * wb + extra * front_over / (front_over + back_over)
        p[[6, 7], 0] = -0.5 * wb - extra * back_over / (front_over + back_over)
        if self.windshield_x is not None:
            p[[8, 9], 0] = self.windshield_x * wb
        if self.rear_window_x is not None:
            p[[10, 11], 0] = self.rear_window_x * wb
        # y: scale so that the track is track_over_width * width.
        track = self.track_over_width * self.width
        p[:, 1] = t[:, 1] * track / (2 * t[0, 1])
        p[:4, 1] = [0.5 * track, -0.5 * track, 0.5 * track, -0.5 * track]  # the wheel layer is a rectangle
        # z: hubs at 0 (origin), roof keypoints roof_gap below the top, lights scaled alike.
        roof_z = self.height - self.wheel_radius - self.roof_gap
        scale_z = roof_z / t[8:, 2].mean()
        p[:, 2] = t[:, 2] * scale_z
        p[:4, 2] = 0.0
        return Wireframe(p)


_DIMS = "manufacturer's published exterior dimensions"

#: Presets: the paper's three simulated vehicles and a few more body types.
PRESETS: dict[str, VehiclePreset] = {
    p.name: p
    for p in (
        VehiclePreset("lincoln_mkz", 4.925, 1.864, 1.476, 2.850, 0.34, source=f"Lincoln MKZ 2017, {_DIMS}"),
        VehiclePreset("toyota_prius", 4.540, 1.760, 1.470, 2.700, 0.32, source=f"Toyota Prius 2016 (XW50), {_DIMS}"),
        VehiclePreset("bmw_x5", 4.886, 1.938, 1.762, 2.933, 0.38, source=f"BMW X5 2014 (F15), {_DIMS}"),
        VehiclePreset("hatchback", 4.255, 1.799, 1.452, 2.637, 0.32, source=f"Volkswagen Golf Mk7, {_DIMS}"),
        VehiclePreset("suv", 4.600, 1.855, 1.685, 2.690, 0.37, source=f"Toyota RAV4 2019 (XA50), {_DIMS}"),
        VehiclePreset(
            "pickup", 5.890, 2.029, 1.961, 3.683, 0.42, rear_window_x=-0.05, roof_gap=0.08,
            source=f"Ford F-150 2015 SuperCrew 5.5 ft, {_DIMS}",
        ),
        VehiclePreset(
            "van", 4.972, 1.986, 1.990, 2.933, 0.35, windshield_x=0.30, rear_window_x=-0.78, roof_gap=0.10,
            source=f"Ford Transit Custom 2013 SWB, {_DIMS}",
        ),
    )
}


def preset(name: str) -> VehiclePreset:
    """Returns the preset ``name``; raises ``ValueError`` listing the known names."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"vehicle preset: unknown name {name!r}; known: {sorted(PRESETS)}") from None
