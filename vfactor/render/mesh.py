"""Textured low-poly vehicle meshes built around a 12-keypoint wireframe (NumPy only).

A vehicle mesh is built in the body frame (x forward, y left, z up, origin at
the centroid of the four wheel hubs; docs/conventions.md) so that every keypoint lies
exactly on the feature it names:

* wheel hubs (0-3): the centre of the hub cap, in the plane of the rim disc,
  the wheel's outermost surface; the tyre is a cylinder of radius = hub height
  above the road (so it touches the road) whose outer face lies 6 mm inside;
* lights (4-7): the outer corner of a light that wraps around the body's
  corner: the keypoint lies on the vertical edge where the front (back) face
  meets the tapered side, at the light's mid-height; the light covers both
  faces next to that edge (so, as on real cars, it is seen from the side too);
* roof (8-11): the top corners of the windshield and of the rear window, which
  are mesh vertices shared by the glass, the roof and the cabin sides.

The body is a loft of cross-sections along x: lower body (sides with wheel
arches cut around the hubs, a darker sill trim, bumpers, hood and rear deck
rising to the belt line) and a cabin (windshield, roof, rear window, side
windows split by pillars). Wheels are dark cylinders with a lighter rim disc.

For a left/right symmetric wireframe (the presets and the random PASCAL3D+
shapes) the mesh is built from the wireframe directly. An asymmetric wireframe
is built from its symmetrised copy and then bent by a 3D thin-plate spline that
moves the symmetrised keypoints exactly onto the given ones, so the annotations
stay exact.

A :class:`Mesh` is a triangle soup with per-triangle colour (sRGB in [0, 1]),
part label (:class:`Part`), specular strength and emission; it carries no
OpenGL state, so meshes can be built, transformed and tested without a GPU
context.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass, field, replace
from enum import IntEnum

import numpy as np

from vfactor.keypoints import MIRROR_PERMUTATION
from vfactor.wireframe import Wireframe

__all__ = [
    "Part",
    "Mesh",
    "Appearance",
    "VehicleGeometry",
    "vehicle_geometry",
    "vehicle_mesh",
    "box_mesh",
    "cylinder_mesh",
    "quad_mesh",
    "DECAL_OFFSET",
]

#: Distance (m) between a grille / plate patch and the painted face behind it.
DECAL_OFFSET = 0.004
#: Radius of the hub's centre cap / wheel radius (the cap's centre is the hub keypoint).
_CAP_FRACTION = 0.17
#: Distance (m) between the rim disc and the tyre's outer face behind it.
_TYRE_INSET = 0.006
_WHEEL_SEGMENTS = 18
_ARCH_SEGMENTS = 8


class Part(IntEnum):
    """Labels of the rendered surfaces (the renderer's ``part_ids``); 0 where nothing is drawn."""

    NONE = 0
    GROUND = 1
    BODY = 2
    TRIM = 3
    GLASS = 4
    TYRE = 5
    RIM = 6
    HEAD_LIGHT = 7
    TAIL_LIGHT = 8
    GRILLE = 9
    PLATE = 10
    UNDERBODY = 11
    OCCLUDER = 12
    DECAL = 13


@dataclass
class Mesh:
    """A triangle soup with flat per-triangle attributes.

    Attributes:
        triangles: (T, 3, 3) vertex positions, metres (the frame is the caller's:
            body frame for :func:`vehicle_mesh`, world frame once transformed).
        colors: (T, 3) albedo, sRGB in [0, 1].
        parts: (T,) :class:`Part` labels.
        specular: (T,) Blinn-Phong specular strength (0 = matte).
        emission: (T,) self-illumination in [0, 1] (lights).
    """

    triangles: np.ndarray
    colors: np.ndarray
    parts: np.ndarray
    specular: np.ndarray
    emission: np.ndarray

    def __post_init__(self):
        self.triangles = np.asarray(self.triangles, dtype=float).reshape(-1, 3, 3)
        n = len(self.triangles)
        self.colors = np.asarray(self.colors, dtype=np.float32).reshape(n, 3)
        self.parts = np.asarray(self.parts, dtype=np.int16).reshape(n)
        self.specular = np.asarray(self.specular, dtype=np.float32).reshape(n)
        self.emission = np.asarray(self.emission, dtype=np.float32).reshape(n)

    def __len__(self) -> int:
        return len(self.triangles)

    @property
    def vertices(self) -> np.ndarray:
        """(3T, 3) all vertex positions."""
        return self.triangles.reshape(-1, 3)

    def transformed(self, T) -> "Mesh":
        """The mesh moved by a 4x4 transform or a ``gtsam.Pose3`` (e.g. ``world_T_vehicle``)."""
        T = np.asarray(T.matrix() if hasattr(T, "matrix") else T, dtype=float)
        tri = self.triangles @ T[:3, :3].T + T[:3, 3]
        return replace(self, triangles=tri)

    def face_normals(self) -> np.ndarray:
        """(T, 3) unit normals (orientation arbitrary: the renderer shades both sides)."""
        t = self.triangles
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return n / np.maximum(length, 1e-12)

    @staticmethod
    def concatenate(meshes) -> "Mesh":
        meshes = [m for m in meshes if m is not None and len(m)]
        if not meshes:
            return Mesh(np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0))
        return Mesh(
            np.concatenate([m.triangles for m in meshes]),
            np.concatenate([m.colors for m in meshes]),
            np.concatenate([m.parts for m in meshes]),
            np.concatenate([m.specular for m in meshes]),
            np.concatenate([m.emission for m in meshes]),
        )


# --------------------------------------------------------------------------- appearance
def _hex(rgb):
    return tuple(float(c) for c in rgb)


@dataclass(frozen=True)
class Appearance:
    """Colours and the few free shape details of a rendered vehicle.

    Colours are sRGB triples in [0, 1]. Lengths are metres.

    Attributes:
        paint: body colour.
        trim: lower trim (sills, bumpers) colour; ``None`` -> a darkened paint.
        roof: roof colour; ``None`` -> the paint (a black roof is a common variant).
        pillars: pillar colour; ``None`` -> the paint.
        glass, tyre, rim, cap, head_light, tail_light, grille, plate, underbody: part colours.
        paint_specular, glass_specular: Blinn-Phong strengths.
        light_emission: self-illumination of the light patches (0: off).
        texture: amplitude of the renderer's procedural surface noise (dirt, panels).
        head_light_size, tail_light_size: (width on the end face along y, half height along z) of the
            lights; each also wraps ``light_wrap`` metres back along the side.
        light_wrap: length of the lights along the tapered sides.
        clearance: sill height above the road.
        tyre_width: tyre width (the tyre's outer face is at the hub keypoint).
        rim_fraction: rim disc radius / wheel radius.
        windshield_rake_deg: windshield angle from the horizontal.
        rear_rake_deg: rear-window angle from the horizontal; ``None``: 32 degrees,
            or near-vertical when a long deck follows (a pickup's cab).
        tumblehome: inward step of the cabin sides over the body sides at the belt line.
    """

    paint: tuple = (0.55, 0.57, 0.6)
    trim: tuple | None = None
    roof: tuple | None = None
    pillars: tuple | None = None
    glass: tuple = (0.12, 0.16, 0.2)
    tyre: tuple = (0.06, 0.06, 0.065)
    rim: tuple = (0.62, 0.63, 0.65)
    cap: tuple = (0.25, 0.25, 0.27)
    head_light: tuple = (0.95, 0.95, 0.88)
    tail_light: tuple = (0.85, 0.08, 0.06)
    grille: tuple = (0.08, 0.08, 0.09)
    plate: tuple = (0.92, 0.92, 0.9)
    underbody: tuple = (0.05, 0.05, 0.05)
    paint_specular: float = 0.35
    glass_specular: float = 0.45
    light_emission: float = 0.35
    texture: float = 0.05
    head_light_size: tuple = (0.22, 0.055)
    tail_light_size: tuple = (0.2, 0.06)
    light_wrap: float = 0.14
    clearance: float = 0.16
    tyre_width: float = 0.21
    rim_fraction: float = 0.62
    windshield_rake_deg: float = 30.0
    rear_rake_deg: float | None = None
    tumblehome: float = 0.07

    @property
    def trim_color(self):
        return self.trim if self.trim is not None else tuple(0.35 * c for c in self.paint)

    @classmethod
    def random(cls, rng: np.random.Generator, paint=None) -> "Appearance":
        """A random appearance (colours, light sizes, rakes, clearance) drawn from ``rng``.

        Args:
            rng: the only source of randomness.
            paint: the body colour (sRGB); ``None`` draws one with :func:`random_paint`.
        """
        paint = random_paint(rng) if paint is None else tuple(paint)
        u = rng.uniform(size=16)
        trim_kind = u[0]
        if trim_kind < 0.5:
            trim = tuple(float(v) for v in np.full(3, 0.05 + 0.08 * u[1]))  # black plastic
        elif trim_kind < 0.8:
            trim = None  # darker paint
        else:
            trim = paint  # body-coloured bumpers
        roof = (0.05, 0.05, 0.06) if u[2] < 0.12 else None
        pillars = (0.05, 0.05, 0.06) if u[3] < 0.5 else None
        glass_v = 0.08 + 0.14 * u[4]
        glass = (glass_v * 0.85, glass_v * (0.95 + 0.1 * u[5]), glass_v * 1.15)
        rim_v = 0.2 + 0.55 * u[6]
        return cls(
            paint=_hex(paint),
            trim=trim,
            roof=roof,
            pillars=pillars,
            glass=glass,
            rim=(rim_v, rim_v, rim_v * 1.03),
            cap=(0.15 + 0.5 * u[7],) * 3,
            head_light=(0.85 + 0.15 * u[8], 0.85 + 0.15 * u[8], 0.78 + 0.15 * u[8]),
            tail_light=(0.65 + 0.3 * u[9], 0.04 + 0.1 * u[9], 0.04),
            paint_specular=0.15 + 0.45 * u[10],
            glass_specular=rng.uniform(0.2, 0.6),
            light_emission=0.5 * u[11] if rng.uniform() < 0.7 else 0.0,
            texture=0.02 + 0.08 * u[12],
            head_light_size=(0.16 + 0.14 * u[13], 0.045 + 0.03 * rng.uniform()),
            tail_light_size=(0.14 + 0.16 * u[14], 0.045 + 0.035 * rng.uniform()),
            light_wrap=rng.uniform(0.06, 0.2),
            clearance=0.13 + 0.07 * u[15],
            tyre_width=rng.uniform(0.18, 0.26),
            rim_fraction=rng.uniform(0.52, 0.72),
            windshield_rake_deg=rng.uniform(24.0, 40.0),
            tumblehome=rng.uniform(0.04, 0.11),
        )


def random_paint(rng: np.random.Generator, hue_ok=None, grey_ok=None) -> tuple:
    """A car paint colour: achromatic (white, silver, grey, black) 55 % of the time, else a hue.

    Args:
        rng: the only source of randomness.
        hue_ok: optional predicate on the hue in degrees [0, 360) (rejection-sampled).
        grey_ok: optional predicate on the grey level in [0, 1] (rejection-sampled).
    """
    for _ in range(1000):
        if rng.uniform() < 0.55:
            v = float(rng.uniform(0.04, 0.95))
            if grey_ok is None or grey_ok(v):
                tint = rng.normal(0.0, 0.01, size=3)
                return tuple(float(c) for c in np.clip(v + tint, 0.0, 1.0))
        else:
            h = float(rng.uniform(0.0, 360.0))
            if hue_ok is None or hue_ok(h):
                s = rng.uniform(0.35, 0.95)
                v = rng.uniform(0.2, 0.9)
                return tuple(float(c) for c in colorsys.hsv_to_rgb(h / 360.0, s, v))
    raise RuntimeError("random_paint: the hue/grey predicates reject everything")


# --------------------------------------------------------------------------- geometry
@dataclass(frozen=True)
class VehicleGeometry:
    """Derived dimensions of a vehicle mesh (body frame, metres; left side, y > 0).

    Attributes:
        wheel_radius: hub height above the road; the road is body ``z = -wheel_radius``.
        half_width: body side ``|y|`` between the axles.
        front_half_width, rear_half_width: ``|y|`` of the front and back faces' sides.
        x_front, x_rear: the front/back face planes (the light keypoints' x).
        front_wrap, rear_wrap: how far the lights wrap back along the sides.
        z_sill: lowest edge of the body sides.
        z_belt: belt line (bottom of the side windows, top of the hood at the cowl).
        z_front_top, z_rear_top: top edges of the front and back faces.
        x_windshield_base, x_rear_window_base: x where the glass meets the hood / deck.
        arch_radius: (2,) radius of the front and rear wheel arches.
        stations: x of the loft's cross-sections, rear to front.
    """

    wheel_radius: float
    half_width: float
    front_half_width: float
    rear_half_width: float
    x_front: float
    x_rear: float
    front_wrap: float
    rear_wrap: float
    z_sill: float
    z_belt: float
    z_front_top: float
    z_rear_top: float
    x_windshield_base: float
    x_rear_window_base: float
    arch_radius: tuple
    stations: np.ndarray = field(repr=False)
    z_bottom: np.ndarray = field(repr=False)
    z_top: np.ndarray = field(repr=False)
    widths: np.ndarray = field(repr=False)

    def width_at(self, x: float) -> float:
        return float(np.interp(x, self.stations, self.widths))


def _symmetrised(points: np.ndarray) -> np.ndarray:
    return 0.5 * (points + points[MIRROR_PERMUTATION] * [1.0, -1.0, 1.0])


#: :func:`vehicle_mesh` adds a roof box only where the roof stands at least this far (metres) above the window tops.
_MIN_ROOF_BOX = 0.01


def vehicle_geometry(wireframe: Wireframe, appearance: Appearance | None = None, wheel_radius: float = 0.33):
    """The loft's dimensions for a (symmetrised) wireframe; see :class:`VehicleGeometry`."""
    a = Appearance() if appearance is None else appearance
    s = _symmetrised(np.asarray(wireframe.vehicle_p_keypoints, dtype=float))
    r = float(wheel_radius)
    if not 0.05 < r < 2.0:
        raise ValueError(f"wheel_radius: expected a hub height in (0.05, 2) m, got {wheel_radius}")
    hub_f, hub_b = s[0], s[2]
    light_f, light_b = s[4], s[6]
    wind, rear = s[8], s[10]
    if not (light_b[0] < hub_b[0] < hub_f[0] < light_f[0]):
        raise ValueError("wireframe: expected back light < back hub < front hub < front light along body x")
    hw_f, hh_f = a.head_light_size
    hw_b, hh_b = a.tail_light_size
    x_front = light_f[0]
    x_rear = light_b[0]
    length = x_front - x_rear

    # Widths: the body sides stand just outside the tyres' outer faces; the end faces end at the lights'
    # outer corners (the light keypoints), from where the sides taper out to the full width.
    front_hw = abs(light_f[1])
    rear_hw = abs(light_b[1])
    if min(front_hw, rear_hw) < 0.2:
        raise ValueError("wireframe: the lights are less than 0.2 m from the medial plane")
    half_width = max(abs(hub_f[1]), abs(hub_b[1]), front_hw + 0.02, rear_hw + 0.02) + 0.015

    # Heights.
    z_roof = min(wind[2], rear[2])
    z_sill = -r + a.clearance
    z_belt = max(light_b[2] + hh_b + 0.06, light_f[2] + 0.2, z_roof - 0.5)
    z_belt = min(z_belt, z_roof - 0.22)
    z_front_top = max(light_f[2] + hh_f + 0.05, min(light_f[2] + 0.15, z_belt - 0.02))
    z_rear_top = max(light_b[2] + hh_b + 0.04, min(light_b[2] + 0.12, z_belt))

    # Wheel arches: radius from each wheel's own hub height, kept clear of the ends and of each other.
    radii = []
    for hub, toward_end in ((hub_f, x_front - hub_f[0]), (hub_b, hub_b[0] - x_rear)):
        wr = r + hub[2]
        ra = 1.12 * wr + 0.03
        ra = min(ra, toward_end - 0.08, 0.5 * (hub_f[0] - hub_b[0]) - 0.08)
        radii.append(max(ra, 1.0 * wr + 0.005))
    ra_f, ra_b = radii

    # Glass bases (kept clear of the nose and tail bevels).
    nose = min(0.3, 0.1 * length)
    tail = min(0.25, 0.1 * length)
    x_wb = wind[0] + (wind[2] - z_belt) / np.tan(np.radians(a.windshield_rake_deg))
    x_wb = float(np.clip(x_wb, wind[0] + 0.05, max(x_front - 0.35, wind[0] + 0.05)))
    if x_wb >= x_front - nose:  # a windshield at the very front (a bus's top 0.15 m behind it): a shorter nose bevel
        nose = 0.5 * (x_front - x_wb)
    deck = rear[0] - x_rear
    rear_rake = a.rear_rake_deg
    if rear_rake is None:
        rear_rake = 82.0 if deck > 1.6 else 32.0
    x_rb = rear[0] - (rear[2] - z_belt) / np.tan(np.radians(rear_rake))
    x_rb = float(np.clip(x_rb, x_rear + tail + 0.05, rear[0] - 0.03))
    if x_rb >= x_wb - 0.2 or x_wb >= x_front - nose:
        raise ValueError("wireframe: the windshield and the rear window overlap; is the roof layer reversed?")

    # Loft stations (rear -> front): end faces, bevels, glass bases, even fill, wheel arches (semicircles
    # over each hub, with a doubled station at each arch end where the body bottom steps from the sill).
    arches = ((hub_b, ra_b), (hub_f, ra_f))

    def z_bottom_at(x):
        for hub, ra in arches:
            dx = x - hub[0]
            if abs(dx) < ra - 1e-9:
                return hub[2] + np.sqrt(ra * ra - dx * dx)
        return z_sill

    bump_bottom = z_sill + 0.03
    # The lights wrap back along the sides up to a station of their own, short of the arches.
    wrap_f = float(np.clip(a.light_wrap, 0.02, max(0.02, min(nose, (x_front - hub_f[0] - ra_f) - 0.05))))
    wrap_b = float(np.clip(a.light_wrap, 0.02, max(0.02, min(tail, (hub_b[0] - ra_b - x_rear) - 0.05))))
    stations = [(x_rear, bump_bottom, 0), (x_front, bump_bottom, 0)]
    inner_x = [x_rear + tail, x_rb, x_wb, x_front - nose] + list(np.linspace(x_rear, x_front, 12)[1:-1])
    inner_x = [x for x in inner_x if x_rear + wrap_b + 1e-3 < x < x_front - wrap_f - 1e-3]
    inner_x += [x_rear + wrap_b, x_front - wrap_f]
    ends = [hub[0] + sgn * ra for hub, ra in arches for sgn in (-1, 1)]
    stations += [(x, z_bottom_at(x), 0) for x in inner_x if min(abs(x - e) for e in ends) > 1e-3]
    for hub, ra in arches:
        theta = np.linspace(0.0, np.pi, _ARCH_SEGMENTS + 1)
        stations += [(hub[0] - ra * np.cos(t), hub[2] + ra * np.sin(t), 0) for t in theta[1:-1]]
        stations += [(hub[0] - ra, z_sill, 0), (hub[0] - ra, hub[2], 1)]  # sill, then up into the arch
        stations += [(hub[0] + ra, hub[2], 0), (hub[0] + ra, z_sill, 1)]  # down out of the arch, then sill
    stations.sort(key=lambda t: (t[0], t[2]))
    xs = np.array([t[0] for t in stations])
    zb = np.array([t[1] for t in stations])

    # Top profile: hood rising to the belt at the windshield base, flat under the cabin, deck down to the back.
    ctrl_x = [x_rear, x_rear + tail, x_rb, x_wb, x_front - nose, x_front]
    ctrl_z = [z_rear_top, min(z_rear_top + 0.04, z_belt), z_belt, z_belt, min(z_front_top + 0.05, z_belt), z_front_top]
    zt = np.interp(xs, ctrl_x, ctrl_z)
    zt = np.maximum(zt, zb + 0.1)  # fenders bulge over tall arches

    # Widths taper linearly into the end faces (over most of the overhang: the corners are chamfered).
    taper_f = max(0.6 * (x_front - hub_f[0]), wrap_f + 0.05)
    taper_b = max(0.6 * (hub_b[0] - x_rear), wrap_b + 0.05)
    wf = front_hw + (half_width - front_hw) * np.clip((x_front - xs) / taper_f, 0.0, 1.0)
    wb = rear_hw + (half_width - rear_hw) * np.clip((xs - x_rear) / taper_b, 0.0, 1.0)
    widths = np.minimum(wf, wb)

    return VehicleGeometry(
        wheel_radius=r,
        half_width=float(half_width),
        front_half_width=float(front_hw),
        rear_half_width=float(rear_hw),
        x_front=float(x_front),
        x_rear=float(x_rear),
        front_wrap=wrap_f,
        rear_wrap=wrap_b,
        z_sill=float(z_sill),
        z_belt=float(z_belt),
        z_front_top=float(z_front_top),
        z_rear_top=float(z_rear_top),
        x_windshield_base=float(x_wb),
        x_rear_window_base=float(x_rb),
        arch_radius=(float(ra_f), float(ra_b)),
        stations=xs,
        z_bottom=zb,
        z_top=zt,
        widths=widths,
    )


# --------------------------------------------------------------------------- builder
class _Builder:
    """Accumulates triangles with flat attributes."""

    def __init__(self):
        self.tris: list[np.ndarray] = []
        self.attrs: list[tuple] = []

    def tris_(self, tri: np.ndarray, color, part: Part, spec: float = 0.0, emit: float = 0.0):
        tri = np.asarray(tri, dtype=float).reshape(-1, 3, 3)
        self.tris.append(tri)
        self.attrs.append((len(tri), color, int(part), spec, emit))

    def quads(self, q: np.ndarray, color, part, spec=0.0, emit=0.0):
        """(N, 4, 3) quads (corners in order) -> 2N triangles."""
        q = np.asarray(q, dtype=float).reshape(-1, 4, 3)
        tri = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
        self.tris_(tri, color, part, spec, emit)

    def fan(self, poly: np.ndarray, color, part, spec=0.0, emit=0.0, center=None):
        """A convex polygon (N, 3) as a triangle fan around ``center`` (default: its centroid)."""
        poly = np.asarray(poly, dtype=float)
        c = poly.mean(0) if center is None else np.asarray(center, float)
        nxt = np.roll(poly, -1, axis=0)
        tri = np.stack([np.broadcast_to(c, poly.shape), poly, nxt], axis=1)
        self.tris_(tri, color, part, spec, emit)

    def mesh(self) -> Mesh:
        if not self.tris:
            return Mesh.concatenate([])
        tri = np.concatenate(self.tris)
        n = [a[0] for a in self.attrs]
        colors = np.repeat(np.array([a[1] for a in self.attrs], dtype=np.float32), n, axis=0)
        parts = np.repeat(np.array([a[2] for a in self.attrs]), n)
        spec = np.repeat(np.array([a[3] for a in self.attrs], dtype=np.float32), n)
        emit = np.repeat(np.array([a[4] for a in self.attrs], dtype=np.float32), n)
        area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        keep = area > 1e-10
        return Mesh(tri[keep], colors[keep], parts[keep], spec[keep], emit[keep])


def _rect_yz(x, yc, zc, hw, hh):
    """A rectangle in the plane x = const, centred at (yc, zc)."""
    return np.array([[x, yc - hw, zc - hh], [x, yc + hw, zc - hh], [x, yc + hw, zc + hh], [x, yc - hw, zc + hh]])


def _disc_points(center, radius, n, axis_y_sign=1.0):
    """Points of a circle of ``radius`` around ``center`` in the x-z plane."""
    theta = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    pts = np.repeat(np.asarray(center, float)[None], n, axis=0)
    pts[:, 0] += radius * np.cos(theta)
    pts[:, 2] += radius * np.sin(theta)
    return pts


def vehicle_mesh(wireframe: Wireframe, appearance: Appearance | None = None, wheel_radius: float = 0.33,
                 roof: float | None = None) -> Mesh:
    """The low-poly vehicle mesh of a wireframe, in the body frame.

    Args:
        wireframe: the 12 body-frame keypoints, metres (fixed order).
        appearance: colours and free shape details (default :class:`Appearance`).
        wheel_radius: hub height above the road, metres; each tyre's radius is
            its hub's height above the road plane ``z = -wheel_radius``.
        roof: the roof's height above the hubs (body z, metres: a vehicle's published height less its wheel
            radius). ``None`` (the default): the roof is the quad between the window tops, as the 12 keypoints
            alone say. Above the window tops, a roof box stands on that quad, its sides straight up from the
            glass tops (a real vehicle's roof is 8-12 cm above them, a high-roof van's up to 0.7 m: the
            vehicle library's rules, docs/vehicles.md); the keypoints stay its vertices.

    Returns:
        :class:`Mesh` in the body frame.

    Raises:
        ValueError: a wireframe whose layers are out of order (e.g. front and
            back swapped) or a wheel radius outside (0.05, 2) m.
    """
    a = Appearance() if appearance is None else appearance
    p = np.asarray(wireframe.vehicle_p_keypoints, dtype=float)
    s = _symmetrised(p)
    g = vehicle_geometry(wireframe, a, wheel_radius)
    b = _Builder()
    paint, trim = a.paint, a.trim_color
    roof_c = a.roof if a.roof is not None else paint
    pillar_c = a.pillars if a.pillars is not None else paint
    ps = a.paint_specular
    r = g.wheel_radius

    xs, zb, zt, w = g.stations, g.z_bottom, g.z_top, g.widths
    bev = np.minimum(0.06, (zt - zb) / 3.0)
    z_trim = min(g.z_sill + 0.11, min(s[0, 2], s[2, 2]) - 0.03)

    # ---- lower body: cross-section polygon per station, [P0 .. P5] from right-bottom over the top to left-bottom
    n = len(xs)
    P = np.zeros((n, 6, 3))
    P[:, :, 0] = xs[:, None]
    P[:, 0, 1:] = np.stack([-w, zb], 1)
    P[:, 1, 1:] = np.stack([-w, zt - bev], 1)
    P[:, 2, 1:] = np.stack([-w + bev, zt], 1)
    P[:, 3, 1:] = np.stack([w - bev, zt], 1)
    P[:, 4, 1:] = np.stack([w, zt - bev], 1)
    P[:, 5, 1:] = np.stack([w, zb], 1)
    i0, i1 = np.arange(n - 1), np.arange(1, n)

    def strip(ka, kb, color, part, spec=0.0):
        q = np.stack([P[i0, ka], P[i1, ka], P[i1, kb], P[i0, kb]], axis=1)
        b.quads(q, color, part, spec)

    strip(1, 2, paint, Part.BODY, ps)
    strip(2, 3, paint, Part.BODY, ps)
    strip(3, 4, paint, Part.BODY, ps)
    strip(0, 5, a.underbody, Part.UNDERBODY)
    # Sides in horizontal bands (trim, paint, and the wrapped lights near the ends), clipped per vertex
    # into [bottom, top - bevel] of each station.
    light_f, light_b = s[4], s[6]
    hh_f, hh_b = a.head_light_size[1], a.tail_light_size[1]
    x_lf = g.x_front - g.front_wrap - 1e-9
    x_lb = g.x_rear + g.rear_wrap + 1e-9
    front_seg = (xs[i0] >= x_lf) & (xs[i1] >= x_lf)
    rear_seg = (xs[i0] <= x_lb) & (xs[i1] <= x_lb)
    plain = ~front_seg & ~rear_seg
    inf = np.inf
    plain_bands = [(-inf, z_trim, trim, Part.TRIM, 0.0, 0.0), (z_trim, inf, paint, Part.BODY, ps, 0.0)]

    def light_bands(light, hh, color, part):
        z0, z1 = light[2] - hh, light[2] + hh
        # Split at the keypoint's height, so that the keypoint is a vertex (exact under the thin-plate warp).
        return [(-inf, min(z_trim, z0), trim, Part.TRIM, 0.0, 0.0), (min(z_trim, z0), z0, paint, Part.BODY, ps, 0.0),
                (z0, light[2], color, part, 0.6, a.light_emission), (light[2], z1, color, part, 0.6, a.light_emission),
                (z1, inf, paint, Part.BODY, ps, 0.0)]

    for segs, bands in ((plain, plain_bands),
                        (front_seg, light_bands(light_f, hh_f, a.head_light, Part.HEAD_LIGHT)),
                        (rear_seg, light_bands(light_b, hh_b, a.tail_light, Part.TAIL_LIGHT))):
        j0, j1 = i0[segs], i1[segs]
        if len(j0) == 0:
            continue
        for lo, hi in ((5, 4), (0, 1)):
            for z_lo, z_hi, color, part, spec, emit in bands:
                bot = P[:, lo].copy()
                top = P[:, lo].copy()
                bot[:, 2] = np.clip(z_lo, P[:, lo, 2], P[:, hi, 2])
                top[:, 2] = np.clip(z_hi, P[:, lo, 2], P[:, hi, 2])
                b.quads(np.stack([bot[j0], bot[j1], top[j1], top[j0]], axis=1), color, part, spec, emit)

    # ---- end faces (planes x = light x): horizontal bands; the light band holds the lights at its outer
    # ends (the keypoints are on the face's side edges), paint and a grille between them
    for end, sign in ((n - 1, 1.0), (0, -1.0)):
        x = xs[end]
        front = sign > 0
        light = light_f if front else light_b
        lw, lhh = a.head_light_size if front else a.tail_light_size
        we, zte, be, zbe = w[end], zt[end], bev[end], zb[end]
        z0, z1 = light[2] - lhh, min(light[2] + lhh, zte - be)
        z_bump = min(max(zbe + 0.06, min(z0 - 0.05, zbe + 0.3)), z0)
        lw = min(lw, 0.45 * we)
        color = a.head_light if front else a.tail_light
        part = Part.HEAD_LIGHT if front else Part.TAIL_LIGHT

        def rect(y0, y1, za, zb_, col, prt, spec=0.0, emit=0.0):
            if y1 > y0 and zb_ > za:
                b.quads(np.array([[x, y0, za], [x, y1, za], [x, y1, zb_], [x, y0, zb_]]), col, prt, spec, emit)

        rect(-we, we, zbe, z_bump, trim, Part.TRIM)
        rect(-we, we, z_bump, z0, paint, Part.BODY, ps)
        for za, zb_ in ((z0, light[2]), (light[2], z1)):  # split at the keypoints' height (vertices)
            rect(-we, -we + lw, za, zb_, color, part, 0.6, a.light_emission)
            rect(we - lw, we, za, zb_, color, part, 0.6, a.light_emission)
        rect(-we + lw, we - lw, z0, z1, paint, Part.BODY, ps)
        rect(-we, we, z1, zte - be, paint, Part.BODY, ps)
        b.quads(np.array([P[end, 1], P[end, 2], P[end, 3], P[end, 4]]), paint, Part.BODY, ps)
        xd = x + sign * DECAL_OFFSET
        inner = we - lw - 0.03
        if front and inner > 0.08:
            b.quads(_rect_yz(xd, 0.0, light[2] - 0.2 * lhh, inner, 0.8 * lhh), a.grille, Part.GRILLE, 0.1)
        # Number plate on the bumper (front) or between the tail lights (back).
        band = z_bump - zbe
        if front and band > 0.16:
            b.quads(_rect_yz(xd, 0.0, 0.5 * (zbe + z_bump), min(0.26, 0.8 * we), 0.06), a.plate, Part.PLATE, 0.2)
        elif not front:
            zc = z0 - 0.09 if z0 - 0.16 > z_bump else light[2]
            half = min(0.26, inner - 0.02) if zc == light[2] else min(0.26, 0.8 * we)
            if half > 0.1:
                b.quads(_rect_yz(xd, 0.0, zc, half, 0.06), a.plate, Part.PLATE, 0.2)

    # ---- cabin
    z_belt = g.z_belt
    wb_w = g.width_at(g.x_windshield_base) - a.tumblehome
    rb_w = g.width_at(g.x_rear_window_base) - a.tumblehome
    A = {sgn: np.array([g.x_windshield_base, sgn * wb_w, z_belt]) for sgn in (1.0, -1.0)}
    D = {sgn: np.array([g.x_rear_window_base, sgn * rb_w, z_belt]) for sgn in (1.0, -1.0)}
    B = {1.0: s[8], -1.0: s[9]}
    C = {1.0: s[10], -1.0: s[11]}
    b.quads(np.array([A[-1.0], A[1.0], B[1.0], B[-1.0]]), a.glass, Part.GLASS, a.glass_specular)
    b.quads(np.array([B[1.0], B[-1.0], C[-1.0], C[1.0]]), roof_c, Part.BODY, ps)
    if roof is not None and roof > max(B[1.0][2], C[1.0][2]) + _MIN_ROOF_BOX:
        Bu = {sgn: np.array([B[sgn][0], B[sgn][1], roof]) for sgn in (1.0, -1.0)}
        Cu = {sgn: np.array([C[sgn][0], C[sgn][1], roof]) for sgn in (1.0, -1.0)}
        b.quads(np.array([Bu[1.0], Bu[-1.0], Cu[-1.0], Cu[1.0]]), roof_c, Part.BODY, ps)  # the roof
        b.quads(np.array([B[-1.0], B[1.0], Bu[1.0], Bu[-1.0]]), paint, Part.BODY, ps)  # above the windshield
        b.quads(np.array([C[1.0], C[-1.0], Cu[-1.0], Cu[1.0]]), paint, Part.BODY, ps)  # above the rear window
        for sgn in (1.0, -1.0):  # the sides above the side windows
            b.quads(np.array([B[sgn], C[sgn], Cu[sgn], Bu[sgn]]), paint, Part.BODY, ps)
    b.quads(np.array([D[1.0], D[-1.0], C[-1.0], C[1.0]]), a.glass, Part.GLASS, a.glass_specular)
    # Sides: a bilinear patch A (front bottom), D (rear bottom), B (front top), C (rear top), split into
    # pillars and windows.
    top_len = np.linalg.norm(s[8] - s[10])
    s_a = min(0.12, 0.09 / max(top_len, 0.3))
    s_c = min(0.2, 0.14 / max(top_len, 0.3))
    s_b0, s_b1 = 0.47, 0.47 + min(0.1, 0.08 / max(top_len, 0.3))
    s_br = np.array([0.0, s_a, s_b0, s_b1, 1.0 - s_c, 1.0])
    t_br = np.array([0.0, 0.05, 0.92, 1.0])
    glass_cells = {(1, 1), (3, 1)}
    for sgn in (1.0, -1.0):
        a_, d_, b_, c_ = A[sgn], D[sgn], B[sgn], C[sgn]
        S, T = np.meshgrid(s_br, t_br, indexing="ij")
        grid = ((1 - T)[..., None] * ((1 - S)[..., None] * a_ + S[..., None] * d_)
                + T[..., None] * ((1 - S)[..., None] * b_ + S[..., None] * c_))
        for i in range(len(s_br) - 1):
            for j in range(len(t_br) - 1):
                q = np.array([grid[i, j], grid[i + 1, j], grid[i + 1, j + 1], grid[i, j + 1]])
                if (i, j) in glass_cells:
                    b.quads(q, a.glass, Part.GLASS, a.glass_specular)
                else:
                    b.quads(q, pillar_c if j == 1 else paint, Part.BODY, ps)

    # ---- wheels: tyre cylinder, tyre faces, rim disc (its centre is the hub keypoint), centre cap, arch liners
    m = _WHEEL_SEGMENTS
    for k in range(4):
        hub = s[k]
        sgn = 1.0 if hub[1] > 0 else -1.0
        wr = r + hub[2]
        outer = hub.copy()
        outer[1] -= sgn * _TYRE_INSET
        inner = hub.copy()
        inner[1] -= sgn * a.tyre_width
        ring_o = _disc_points(outer, wr, m)
        ring_i = _disc_points(inner, wr, m)
        nxt = np.roll(np.arange(m), -1)
        b.quads(np.stack([ring_o, ring_o[nxt], ring_i[nxt], ring_i], 1), a.tyre, Part.TYRE, 0.05)
        rim_o = _disc_points(outer, a.rim_fraction * wr, m)
        b.quads(np.stack([rim_o, rim_o[nxt], ring_o[nxt], ring_o], 1), a.tyre, Part.TYRE, 0.05)
        b.fan(ring_i, a.tyre, Part.TYRE, center=inner)
        # Rim: an annulus and a centre cap in the plane y = hub y; the cap's centre is the hub keypoint.
        rim = _disc_points(hub, a.rim_fraction * wr, m)
        cap = _disc_points(hub, _CAP_FRACTION * wr, m)
        b.quads(np.stack([cap, cap[nxt], rim[nxt], rim], 1), a.rim, Part.RIM, 0.5)
        b.fan(cap, a.cap, Part.RIM, 0.5, center=hub)
        # Liner: a dark half-disc + rectangle inside the arch, behind the tyre.
        ra = g.arch_radius[0 if k < 2 else 1]
        liner_y = sgn * (abs(hub[1]) - a.tyre_width - 0.03)
        theta = np.linspace(0.0, np.pi, _ARCH_SEGMENTS + 1)
        arc = np.stack([hub[0] - ra * np.cos(theta), np.full_like(theta, liner_y), hub[2] + ra * np.sin(theta)], 1)
        low = np.array([[hub[0] + ra, liner_y, g.z_sill], [hub[0] - ra, liner_y, g.z_sill]])
        b.fan(np.concatenate([arc, low]), a.underbody, Part.UNDERBODY)

    mesh = b.mesh()
    if np.abs(p - s).max() > 1e-9:
        mesh = replace(mesh, triangles=_thin_plate_warp(s, p, mesh.triangles))
    return mesh


def _thin_plate_warp(src: np.ndarray, dst: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Moves ``points`` by the 3D thin-plate spline (kernel |r|) that maps ``src`` keypoints onto ``dst``."""
    k = len(src)
    Phi = np.linalg.norm(src[:, None] - src[None], axis=2)
    Pm = np.hstack([np.ones((k, 1)), src])
    A = np.zeros((k + 4, k + 4))
    A[:k, :k], A[:k, k:], A[k:, :k] = Phi, Pm, Pm.T
    rhs = np.zeros((k + 4, 3))
    rhs[:k] = dst - src
    coef = np.linalg.lstsq(A, rhs, rcond=None)[0]
    flat = points.reshape(-1, 3)
    U = np.linalg.norm(flat[:, None] - src[None], axis=2)
    disp = U @ coef[:k] + np.hstack([np.ones((len(flat), 1)), flat]) @ coef[k:]
    return (flat + disp).reshape(points.shape)


# --------------------------------------------------------------------------- simple props
def box_mesh(center, size, yaw: float = 0.0, color=(0.5, 0.5, 0.5), part: Part = Part.OCCLUDER, specular=0.1) -> Mesh:
    """An axis-aligned (then yawed) box; ``center`` is the box centre, ``size`` (dx, dy, dz), world frame."""
    c = np.asarray(center, float)
    hx, hy, hz = 0.5 * np.asarray(size, float)
    corners = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    cy, sy_ = np.cos(yaw), np.sin(yaw)
    R = np.array([[cy, -sy_, 0], [sy_, cy, 0], [0, 0, 1]])
    v = corners @ R.T + c
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    b = _Builder()
    b.quads(np.array([[v[i] for i in f] for f in faces]), tuple(color), part, specular)
    return b.mesh()


def cylinder_mesh(base, radius: float, height: float, color=(0.4, 0.4, 0.4), part: Part = Part.OCCLUDER,
                  segments: int = 12, specular=0.2) -> Mesh:
    """A vertical cylinder standing on ``base`` (x, y, z), world frame (a pole, a bollard, a tree trunk)."""
    base = np.asarray(base, float)
    theta = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([base[0] + radius * np.cos(theta), base[1] + radius * np.sin(theta), np.full(segments, base[2])], 1)
    top = ring + [0, 0, height]
    nxt = np.roll(np.arange(segments), -1)
    b = _Builder()
    b.quads(np.stack([ring, ring[nxt], top[nxt], top], 1), tuple(color), part, specular)
    b.fan(top, tuple(color), part, specular)
    return b.mesh()


def quad_mesh(corners, color=(0.5, 0.5, 0.5), part: Part = Part.DECAL, specular=0.0) -> Mesh:
    """A planar convex polygon (N, 3), e.g. a road marking or a sign board, world frame."""
    b = _Builder()
    b.fan(np.asarray(corners, float), tuple(color), part, specular)
    return b.mesh()


