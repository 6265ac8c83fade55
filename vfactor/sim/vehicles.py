"""Simulated vehicles: shapes (library vehicles, presets or random PASCAL3D+ cars) and poses on the road.

A scenario names each vehicle by a preset name, a library id
(:mod:`vfactor.vehicle_library`), ``"library"`` (any library vehicle),
``"library:<body type>"`` (one of that type) or ``"random"`` (a random
PASCAL3D+ car); :func:`draw_vehicle` turns the name into a shape.

A vehicle stands on the road ``z = 0`` with roll = pitch = 0. Its body origin is
the centroid of the four wheel hubs (docs/conventions.md), so the origin lies
``wheel_radius`` above the road and the road is the body plane
``z = -wheel_radius``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import lru_cache

import gtsam
import numpy as np

from vfactor.keypoints import LAYERS
from vfactor.shape_model import DISTANCE_PAIRS, HwcBounds, default_hwc_bounds
from vfactor.vehicle_library import BODY_TYPES, library_ids, vehicle_library
from vfactor.wireframe import PRESETS, Wireframe, pascal3d_shapes, symmetrised

__all__ = [
    "RANDOM",
    "LIBRARY",
    "RandomShape",
    "random_wireframe",
    "symmetrised",
    "vehicle_shape",
    "draw_vehicle",
    "check_vehicle_name",
    "vehicle_names",
    "within_hwc_bounds",
    "road_pose",
    "footprint",
    "footprints_overlap",
]

#: Vehicle name that asks for a random PASCAL3D+ shape instead of a preset.
RANDOM = "random"
#: Vehicle name that asks for a random library vehicle; ``"library:<body type>"`` for one of a type.
LIBRARY = "library"


@dataclass(frozen=True)
class RandomShape:
    """How random vehicle shapes are drawn.

    Attributes:
        wheelbase: ``(min, max)`` of the uniform wheelbase, metres.
        jitter: standard deviation of the Gaussian noise added to every
            keypoint coordinate (before symmetrisation), metres; also added to
            library vehicles (the lamps and window tops are placed by rules,
            docs/vehicles.md: a real vehicle departs from them).
        wheel_radius: wheel radius (hub height above the road), metres.
        max_tries: draws before giving up on a shape inside the HWC bounds.
    """

    wheelbase: tuple[float, float] = (2.5, 3.0)
    jitter: float = 0.03
    wheel_radius: float = 0.33
    max_tries: int = 100


def random_wireframe(
    rng: np.random.Generator, spec: RandomShape = RandomShape(), bounds: HwcBounds | None = None
) -> Wireframe:
    """A random car: one PASCAL3D+ model times a random wheelbase, jittered (the hubs kept level), symmetrised.

    The shape is re-centred on its wheel-hub centroid and redrawn until it lies
    within the HWC ``bounds`` (default: the region random cars have always been drawn in, ``_draw_bounds``).

    Args:
        rng: random generator (the only source of randomness).
        spec: wheelbase range, jitter and number of tries.
        bounds: HWC bounds the shape must satisfy.

    Raises:
        RuntimeError: no shape within the bounds after ``spec.max_tries`` draws.
    """
    return _random_pascal3d(rng, spec, bounds)[0]


def _random_pascal3d(rng: np.random.Generator, spec: RandomShape, bounds: HwcBounds | None) -> tuple[Wireframe, int]:
    """:func:`random_wireframe` and the index of the PASCAL3D+ model drawn."""
    bounds = _draw_bounds() if bounds is None else bounds
    shapes = pascal3d_shapes()
    for _ in range(spec.max_tries):
        index = int(rng.integers(len(shapes)))
        model = shapes[index]
        wheelbase = rng.uniform(*spec.wheelbase)
        points = model * wheelbase + rng.normal(0.0, spec.jitter, size=model.shape)
        points = symmetrised(points)
        if spec.jitter > 0:
            points[:4, 2] = 0.0  # the jitter must not tilt the body frame: the hubs stay level (docs/conventions.md)
        points -= points[list(LAYERS["wheel"])].mean(axis=0)
        wireframe = Wireframe(points)
        if within_hwc_bounds(wireframe, bounds):
            return wireframe, index
    raise RuntimeError(f"random_wireframe: no shape within the HWC bounds after {spec.max_tries} draws")


@lru_cache(maxsize=1)
def _draw_bounds() -> HwcBounds:
    """Where random PASCAL3D+ cars are drawn: the bounds of the cars and the library alone
    (``default_hwc_bounds(road_extremes=False)``) with their layer offsets as :class:`HwcBounds` stored them until
    2026-12-07 (transposed: the x range ``[x_min, z_min]``, the z range ``[x_max, z_max]``), so that every seed
    keeps its scene."""
    bounds = default_hwc_bounds(road_extremes=False)
    return dataclasses.replace(bounds, layer_offset={k: np.asarray(v).T.copy() for k, v in bounds.layer_offset.items()})


def within_hwc_bounds(wireframe: Wireframe, bounds: HwcBounds | None = None) -> bool:
    """Whether a wireframe satisfies every HWC range: distances, trapezoid width ratios, layer offsets."""
    bounds = default_hwc_bounds() if bounds is None else bounds
    p = wireframe.vehicle_p_keypoints
    d = np.linalg.norm(p[DISTANCE_PAIRS[:, 0]] - p[DISTANCE_PAIRS[:, 1]], axis=1)
    if np.any(d < bounds.distance[:, 0]) or np.any(d > bounds.distance[:, 1]):
        return False
    wheel_centroid = p[list(LAYERS["wheel"])].mean(axis=0)
    for name, (lo, hi) in bounds.width_ratio.items():
        lf, rf, lb, rb = LAYERS[name]
        ratio = np.linalg.norm(p[lf] - p[rf]) / np.linalg.norm(p[lb] - p[rb])
        if not lo <= ratio <= hi:
            return False
    for name, box in bounds.layer_offset.items():
        off = (p[list(LAYERS[name])].mean(axis=0) - wheel_centroid)[[0, 2]]
        if np.any(off < box[:, 0]) or np.any(off > box[:, 1]):
            return False
    return True


def vehicle_names() -> tuple[str, ...]:
    """Every vehicle name a scenario may use: presets, library ids, ``library``, ``library:<type>``, ``random``."""
    return (*PRESETS, *library_ids(), LIBRARY, *(f"{LIBRARY}:{t}" for t in BODY_TYPES), RANDOM)


def check_vehicle_name(name: str) -> str:
    """``name`` if a scenario may use it; raises ``ValueError`` listing the kinds of name otherwise."""
    if name in PRESETS or name in (RANDOM, LIBRARY) or name in vehicle_library():
        return name
    if name.startswith(f"{LIBRARY}:") and name.split(":", 1)[1] in BODY_TYPES:
        return name
    raise ValueError(f"vehicle: unknown name {name!r}; expected a preset ({', '.join(sorted(PRESETS))}), a library id "
                     f"(vfactor.vehicle_library.library_ids()), {LIBRARY!r}, '{LIBRARY}:<body type>' with a body type "
                     f"of {', '.join(BODY_TYPES)}, or {RANDOM!r}")


def draw_vehicle(
    name: str, rng: np.random.Generator, random_shape: RandomShape = RandomShape()
) -> tuple[Wireframe, float, str]:
    """Shape, wheel radius and model name of a scenario's vehicle name.

    A preset is returned as it is. A library vehicle (by id, or drawn with
    ``"library"`` / ``"library:<body type>"``) gets ``random_shape.jitter`` on
    every keypoint, symmetrised and re-centred. ``"random"`` is a random
    PASCAL3D+ car (:func:`random_wireframe`).

    Returns:
        (wireframe in metres, wheel radius in metres, model: the preset name,
        the library id, or ``"pascal3d_<index>"`` for a random PASCAL3D+ car).

    Raises:
        ValueError: unknown name.
    """
    check_vehicle_name(name)
    if name == RANDOM:
        wireframe, index = _random_pascal3d(rng, random_shape, None)
        return wireframe, random_shape.wheel_radius, f"pascal3d_{index}"
    if name in PRESETS:
        p = PRESETS[name]
        return p.wireframe(), p.wheel_radius, name
    if name == LIBRARY or name.startswith(f"{LIBRARY}:"):
        ids = library_ids(name.split(":", 1)[1] if ":" in name else None)
        name = ids[rng.integers(len(ids))]
    vehicle = vehicle_library()[name]
    points = vehicle.wireframe.vehicle_p_keypoints
    if random_shape.jitter > 0:
        points = symmetrised(points + rng.normal(0.0, random_shape.jitter, size=points.shape))
        points[:4, 2] = 0.0  # the hubs stay level at the origin's height
        points -= points[list(LAYERS["wheel"])].mean(axis=0)
    return Wireframe(points), vehicle.wheel_radius, name


def vehicle_shape(
    name: str, rng: np.random.Generator, random_shape: RandomShape = RandomShape()
) -> tuple[Wireframe, float]:
    """Shape and wheel radius of a vehicle name (:func:`draw_vehicle` without the model name).

    Returns:
        (wireframe in metres, wheel radius in metres).

    Raises:
        ValueError: unknown name.
    """
    wireframe, radius, _ = draw_vehicle(name, rng, random_shape)
    return wireframe, radius


def road_pose(x: float, y: float, yaw: float, wheel_radius: float) -> gtsam.Pose3:
    """``world_T_vehicle`` of a vehicle standing on the road at ``(x, y)`` heading ``yaw`` (rad, from world x)."""
    return gtsam.Pose3(gtsam.Rot3.Yaw(yaw), np.array([x, y, wheel_radius], dtype=float))


def footprint(wireframe: Wireframe, world_T_vehicle: gtsam.Pose3, pad: float = 0.1) -> np.ndarray:
    """(4, 2) corners (counter-clockwise) of the vehicle's rectangle on the road, world x-y, metres.

    The rectangle spans the keypoints' body x and y ranges grown by ``pad`` on every side.
    """
    p = wireframe.vehicle_p_keypoints
    x0, x1 = p[:, 0].min() - pad, p[:, 0].max() + pad
    y0, y1 = p[:, 1].min() - pad, p[:, 1].max() + pad
    corners = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
    T = world_T_vehicle.matrix()
    return (corners @ T[:3, :3].T + T[:3, 3])[:, :2]


def footprints_overlap(a: np.ndarray, b: np.ndarray, gap: float = 0.0) -> bool:
    """Whether two convex polygons (N, 2) come closer than ``gap`` along some separating axis.

    Separating-axis test over the edge normals of both polygons: the polygons
    are apart when, on at least one axis, their projections are separated by
    ``gap`` or more.
    """
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        pa, pb = a @ normals.T, b @ normals.T
        separation = np.maximum(pb.min(0) - pa.max(0), pa.min(0) - pb.max(0))
        if np.any(separation >= gap):
            return False
    return True
