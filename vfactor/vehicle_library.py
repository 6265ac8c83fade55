"""A library of production vehicles: published dimensions and the 12 keypoints derived from them.

``vfactor/data/vehicle_dimensions.json`` holds the manufacturers' published
exterior dimensions of production vehicles of seven body types (:data:`BODY_TYPES`:
six of light vehicles and the single-deck bus): overall length, width, height,
wheelbase, front and rear track, tyre size, overhangs and, for pickups, the bed
length, each with its source.
:func:`keypoints_from_dimensions` turns one vehicle's dimensions into its 12
keypoints in the body frame (x forward, y left, z up, origin at the centroid
of the four wheel hubs, metres) by the rules documented in docs/vehicles.md;
the rules that no specification sheet gives (where the lamps and the window
tops sit) are fixed per body type in :data:`BODY_RULES`.

The simulator draws vehicles from the library (scenario vehicle names
``"<id>"``, ``"library"`` or ``"library:<body type>"``) and the shape model
(:mod:`vfactor.shape_model`) learns one prior per body type from it.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

import numpy as np

from vfactor import prebuilt
from vfactor.wireframe import Wireframe

__all__ = [
    "BODY_TYPES",
    "LIGHT_TYPES",
    "HEAVY_TYPES",
    "BodyRules",
    "BODY_RULES",
    "VehicleDimensions",
    "LibraryVehicle",
    "tyre_radius",
    "keypoints_from_dimensions",
    "vehicle_library",
    "bounds_vehicles",
    "library_vehicle",
    "library_ids",
    "library_table",
]

#: The body types of the library, in table order.
BODY_TYPES: tuple[str, ...] = ("sedan", "hatchback", "estate", "suv", "pickup", "van", "bus")

#: The light vehicles' body types (cars, SUVs, pickups, vans): the pooled prior, the HWC bounds' ranges and the
#: keypoint network's rendered training vehicles are theirs.
LIGHT_TYPES: tuple[str, ...] = ("sedan", "hatchback", "estate", "suv", "pickup", "van")

#: The heavy vehicles' body types, the others (single-deck rigid buses and coaches): a body-type prior each, and the
#: HWC bounds span them on their own side (:func:`vfactor.shape_model.default_hwc_bounds`); they would widen the
#: pooled prior and the bounds' ranges several times over for every car.
HEAVY_TYPES: tuple[str, ...] = tuple(t for t in BODY_TYPES if t not in LIGHT_TYPES)


@dataclass(frozen=True)
class BodyRules:
    """Where the lamps and the window tops of a body type sit (metres; heights above the road).

    Attributes:
        front_overhang_share: share of ``length - wheelbase`` in front of the front
            axle when the front overhang is not published.
        front_light_setback: front-lamp keypoint behind the front end.
        front_light_height: front-lamp keypoint height.
        front_light_inset: front-lamp keypoint inside the body side.
        back_light_setback: tail-lamp keypoint ahead of the rear end.
        back_light_height: tail-lamp keypoint height.
        back_light_inset: tail-lamp keypoint inside the body side.
        windshield_behind_axle: windshield top behind the front axle, as a
            share of the wheelbase (``windshield_fixed`` adds metres).
        windshield_fixed: metres added to that distance.
        windshield_max_height: the windshield top is at most this high (the
            cab of a high-roof van), else ``roof_gap`` below the overall height.
        roof_gap: roof keypoints below the overall height.
        roof_inset: roof keypoints inside the body side (tumblehome).
        rear_window: how the rear-window top is placed: ``"axle"`` (a
            saloon's C-pillar top, ``rear_window_offset`` ahead of the rear
            axle), ``"end"`` (a tailgate's top, ``rear_window_offset`` ahead of
            the rear end) or ``"cab"`` (a pickup's cab back: the bed length plus
            ``rear_window_offset`` ahead of the rear end).
        rear_window_offset: see ``rear_window``.
        rear_window_drop: rear-window top below the overall height.
        rear_window_max_height: the rear-window top is at most this high.
        bed_length: a pickup's bed length when none is published.
        windshield_setback: when given, the windshield top sits this far behind the
            front end instead (a bus's, at the front edge of its roof, whatever
            its front overhang); ``windshield_behind_axle`` and
            ``windshield_fixed`` are then not used.
    """

    front_overhang_share: float
    front_light_setback: float
    front_light_height: float
    front_light_inset: float
    back_light_setback: float
    back_light_height: float
    back_light_inset: float
    windshield_behind_axle: float
    windshield_fixed: float
    windshield_max_height: float
    roof_gap: float
    roof_inset: float
    rear_window: str
    rear_window_offset: float
    rear_window_drop: float
    rear_window_max_height: float = 10.0
    bed_length: float = 1.70
    windshield_setback: float | None = None


#: Per body type: the placement rules of the keypoints that no specification gives
#: (docs/vehicles.md says where each number comes from).
BODY_RULES: dict[str, BodyRules] = {
    "sedan": BodyRules(0.46, 0.28, 0.68, 0.25, 0.20, 0.92, 0.24, 0.36, 0.0, 10.0, 0.06, 0.33, "axle", 0.15, 0.08),
    "hatchback": BodyRules(0.52, 0.28, 0.70, 0.25, 0.12, 0.98, 0.22, 0.36, 0.0, 10.0, 0.06, 0.31, "end", 0.40, 0.10),
    "estate": BodyRules(0.46, 0.28, 0.68, 0.25, 0.12, 0.96, 0.22, 0.37, 0.0, 10.0, 0.08, 0.31, "end", 0.30, 0.10),
    "suv": BodyRules(0.47, 0.22, 0.82, 0.22, 0.08, 1.06, 0.17, 0.33, 0.0, 10.0, 0.08, 0.27, "end", 0.30, 0.12),
    "pickup": BodyRules(0.42, 0.16, 1.00, 0.22, 0.05, 0.98, 0.09, 0.10, 0.75, 10.0, 0.08, 0.27, "cab", 0.15, 0.10),
    "van": BodyRules(0.46, 0.14, 0.92, 0.20, 0.04, 1.00, 0.08, 0.0, 0.58, 2.05, 0.10, 0.20, "end", 0.08, 0.15, 2.20),
    "bus": BodyRules(0.44, 0.06, 0.90, 0.20, 0.04, 1.15, 0.12, 0.0, 0.0, 10.0, 0.25, 0.10, "end", 0.06, 0.45,
                     windshield_setback=0.15),
}

_TYRE = re.compile(r"^(?:LT|P)?(\d{3})/(\d{2})Z?R(\d{2}(?:\.\d)?)C?$")


def tyre_radius(tyre: str) -> float:
    """Unloaded radius of a tyre given as ISO metric ``WIDTH/ASPECT R RIM`` (e.g. ``205/55R16``), metres.

    ``r = rim * 25.4 / 2 + width * aspect / 100`` (mm), the hub height above the
    road of an unladen wheel.

    Raises:
        ValueError: the text is not an ISO metric tyre size.
    """
    match = _TYRE.match(tyre.strip().upper().replace(" ", ""))
    if match is None:
        raise ValueError(f"tyre: expected an ISO metric size such as '205/55R16', got {tyre!r}")
    width, aspect, rim = float(match.group(1)), float(match.group(2)), float(match.group(3))
    return (rim * 25.4 / 2 + width * aspect / 100) / 1000


@dataclass(frozen=True)
class VehicleDimensions:
    """Published exterior dimensions of one production vehicle (metres; width without mirrors).

    Attributes:
        id: library id (``[a-z0-9_]``).
        make, model, generation, variant: which vehicle.
        body_type: one of :data:`BODY_TYPES`.
        length, width, height, wheelbase, front_track, rear_track: overall dimensions.
        tyre: standard tyre size (ISO metric), for the wheel radius.
        front_overhang, rear_overhang: published overhangs, or None.
        ground_clearance: published ground clearance, or None (not used for keypoints).
        bed_length: a pickup's bed length, or None.
        load_length: a panel van's published load floor length, or None (not used for keypoints).
        roof: a van's roof (``"low"``, ``"medium"``, ``"high"``), or None.
        source: the published document the figures come from.
    """

    id: str
    make: str
    model: str
    generation: str
    variant: str
    body_type: str
    length: float
    width: float
    height: float
    wheelbase: float
    front_track: float
    rear_track: float
    tyre: str
    front_overhang: float | None = None
    rear_overhang: float | None = None
    ground_clearance: float | None = None
    bed_length: float | None = None
    load_length: float | None = None
    roof: str | None = None
    source: str = ""

    @property
    def wheel_radius(self) -> float:
        """Hub height above the road, metres (:func:`tyre_radius` of ``tyre``)."""
        return tyre_radius(self.tyre)

    def overhangs(self, rules: "BodyRules | None" = None) -> tuple[float, float]:
        """(front, rear) overhang, metres: the published ones, else ``length - wheelbase`` split by ``rules``
        (default: the body type's :data:`BODY_RULES`).

        Raises:
            ValueError: neither overhang is published and there are no rules for the body type.
        """
        extra = self.length - self.wheelbase
        front, rear = self.front_overhang, self.rear_overhang
        if front is None and rear is None:
            rules = rules or BODY_RULES.get(self.body_type)
            if rules is None:
                raise ValueError(f"VehicleDimensions {self.id!r}: no overhang published and no BodyRules for body "
                                 f"type {self.body_type!r} (give front_overhang or rules)")
            front = rules.front_overhang_share * extra
        if front is None:
            front = extra - rear
        return float(front), float(extra - front)


@dataclass(frozen=True)
class LibraryVehicle:
    """A library vehicle: its dimensions, its keypoints and its wheel radius.

    Attributes:
        dimensions: the published dimensions.
        wireframe: the 12 keypoints, body frame, metres.
    """

    dimensions: VehicleDimensions
    wireframe: Wireframe

    @property
    def id(self) -> str:
        return self.dimensions.id

    @property
    def body_type(self) -> str:
        return self.dimensions.body_type

    @property
    def wheel_radius(self) -> float:
        return self.dimensions.wheel_radius


def keypoints_from_dimensions(dims: VehicleDimensions, rules: BodyRules | None = None) -> Wireframe:
    """The 12 keypoints of a vehicle from its published dimensions (docs/vehicles.md).

    Body frame, metres: hubs at ``x = +-wheelbase / 2``, ``y = +-track / 2``
    (front and rear tracks apart), ``z = 0``; the road at ``z = -r`` with ``r``
    the tyre's radius; the front end at ``wheelbase / 2 + front overhang``, the
    rear end at ``-(wheelbase / 2 + rear overhang)``. Lamps and window tops
    follow the body type's :class:`BodyRules`.

    Args:
        dims: the vehicle's dimensions.
        rules: placement rules (default: ``BODY_RULES[dims.body_type]``).
    """
    rules = rules or BODY_RULES.get(dims.body_type)
    if rules is None:
        raise ValueError(f"keypoints_from_dimensions: no BodyRules for body type {dims.body_type!r} of "
                         f"{dims.id!r}; give rules (BodyRules: where its lamps and window tops sit)")
    r = dims.wheel_radius
    half_wb, half_w = dims.wheelbase / 2, dims.width / 2
    front_oh, rear_oh = dims.overhangs(rules)
    x_front, x_rear = half_wb + front_oh, -(half_wb + rear_oh)

    def height(h: float) -> float:  # height above the road -> body z
        return h - r

    x_fl = x_front - rules.front_light_setback
    z_fl = height(min(rules.front_light_height, 0.6 * dims.height))
    y_fl = half_w - rules.front_light_inset
    x_bl = x_rear + rules.back_light_setback
    z_bl = height(min(rules.back_light_height, 0.7 * dims.height))
    y_bl = half_w - rules.back_light_inset

    if rules.windshield_setback is not None:
        x_ws = x_front - rules.windshield_setback
    else:
        x_ws = half_wb - rules.windshield_behind_axle * dims.wheelbase - rules.windshield_fixed
    z_ws = height(min(dims.height - rules.roof_gap, rules.windshield_max_height))
    if rules.rear_window == "axle":
        x_rw = -half_wb + rules.rear_window_offset
    elif rules.rear_window == "end":
        x_rw = x_rear + rules.rear_window_offset
    elif rules.rear_window == "cab":
        bed = dims.bed_length if dims.bed_length is not None else rules.bed_length
        x_rw = x_rear + bed + rules.rear_window_offset
    else:
        raise ValueError(f"BodyRules.rear_window: expected 'axle', 'end' or 'cab', got {rules.rear_window!r}")
    z_rw = height(min(dims.height - rules.rear_window_drop, rules.rear_window_max_height))
    y_roof = half_w - rules.roof_inset

    tf, tr = dims.front_track / 2, dims.rear_track / 2
    points = np.array([
        [half_wb, tf, 0.0], [half_wb, -tf, 0.0], [-half_wb, tr, 0.0], [-half_wb, -tr, 0.0],
        [x_fl, y_fl, z_fl], [x_fl, -y_fl, z_fl], [x_bl, y_bl, z_bl], [x_bl, -y_bl, z_bl],
        [x_ws, y_roof, z_ws], [x_ws, -y_roof, z_ws], [x_rw, y_roof, z_rw], [x_rw, -y_roof, z_rw],
    ])
    return Wireframe(points)


_REQUIRED = ("id", "make", "model", "body_type", "length", "width", "height", "wheelbase", "front_track",
             "rear_track", "tyre")


def _dimensions(entry: dict, where: str) -> VehicleDimensions:
    missing = [k for k in _REQUIRED if entry.get(k) is None]
    if missing:
        raise ValueError(f"{where}: missing {missing}")
    if entry["body_type"] not in BODY_TYPES:
        raise ValueError(f"{where}.body_type: expected one of {BODY_TYPES}, got {entry['body_type']!r}")
    fields = {k: entry.get(k) for k in VehicleDimensions.__dataclass_fields__}
    fields["generation"] = fields["generation"] or ""
    fields["variant"] = fields["variant"] or ""
    fields["source"] = fields["source"] or ""
    return VehicleDimensions(**fields)


def _dimensions_file() -> dict:
    """``vfactor/data/vehicle_dimensions.json``, parsed."""
    with resources.files("vfactor.data").joinpath("vehicle_dimensions.json").open("r", encoding="utf-8") as f:
        return json.load(f)


@lru_cache(maxsize=1)
@prebuilt.shipped("vehicle_library")
def vehicle_library() -> dict[str, LibraryVehicle]:
    """Every library vehicle by id, in the file's order (``vfactor/data/vehicle_dimensions.json``)."""
    data = _dimensions_file()
    out = {}
    for i, entry in enumerate(data["vehicles"]):
        dims = _dimensions(entry, f"vehicle_dimensions.json vehicles[{i}]")
        if dims.id in out:
            raise ValueError(f"vehicle_dimensions.json vehicles[{i}].id: duplicate {dims.id!r}")
        out[dims.id] = LibraryVehicle(dims, keypoints_from_dimensions(dims))
    return out


@lru_cache(maxsize=1)
def bounds_vehicles() -> dict[str, LibraryVehicle]:
    """Road vehicles beyond the library's body types (a 12 m city bus, a microcar), by id: the HWC bounds span
    them (:func:`vfactor.shape_model.default_hwc_bounds`: what is physically a vehicle); neither the priors nor
    the simulator use them (``vfactor/data/vehicle_dimensions.json``, ``bounds_vehicles``; docs/vehicles.md)."""
    out = {}
    for i, entry in enumerate(_dimensions_file().get("bounds_vehicles", [])):
        where = f"vehicle_dimensions.json bounds_vehicles[{i}]"
        dims = _dimensions(entry, where)
        rules = None
        if entry.get("rules") is not None:
            try:
                rules = BodyRules(**entry["rules"])
            except TypeError as exc:
                raise ValueError(f"{where}.rules: {exc}") from None
        out[dims.id] = LibraryVehicle(dims, keypoints_from_dimensions(dims, rules))
    return out


def library_vehicle(vehicle_id: str) -> LibraryVehicle:
    """One library vehicle; raises ``ValueError`` naming the known ids."""
    library = vehicle_library()
    if vehicle_id not in library:
        raise ValueError(f"vehicle library: unknown id {vehicle_id!r}; known: {sorted(library)}")
    return library[vehicle_id]


def library_ids(body_type: str | None = None) -> tuple[str, ...]:
    """The library's ids, all or of one body type, in the file's order."""
    if body_type is not None and body_type not in BODY_TYPES:
        raise ValueError(f"body type: expected one of {BODY_TYPES}, got {body_type!r}")
    return tuple(v.id for v in vehicle_library().values() if body_type is None or v.body_type == body_type)


def library_table() -> str:
    """A Markdown table of every library vehicle: type, make and model, the dimensions used, and the source."""
    lines = [
        "| id | body type | vehicle | length | width | height | wheelbase | tracks f / r | tyre (r, m) | overhangs f / r | bed | source |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for v in vehicle_library().values():
        d = v.dimensions
        front, rear = d.overhangs()
        published = "" if d.front_overhang is not None or d.rear_overhang is not None else " (split)"
        bed = f"{d.bed_length:.3f}" if d.bed_length is not None else "-"
        lines.append(
            f"| {d.id} | {d.body_type} | {d.make} {d.model} {d.generation}, {d.variant} | {d.length:.3f} | {d.width:.3f} | "
            f"{d.height:.3f} | {d.wheelbase:.3f} | {d.front_track:.3f} / {d.rear_track:.3f} | {d.tyre} ({d.wheel_radius:.3f}) | "
            f"{front:.3f} / {rear:.3f}{published} | {bed} | {d.source} |")
    return "\n".join(lines)
