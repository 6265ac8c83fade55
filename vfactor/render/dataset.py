"""Random training crops of vehicles seen by surveillance cameras, their .npz shards, and a held-out split.

A sample is one vehicle (the *target*) seen from a camera on a pole 5-10 m
high, 10-40 m away, from any side; around it: other vehicles, props (poles,
bins, barriers, signs, kerbs), road markings, sun and sky, shadows. The crop
is the target's box enlarged by a random margin (10-30 %) and jittered,
rendered directly at ``size x size`` with the crop's own intrinsics (so no
full-resolution image is ever drawn). All 12 keypoints are annotated, the
self-occluded ones too, as the paper does.

The held-out split (:data:`HELD_OUT`) uses shapes, colours and viewpoints that
the training split (:data:`TRAIN`) never draws: other presets, other
PASCAL3D+ models and the other half of the vehicle library's models
(:func:`library_split`: every light body type in both halves), and interleaved bins
of paint hue / grey level, of the
camera's azimuth around the vehicle and of its elevation angle (see
:class:`SplitSpec`). Held-out viewpoints therefore lie between training
viewpoints: the split tests interpolation to unseen views, not extrapolation to
views outside the training range.

Everything is drawn from the ``rng`` passed in, so a sample is a deterministic
function of the generator's state (and :func:`make_dataset` of its seed).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from pathlib import Path

import gtsam
import numpy as np

from vfactor.box import box_features, default_box_model
from vfactor.camera import Camera
from vfactor.heatmaps import clip_roi_to_image, extend_clipped_roi
from vfactor.keypoints import LAYERS, NUM_KEYPOINTS
from vfactor.render.mesh import (
    Appearance,
    Mesh,
    Part,
    box_mesh,
    cylinder_mesh,
    quad_mesh,
    random_paint,
    vehicle_geometry,
)
from vfactor.render.renderer import Ground, Light, Renderer, VehicleInstance, keypoint_annotations, road_texture
from vfactor.sim.rig import intrinsics_from_hfov, look_at
from vfactor.sim.vehicles import (RandomShape, draw_vehicle, footprint, footprints_overlap, road_pose, symmetrised,
                                  within_hwc_bounds)
from vfactor.vehicle_library import BODY_TYPES, LIGHT_TYPES, library_ids, vehicle_library
from vfactor.wireframe import PRESETS, Wireframe, pascal3d_shapes

__all__ = [
    "SplitSpec",
    "library_split",
    "TRAIN",
    "HELD_OUT",
    "SampleOptions",
    "Sample",
    "RenderedDataset",
    "random_training_sample",
    "random_vehicle",
    "random_appearance",
    "roof_height",
    "random_light",
    "random_ground",
    "roi_from_box",
    "crop_camera",
    "make_dataset",
    "load_dataset",
    "sample_rng",
]

_FORMAT_VERSION = 1


# --------------------------------------------------------------------------- splits
@dataclass(frozen=True)
class SplitSpec:
    """What a split may draw. Values fall into bins; a split keeps the bins of its parity.

    Attributes:
        name: "train" or "held_out" (free text for custom splits).
        presets: names in :data:`vfactor.wireframe.PRESETS` the split uses.
        pascal_models: indices (0-8) of the PASCAL3D+ models its random shapes start from.
        preset_probability: chance that a vehicle is a preset rather than a random PASCAL3D+ shape (of the
            vehicles that are not library ones).
        library_models: ids of :mod:`vfactor.vehicle_library` vehicles the split uses (each with the simulator's
            3 cm keypoint jitter, :func:`vfactor.sim.vehicles.draw_vehicle`).
        library_probability: chance that a vehicle is one of ``library_models``.
        library_type_weights: ``((body type, weight), ...)``: a library model of that body type is drawn ``weight``
            times as often as one of a type not listed (weight 1); empty (default): every model equally often.
        shape_stretch: each drawn shape (library vehicle, preset or PASCAL3D+ shape) is stretched along its
            length, width and height by three independent factors uniform in ``[1 - shape_stretch, 1 +
            shape_stretch]`` (about the hubs' centre; the wheel radius kept), and drawn again where that leaves the
            HWC bounds: shapes between and beyond the split's models, so that the network learns the body types
            rather than the few models of each (0, the default: the models as they are).
        parity: 0 or 1: the bins (below) the split keeps: ``floor(value / bin) % 2 == parity``.
        hue_bin_deg: paint hue bins (degrees) for coloured paints.
        grey_bin: grey-level bins for achromatic paints (white, silver, grey, black).
        azimuth_bin_deg: bins of the camera's azimuth around the vehicle (0 = seen from the front,
            90 = from its left).
        elevation_bin_deg: bins of the elevation angle of the camera over the vehicle.
    """

    name: str
    presets: tuple
    pascal_models: tuple
    preset_probability: float = 0.35
    library_models: tuple = ()
    library_probability: float = 0.0
    library_type_weights: tuple = ()
    shape_stretch: float = 0.0
    parity: int = 0
    hue_bin_deg: float = 20.0
    grey_bin: float = 0.1
    azimuth_bin_deg: float = 10.0
    elevation_bin_deg: float = 4.0

    def __post_init__(self):
        weights = dict(self.library_type_weights)
        unknown = sorted(set(weights) - set(BODY_TYPES))
        if unknown:
            raise ValueError(f"library_type_weights: unknown body type {unknown[0]!r} (one of {', '.join(BODY_TYPES)})")
        if not all(isinstance(w, (int, float)) and math.isfinite(w) and w >= 0 for w in weights.values()):
            raise ValueError(f"library_type_weights: expected weights >= 0, got {self.library_type_weights!r}")
        if not (isinstance(self.shape_stretch, (int, float)) and 0.0 <= self.shape_stretch < 0.5):
            raise ValueError(f"shape_stretch: expected a number in [0, 0.5), got {self.shape_stretch!r}")

    def library_draw_probabilities(self) -> np.ndarray | None:
        """The probability of each of ``library_models`` in a library draw (None: uniform, the default)."""
        if not self.library_type_weights:
            return None
        weights = dict(self.library_type_weights)
        w = np.array([float(weights.get(vehicle_library()[m].body_type, 1.0)) for m in self.library_models])
        if not w.sum() > 0:
            raise ValueError("library_type_weights: every library model of the split has weight 0")
        return w / w.sum()

    def keeps(self, value: float, bin_width: float) -> bool:
        return int(math.floor(value / bin_width)) % 2 == self.parity

    def hue_ok(self, hue_deg: float) -> bool:
        return self.keeps(hue_deg, self.hue_bin_deg)

    def grey_ok(self, grey: float) -> bool:
        return self.keeps(grey, self.grey_bin)

    def azimuth_ok(self, azimuth_deg: float) -> bool:
        return self.keeps(azimuth_deg % 360.0, self.azimuth_bin_deg)

    def elevation_ok(self, elevation_deg: float) -> bool:
        return self.keeps(elevation_deg, self.elevation_bin_deg)


def library_split(parity: int) -> tuple[str, ...]:
    """Half of the vehicle library's light vehicles: of each light body type's ids (in the library's order), those
    at even (``parity`` 0: the network's training half) or odd (1: its held-out half) positions. The buses are in
    neither: the shipped network was trained on light vehicles (and these splits keep its training data)."""
    return tuple(v for t in LIGHT_TYPES for i, v in enumerate(library_ids(t)) if i % 2 == parity)


#: The training split: five presets (the paper's three cars, the pickup and the van), PASCAL3D+ models 0-6 and half
#: of the vehicle library (:func:`library_split` 0: 33 models, five or six of each body type), a library vehicle
#: half of the time.
TRAIN = SplitSpec("train", presets=("lincoln_mkz", "toyota_prius", "bmw_x5", "pickup", "van"),
                  pascal_models=(0, 1, 2, 3, 4, 5, 6), library_models=library_split(0), library_probability=0.5,
                  parity=0)
#: The held-out split: the hatchback and the SUV presets, PASCAL3D+ models 7-8, the library's other half, the other
#: colour and view bins.
HELD_OUT = SplitSpec("held_out", presets=("hatchback", "suv"), pascal_models=(7, 8), library_models=library_split(1),
                     library_probability=0.5, parity=1)


# --------------------------------------------------------------------------- options and samples
@dataclass(frozen=True)
class SampleOptions:
    """Ranges of the random sample generator (lengths in metres, angles in degrees).

    Attributes:
        image_size: (width, height) of the full surveillance image the crop comes from.
        hfov_deg: horizontal field of view range of that camera.
        camera_height: pole height range.
        distance: horizontal camera-to-vehicle distance range.
        margin: range of the fraction added to the vehicle box (per side, of the box's larger side).
        jitter: ROI centre jitter, fraction of the ROI side (kept so the box stays inside the ROI).
        edge_probability: chance that the vehicle's centre is put at an image border (within 8 % of the
            image's side outside or inside one of the four edges), so that the image cuts the vehicle: the crop's part
            outside the full image is black, as a zero-padded crop of a real image (vehicles entering
            or leaving a camera's view). Otherwise the centre lands in the middle 70 % x 60 % of the image.
        clipped_box_probability: chance that a target the image border cuts is framed from its box clipped to the
            image (as a 2D detector gives it), grown beyond the border as the detector grows such boxes
            (:func:`vfactor.heatmaps.extend_clipped_roi`), instead of from its whole box; 0 (default): whole boxes,
            and the samples are those of before.
        real_roofs: draw each vehicle's roof at its real height (:func:`roof_height`; the default) instead of at
            its window tops (False: the renderer's earlier default, as the shipped network's crops were drawn;
            docs/rendering.md, "Roofs").
        square: square ROIs (the box's larger side); else the box's own aspect, resized anisotropically.
        other_vehicles: probabilities of 0, 1, 2, 3 other vehicles near the target.
        occluder_probability: chance of a prop between the camera and the target.
        max_occluded_by_other: props/vehicles hiding more of the target's keypoints are dropped.
        low_res_probability: chance of rendering at 50-90 % of the size and upscaling (a low-res camera).
        blur_probability, blur_sigma: Gaussian blur (pixels of the crop).
        motion_blur_probability: linear motion blur of 3-7 px.
        noise_sigma: range of the Gaussian pixel noise (grey levels).
        jpeg_probability, jpeg_quality: JPEG re-compression.
        supersample: renderer supersampling.
        shadows: draw sun shadows.
    """

    image_size: tuple = (1280, 720)
    hfov_deg: tuple = (40.0, 70.0)
    camera_height: tuple = (5.0, 10.0)
    distance: tuple = (10.0, 40.0)
    margin: tuple = (0.10, 0.30)
    jitter: float = 0.05
    edge_probability: float = 0.2
    clipped_box_probability: float = 0.0
    real_roofs: bool = True
    square: bool = True
    other_vehicles: tuple = (0.35, 0.3, 0.2, 0.15)
    occluder_probability: float = 0.35
    max_occluded_by_other: int = 6
    low_res_probability: float = 0.3
    blur_probability: float = 0.5
    blur_sigma: tuple = (0.3, 1.2)
    motion_blur_probability: float = 0.15
    noise_sigma: tuple = (0.0, 6.0)
    jpeg_probability: float = 0.4
    jpeg_quality: tuple = (35, 95)
    supersample: float = 1.5
    shadows: bool = True


@dataclass
class Sample:
    """One training crop.

    Attributes:
        image: (size, size, 3) uint8 **RGB**.
        keypoints: (12, 2) keypoint pixels in the crop (OpenCV centre convention), all 12 annotated.
        visible: (12,) inside the crop and the full image, and hidden by nothing.
        self_occluded: (12,) hidden by the vehicle's own body.
        occluded_by_other: (12,) hidden by another vehicle or a prop.
        in_crop: (12,) inside the crop.
        roi: (4,) ``(x0, y0, x1, y1)`` the crop covers in the full image, pixel edges
            (``vfactor.heatmaps`` convention: ``heatmaps.image_to_heatmap(uv_full, roi, (size, size))``
            gives ``keypoints``).
        camera: the full-image camera; ``crop``: the crop's camera (``K`` adjusted, same pose).
        wireframe, world_T_vehicle, wheel_radius: the target vehicle.
        meta: JSON-able description (split, shape source, colour, viewpoint, augmentations).
    """

    image: np.ndarray
    keypoints: np.ndarray
    visible: np.ndarray
    self_occluded: np.ndarray
    occluded_by_other: np.ndarray
    in_crop: np.ndarray
    roi: np.ndarray
    camera: Camera
    crop: Camera
    wireframe: Wireframe
    world_T_vehicle: gtsam.Pose3
    wheel_radius: float
    meta: dict = field(default_factory=dict)

    @property
    def keypoints_full(self) -> np.ndarray:
        """(12, 2) keypoint pixels in the full image."""
        return self.camera.project(self.wireframe.in_world(self.world_T_vehicle))[0]


# --------------------------------------------------------------------------- geometry helpers
def roi_from_box(box, margin: float = 0.2, square: bool = True, jitter=(0.0, 0.0)) -> np.ndarray:
    """The crop of a vehicle box: enlarged by ``margin`` and shifted by ``jitter``.

    Args:
        box: ``(x0, y0, x1, y1)`` pixel edges.
        margin: fraction of the (larger, if ``square``) side added on each side.
        square: a square crop of the box's larger side (else the box's own aspect).
        jitter: ``(dx, dy)`` shift of the centre, fractions of the ROI's width and height.

    Returns:
        (4,) ``(x0, y0, x1, y1)`` pixel edges.
    """
    x0, y0, x1, y1 = (float(v) for v in box)
    w, h = x1 - x0, y1 - y0
    if not (w > 0 and h > 0):
        raise ValueError(f"box: expected x1 > x0 and y1 > y0, got {box}")
    if square:
        w = h = max(w, h)
    w, h = w * (1 + 2 * margin), h * (1 + 2 * margin)
    cx = 0.5 * (x0 + x1) + jitter[0] * w
    cy = 0.5 * (y0 + y1) + jitter[1] * h
    return np.array([cx - 0.5 * w, cy - 0.5 * h, cx + 0.5 * w, cy + 0.5 * h])


def crop_camera(camera: Camera, roi, size) -> Camera:
    """The camera whose image is the ``roi`` of ``camera``'s image resized to ``size`` (int or (w, h)).

    ``u_crop = sx (u + 0.5 - x0) - 0.5`` with ``sx = w / (x1 - x0)`` (likewise v): the same
    mapping as ``vfactor.heatmaps.image_to_heatmap``. The lens (model and distortion) is kept: every
    model acts on normalised coordinates, before K.
    """
    w, h = (size, size) if np.isscalar(size) else size
    x0, y0, x1, y1 = (float(v) for v in roi)
    sx, sy = w / (x1 - x0), h / (y1 - y0)
    K = np.array(camera.K, float)
    Kc = np.array([
        [sx * K[0, 0], sx * K[0, 1], sx * (K[0, 2] + 0.5 - x0) - 0.5],
        [0.0, sy * K[1, 1], sy * (K[1, 2] + 0.5 - y0) - 0.5],
        [0.0, 0.0, 1.0],
    ])
    return Camera(name=f"{camera.name}_crop", K=Kc, world_T_camera=camera.world_T_camera, dist=camera.dist,
                  image_size=(int(w), int(h)), model=camera.model)


def random_vehicle(rng: np.random.Generator, split: SplitSpec = TRAIN, max_tries: int = 50):
    """A vehicle shape of the split: a library vehicle, a preset, or a random PASCAL3D+ car (wheelbase 2.45-3.05 m,
    jittered); stretched by ``split.shape_stretch``.

    Returns:
        (wireframe, wheel_radius, source) where source is the library id, the preset name or ``"pascal3d:<index>"``.
    """
    shapes = pascal3d_shapes()
    # each library model's chance in a library draw (None: uniform), made once per vehicle, not per try
    chances = split.library_draw_probabilities() if split.library_models and split.library_probability > 0 else None
    for _ in range(max_tries):
        if split.library_models and rng.uniform() < split.library_probability:
            n = len(split.library_models)
            index = rng.integers(n) if chances is None else rng.choice(n, p=chances)
            vehicle_id = split.library_models[index]
            wf, radius, source = draw_vehicle(vehicle_id, rng, RandomShape(jitter=0.03))
        elif split.presets and (not split.pascal_models or rng.uniform() < split.preset_probability):
            name = split.presets[rng.integers(len(split.presets))]
            p = PRESETS[name]
            wf, radius, source = p.wireframe(), p.wheel_radius, name
        else:
            k = int(split.pascal_models[rng.integers(len(split.pascal_models))])
            points = shapes[k] * rng.uniform(2.45, 3.05) + rng.normal(0.0, 0.03, size=(NUM_KEYPOINTS, 3))
            points = symmetrised(points)
            points -= points[list(LAYERS["wheel"])].mean(axis=0)
            wf, radius, source = Wireframe(points), float(rng.uniform(0.30, 0.37)), f"pascal3d:{k}"
            if not within_hwc_bounds(wf):
                continue
        if split.shape_stretch > 0:
            factors = rng.uniform(1.0 - split.shape_stretch, 1.0 + split.shape_stretch, size=3)
            wf = Wireframe(wf.vehicle_p_keypoints * factors)  # body frame: origin at the hubs' centre
            if not within_hwc_bounds(wf):
                continue
        try:
            vehicle_geometry(wf, None, radius)
        except ValueError:
            continue
        return wf, radius, source
    raise RuntimeError(f"random_vehicle: no valid shape in {max_tries} draws for split {split.name!r}")


def roof_height(wireframe: Wireframe, model: str, wheel_radius: float, follow_window_tops: bool = False) -> float:
    """The roof's height above the hubs (metres) at which to draw a vehicle (``vehicle_mesh(..., roof=)``).

    A vehicle-library model's: its published height less its wheel radius. A preset's or a PASCAL3D+ shape's (no
    height published): its higher window pair's mean height plus the library's mean roof offset above it
    (:class:`vfactor.box.BoxModel`, ``"any"``: about 0.1 m).

    Args:
        wireframe: the vehicle's keypoints (body frame, metres); ``model``: its library id, preset name or other
            source name (:func:`random_vehicle`'s source, a simulated vehicle's ``preset``); ``wheel_radius``: its
            hubs' height above the road, metres.
        follow_window_tops: a library model's roof at its own offset above ``wireframe``'s window tops instead
            of at its published height: for a shape stretched away from the model's (``SplitSpec.shape_stretch``).
    """
    top = box_features(wireframe.vehicle_p_keypoints)[0][2]
    vehicle = vehicle_library().get(model)
    if vehicle is None:
        return float(top + default_box_model().mean["any"][2])
    roof = float(vehicle.dimensions.height) - float(wheel_radius)
    if follow_window_tops:
        roof += top - box_features(vehicle.wireframe.vehicle_p_keypoints)[0][2]
    return roof


def random_appearance(rng, split: SplitSpec) -> Appearance:
    """A random paint (in the split's colour bins) and details."""
    paint = random_paint(rng, hue_ok=split.hue_ok, grey_ok=split.grey_ok)
    return Appearance.random(rng, paint=paint)


def random_light(rng) -> Light:
    """A random sun (15-75 deg elevation) and sky, or an overcast sky (30 %)."""
    overcast = rng.uniform() < 0.3
    elev = np.radians(rng.uniform(15.0, 75.0))
    az = rng.uniform(0.0, 2 * np.pi)
    direction = (np.cos(elev) * np.cos(az), np.cos(elev) * np.sin(az), np.sin(elev))
    warm = rng.uniform(0.0, 0.12)
    sky_v = rng.uniform(0.6, 0.95)
    sky = (sky_v * rng.uniform(0.85, 1.0), sky_v * rng.uniform(0.9, 1.0), sky_v)
    if overcast:
        return Light(direction, (1.0, 1.0, 1.0), rng.uniform(0.1, 0.3), rng.uniform(0.65, 0.95), sky,
                     shadows=True, shadow_strength=rng.uniform(0.2, 0.5), contact_shadow=rng.uniform(0.5, 0.75))
    return Light(direction, (1.0, 1.0 - 0.5 * warm, 1.0 - warm), rng.uniform(0.55, 1.0), rng.uniform(0.25, 0.55), sky,
                 shadows=True, shadow_strength=rng.uniform(0.7, 0.95), contact_shadow=rng.uniform(0.4, 0.7))


_ROAD_BANK_SIZE = 48


@lru_cache(maxsize=1)
def _road_bank() -> tuple:
    """A fixed bank of procedural road textures (made once per process from fixed seeds)."""
    return tuple(road_texture(np.random.default_rng(10_000 + i), 256, lanes=i % 4 != 3) for i in range(_ROAD_BANK_SIZE))


def random_ground(rng) -> Ground:
    """A road texture from the fixed bank, randomly tiled, placed, turned and tinted."""
    tex = _road_bank()[int(rng.integers(_ROAD_BANK_SIZE))]
    tint = rng.uniform(0.75, 1.25) * rng.uniform(0.92, 1.08, 3)
    return Ground(texture=tex, tile=float(rng.uniform(6.0, 16.0)), origin=tuple(rng.uniform(-50, 50, 2)),
                  yaw=float(rng.uniform(0, 2 * np.pi)), tint=tuple(float(t) for t in tint))


def _random_colour(rng, lo=0.1, hi=0.9):
    return tuple(float(c) for c in rng.uniform(lo, hi, 3))


def _road_decals(rng, centre, yaw) -> list[Mesh]:
    """Markings and patches on the road near the target (crossings, stop lines, grass, manholes)."""
    out = []
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    for _ in range(rng.integers(0, 4)):
        kind = rng.uniform()
        off = rng.uniform(-12, 12, 2)
        z = rng.uniform(0.002, 0.006)
        if kind < 0.35:  # zebra stripes
            n = rng.integers(3, 8)
            width, length, gap = rng.uniform(0.4, 0.6), rng.uniform(2.5, 4.0), rng.uniform(0.4, 0.6)
            for i in range(n):
                x0 = off[0] + i * (width + gap)
                y0, y1 = off[1], off[1] + length
                rect = np.array([[x0, y0], [x0 + width, y0], [x0 + width, y1], [x0, y1]])
                xy = rect @ R.T + centre
                out.append(quad_mesh(np.column_stack([xy, np.full(4, z)]), (0.88, 0.88, 0.86), Part.DECAL))
        elif kind < 0.6:  # grass or pavement area
            w, l = rng.uniform(2, 8), rng.uniform(5, 25)
            rect = np.array([[0, 0], [l, 0], [l, w], [0, w]]) + off
            xy = rect @ R.T + centre
            colour = (rng.uniform(0.2, 0.35), rng.uniform(0.35, 0.5), rng.uniform(0.15, 0.25)) if rng.uniform() < 0.5 \
                else (rng.uniform(0.45, 0.65),) * 3
            out.append(quad_mesh(np.column_stack([xy, np.full(4, z)]), colour, Part.DECAL))
        elif kind < 0.8:  # manhole / stain
            r = rng.uniform(0.3, 0.8)
            t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
            xy = np.column_stack([r * np.cos(t), r * np.sin(t)]) + off @ R.T + centre
            out.append(quad_mesh(np.column_stack([xy, np.full(12, z)]), (rng.uniform(0.1, 0.35),) * 3, Part.DECAL))
        else:  # stop line / arrow-ish bar
            w, l = rng.uniform(0.2, 0.5), rng.uniform(2.5, 7)
            rect = np.array([[0, 0], [w, 0], [w, l], [0, l]]) + off
            xy = rect @ R.T + centre
            out.append(quad_mesh(np.column_stack([xy, np.full(4, z)]), (0.9, 0.9, 0.85), Part.DECAL))
    return out


def _random_prop(rng, camera_xy, target_xy, target_len) -> list[Mesh]:
    """A prop standing between the camera and the target (it may or may not hide part of it)."""
    f = rng.uniform(0.3, 0.85)
    base = camera_xy + f * (target_xy - camera_xy)
    d = target_xy - camera_xy
    normal = np.array([-d[1], d[0]]) / max(np.linalg.norm(d), 1e-9)
    base = base + normal * rng.uniform(-0.6, 0.6) * target_len * f
    kind = rng.uniform()
    colour = _random_colour(rng, 0.15, 0.85)
    if kind < 0.4:  # pole (street light, traffic light)
        h = rng.uniform(2.5, 7.0)
        return [cylinder_mesh([base[0], base[1], 0.0], rng.uniform(0.05, 0.18), h, colour)]
    if kind < 0.65:  # sign: pole + board
        h = rng.uniform(1.8, 3.0)
        pole = cylinder_mesh([base[0], base[1], 0.0], 0.04, h, (0.5, 0.5, 0.52))
        yaw = np.arctan2(d[1], d[0]) + np.pi / 2 + rng.normal(0, 0.3)
        w, bh = rng.uniform(0.5, 1.0), rng.uniform(0.5, 0.9)
        board = box_mesh([base[0], base[1], h + 0.5 * bh], (w, 0.03, bh), yaw, _random_colour(rng, 0.1, 0.95))
        return [pole, board]
    if kind < 0.85:  # bin / box / barrier
        size = (rng.uniform(0.5, 2.5), rng.uniform(0.4, 1.0), rng.uniform(0.6, 1.3))
        return [box_mesh([base[0], base[1], 0.5 * size[2]], size, rng.uniform(0, np.pi), colour)]
    # a person-sized column
    h = rng.uniform(1.5, 1.9)
    return [cylinder_mesh([base[0], base[1], 0.0], rng.uniform(0.18, 0.28), h, colour, segments=10)]


def _kerb(rng, centre, yaw) -> list[Mesh]:
    if rng.uniform() > 0.5:
        return []
    side = rng.choice([-1.0, 1.0])
    off = side * rng.uniform(4.0, 9.0)
    width = rng.uniform(2.0, 5.0)
    c, s = np.cos(yaw), np.sin(yaw)
    ctr = np.asarray(centre) + off * np.array([-s, c]) + side * 0.5 * width * np.array([-s, c])
    colour = (rng.uniform(0.5, 0.7),) * 3
    return [box_mesh([ctr[0], ctr[1], 0.075], (60.0, width, 0.15), yaw, colour)]


def _roof(options: SampleOptions, wireframe: Wireframe, source: str, radius: float, split: SplitSpec):
    """The roof height to draw a sampled vehicle with (:func:`roof_height`; a stretched shape's follows its window
    tops), or None where ``options`` draw roofs at the window tops."""
    return roof_height(wireframe, source, radius, split.shape_stretch > 0) if options.real_roofs else None


def _place_others(rng, split, target_fp, target_xy, yaw, camera_xy, count, options: SampleOptions):
    placed = [target_fp]
    others = []
    for _ in range(count):
        for _try in range(20):
            kind = rng.uniform()
            c, s = np.cos(yaw), np.sin(yaw)
            fwd, left = np.array([c, s]), np.array([-s, c])
            if kind < 0.5:  # adjacent lane, same or opposite direction
                pos = target_xy + left * rng.choice([-1, 1]) * rng.uniform(2.6, 3.8) + fwd * rng.uniform(-8, 8)
                oyaw = yaw + (np.pi if rng.uniform() < 0.3 else 0.0) + rng.normal(0, 0.05)
            elif kind < 0.8:  # same lane, ahead or behind
                pos = target_xy + fwd * rng.choice([-1, 1]) * rng.uniform(5.5, 9.0) + left * rng.normal(0, 0.3)
                oyaw = yaw + rng.normal(0, 0.05)
            else:  # crossing
                pos = target_xy + fwd * rng.choice([-1, 1]) * rng.uniform(4.5, 9.0) + left * rng.uniform(-6, 6)
                oyaw = yaw + rng.choice([-1, 1]) * np.pi / 2 + rng.normal(0, 0.1)
            wf, radius, source = random_vehicle(rng, split)
            pose = road_pose(pos[0], pos[1], oyaw, radius)
            fp = footprint(wf, pose, pad=0.15)
            if np.linalg.norm(pos - camera_xy) < 4.0:
                continue
            if any(footprints_overlap(fp, q, gap=0.2) for q in placed):
                continue
            placed.append(fp)
            others.append(VehicleInstance(wf, pose, random_appearance(rng, split), radius,
                                          _roof(options, wf, source, radius, split)))
            break
    return others


# --------------------------------------------------------------------------- sampling
_RENDERERS: dict = {}


def _renderer(size: int, supersample: float) -> Renderer:
    key = (os.getpid(), size, supersample)  # a forked child makes its own (its own OpenGL context too)
    r = _RENDERERS.get(key)
    if r is None:
        r = _RENDERERS[key] = Renderer(size, size, supersample=supersample, shadow_map_size=512)
    return r


def random_training_sample(
    rng: np.random.Generator,
    size: int = 128,
    held_out: bool = False,
    options: SampleOptions = SampleOptions(),
    split: SplitSpec | None = None,
    renderer: Renderer | None = None,
) -> Sample:
    """One random surveillance-style crop of a vehicle with its 12 keypoints.

    Args:
        rng: the only source of randomness (a sample is a deterministic function of its state).
        size: crop side in pixels.
        held_out: draw from :data:`HELD_OUT` instead of :data:`TRAIN`.
        options: ranges of the generator.
        split: a custom :class:`SplitSpec` (overrides ``held_out``).
        renderer: a ``size x size`` :class:`Renderer` to use (default: one shared per process).

    Returns:
        :class:`Sample`.
    """
    split = (HELD_OUT if held_out else TRAIN) if split is None else split
    o = options
    # --- the target vehicle
    wf, radius, source = random_vehicle(rng, split)
    appearance = random_appearance(rng, split)
    yaw = float(rng.uniform(0.0, 2 * np.pi))
    target_xy = rng.uniform(-3.0, 3.0, 2)
    pose = road_pose(target_xy[0], target_xy[1], yaw, radius)
    target = VehicleInstance(wf, pose, appearance, radius, _roof(o, wf, source, radius, split))
    centre = wf.in_world(pose).mean(axis=0)

    # --- the camera: azimuth and elevation in the split's bins, pole height and distance in range
    for _ in range(1000):
        azimuth = float(rng.uniform(0.0, 360.0))
        height = float(rng.uniform(*o.camera_height))
        distance = float(rng.uniform(*o.distance))
        elevation = math.degrees(math.atan2(height - centre[2], distance))
        if split.azimuth_ok(azimuth) and split.elevation_ok(elevation):
            break
    else:  # pragma: no cover - the bins leave half of every range
        raise RuntimeError("random_training_sample: no viewpoint in the split's bins")
    direction = yaw + math.radians(azimuth)
    eye = np.array([centre[0] + distance * math.cos(direction), centre[1] + distance * math.sin(direction), height])
    hfov = float(rng.uniform(*o.hfov_deg))
    K = intrinsics_from_hfov(hfov, o.image_size)
    # Aim so that the vehicle lands at a random place of the image (pan/tilt), then a little roll;
    # sometimes at a border, cut by the image.
    u_t = rng.uniform(0.15, 0.85) * o.image_size[0]
    v_t = rng.uniform(0.2, 0.8) * o.image_size[1]
    at_edge, edge, depth = rng.uniform() < o.edge_probability, int(rng.integers(4)), float(rng.uniform(-0.08, 0.08))
    if at_edge:
        if edge < 2:  # left or right
            u_t = (depth if edge == 0 else 1.0 - depth) * o.image_size[0]
        else:  # top or bottom
            v_t = (depth if edge == 2 else 1.0 - depth) * o.image_size[1]
    pan = math.atan2(u_t - K[0, 2], K[0, 0])
    tilt = math.atan2(v_t - K[1, 2], K[1, 1])
    to_vehicle = centre - eye
    az_v = math.atan2(to_vehicle[1], to_vehicle[0]) + pan
    el_v = math.atan2(to_vehicle[2], np.linalg.norm(to_vehicle[:2])) + tilt
    look_dir = np.array([math.cos(el_v) * math.cos(az_v), math.cos(el_v) * math.sin(az_v), math.sin(el_v)])
    world_T_camera = look_at(eye, eye + look_dir)
    roll = math.radians(rng.normal(0.0, 1.5))
    Rz = np.array([[math.cos(roll), -math.sin(roll), 0], [math.sin(roll), math.cos(roll), 0], [0, 0, 1]])
    world_T_camera[:3, :3] = world_T_camera[:3, :3] @ Rz
    camera = Camera("cam", K, world_T_camera, image_size=tuple(o.image_size))

    # --- the ROI: the target's amodal box, enlarged and jittered
    body = target.body_mesh().transformed(pose)
    vuv, _ = camera.project(body.vertices)
    box = np.array([vuv[:, 0].min() + 0.5, vuv[:, 1].min() + 0.5, vuv[:, 0].max() + 0.5, vuv[:, 1].max() + 0.5])
    width, height = o.image_size
    clipped = clip_roi_to_image(box, width, height)
    seen = clipped[2] - clipped[0] >= 1 and clipped[3] - clipped[1] >= 1  # a detector would see some of it
    box_clipped = bool(o.clipped_box_probability > 0 and np.any(clipped != box) and seen
                       and rng.uniform() < o.clipped_box_probability)
    if box_clipped:  # what the detector crops from a 2D detector's box that stops at the border
        box = np.array(extend_clipped_roi(clipped, width, height))
    margin = float(rng.uniform(*o.margin))
    roi0 = roi_from_box(box, margin, o.square)
    slack = np.array([
        max(0.0, 0.5 * ((roi0[2] - roi0[0]) - (box[2] - box[0]))) / (roi0[2] - roi0[0]),
        max(0.0, 0.5 * ((roi0[3] - roi0[1]) - (box[3] - box[1]))) / (roi0[3] - roi0[1]),
    ])
    jitter = np.clip(rng.uniform(-o.jitter, o.jitter, 2), -slack, slack)
    roi = roi_from_box(box, margin, o.square, jitter)

    # --- the surroundings
    n_others = int(rng.choice(len(o.other_vehicles), p=np.asarray(o.other_vehicles) / np.sum(o.other_vehicles)))
    target_fp = footprint(wf, pose, pad=0.15)
    others = _place_others(rng, split, target_fp, target_xy, yaw, eye[:2], n_others, o)
    props: list[Mesh] = []
    if rng.uniform() < o.occluder_probability:
        length = float(np.ptp(wf.vehicle_p_keypoints[:, 0]))
        props += _random_prop(rng, eye[:2], centre[:2], length)
    scenery = _road_decals(rng, centre[:2], yaw) + _kerb(rng, centre[:2], yaw)
    light = random_light(rng)
    ground = random_ground(rng)
    texture_seed = float(rng.uniform(0, 100))

    # --- annotations (exact ray tests, before rendering); drop occluders that hide too much
    crop = crop_camera(camera, roi, size)
    vehicles = [target] + others
    while True:
        ann = keypoint_annotations(crop, vehicles, None, props)[0]
        if np.count_nonzero(ann.occluded_by_other) <= o.max_occluded_by_other or (len(vehicles) == 1 and not props):
            break
        if props:
            props = []
        else:
            vehicles = vehicles[:-1]
    others = vehicles[1:]

    # --- render (possibly at a lower resolution, then upscaled)
    low_res = 1.0
    if rng.uniform() < o.low_res_probability:
        low_res = float(rng.uniform(0.5, 0.9))
    render_size = max(16, int(round(size * low_res)))
    r = renderer if (renderer is not None and render_size == size) else _renderer(render_size, o.supersample)
    render_cam = crop_camera(camera, roi, render_size)
    light = light if o.shadows else replace(light, shadows=False)
    result = r.render(render_cam, vehicles, light=light, occluders=props + scenery, ground=ground,
                      texture_seed=texture_seed, annotate=False)
    image = result.image
    import cv2

    if render_size != size:
        image = cv2.resize(image, (size, size), interpolation=cv2.INTER_LINEAR)
    # Parts of the ROI outside the full image are black, as a zero-padded crop of a real image.
    in_full = _inside_full_image(roi, size, o.image_size)
    if not in_full.all():
        image = image * in_full[..., None].astype(np.uint8)
    image, aug = _augment(rng, image, o)

    uv = ann.uv
    in_crop = ann.in_image
    full_uv = camera.project(wf.in_world(pose))[0]
    in_full_kp = camera.in_image(full_uv)
    visible = in_crop & in_full_kp & ~ann.self_occluded & ~ann.occluded_by_other
    meta = {
        "split": split.name,
        "source": source,
        "wheel_radius": radius,
        "wheelbase": float(wf.wheelbase),
        "paint": list(appearance.paint),
        "yaw_deg": math.degrees(yaw),
        "azimuth_deg": azimuth,
        "elevation_deg": elevation,
        "distance_m": distance,
        "camera_height_m": height,
        "hfov_deg": hfov,
        "margin": margin,
        "jitter": jitter.tolist(),
        "at_edge": bool(at_edge),
        "box": box.tolist(),
        "box_clipped": box_clipped,
        "other_vehicles": len(others),
        "props": len(props),
        "low_res": low_res,
        **aug,
    }
    return Sample(
        image=image,
        keypoints=uv,
        visible=visible,
        self_occluded=ann.self_occluded.copy(),
        occluded_by_other=ann.occluded_by_other.copy(),
        in_crop=in_crop.copy(),
        roi=roi,
        camera=camera,
        crop=crop,
        wireframe=wf,
        world_T_vehicle=pose,
        wheel_radius=radius,
        meta=meta,
    )


def _inside_full_image(roi, size, image_size) -> np.ndarray:
    x0, y0, x1, y1 = roi
    cols = x0 + (np.arange(size) + 0.5) * (x1 - x0) / size
    rows = y0 + (np.arange(size) + 0.5) * (y1 - y0) / size
    w, h = image_size
    return ((rows >= 0) & (rows < h))[:, None] & ((cols >= 0) & (cols < w))[None, :]


def _augment(rng, image, o: SampleOptions):
    import cv2

    img = image.astype(np.float32)
    gain = rng.uniform(0.95, 1.05, 3) * rng.uniform(0.8, 1.2)
    gamma = rng.uniform(0.8, 1.25)
    img = 255.0 * np.clip(img * gain / 255.0, 0, 1) ** gamma
    aug = {"gain": gain.tolist(), "gamma": gamma}
    if rng.uniform() < o.blur_probability:
        sigma = float(rng.uniform(*o.blur_sigma))
        img = cv2.GaussianBlur(img, (0, 0), sigma)
        aug["blur_sigma"] = sigma
    if rng.uniform() < o.motion_blur_probability:
        length = int(rng.integers(3, 8))
        angle = float(rng.uniform(0, 180))
        k = np.zeros((length, length), np.float32)
        k[length // 2, :] = 1.0
        M = cv2.getRotationMatrix2D(((length - 1) / 2, (length - 1) / 2), angle, 1.0)
        k = cv2.warpAffine(k, M, (length, length))
        k /= max(k.sum(), 1e-6)
        img = cv2.filter2D(img, -1, k)
        aug["motion_blur"] = [length, angle]
    sigma_n = float(rng.uniform(*o.noise_sigma))
    if sigma_n > 0:
        img = img + rng.normal(0.0, sigma_n, img.shape).astype(np.float32)
    aug["noise_sigma"] = sigma_n
    out = np.clip(img + 0.5, 0, 255).astype(np.uint8)
    if rng.uniform() < o.jpeg_probability:
        q = int(rng.integers(o.jpeg_quality[0], o.jpeg_quality[1] + 1))
        ok, buf = cv2.imencode(".jpg", out[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, q])
        if ok:
            out = np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1])
        aug["jpeg_quality"] = q
    return out, aug


# --------------------------------------------------------------------------- datasets
@dataclass
class RenderedDataset:
    """A loaded dataset: stacked arrays, one row per sample.

    Attributes:
        images: (N, S, S, 3) uint8 RGB.
        keypoints: (N, 12, 2) float32 crop pixels.
        visible, self_occluded, occluded_by_other, in_crop: (N, 12) bool.
        rois: (N, 4) float64 ``(x0, y0, x1, y1)`` in the full image.
        wireframes: (N, 12, 3) body-frame keypoints, metres.
        world_T_vehicle, world_T_camera: (N, 4, 4).
        K: (N, 3, 3) full-image intrinsics; ``K_crop``: (N, 3, 3) crop intrinsics.
        meta: per-sample dicts; ``info``: the dataset's description (dataset.json).
    """

    images: np.ndarray
    keypoints: np.ndarray
    visible: np.ndarray
    self_occluded: np.ndarray
    occluded_by_other: np.ndarray
    in_crop: np.ndarray
    rois: np.ndarray
    wireframes: np.ndarray
    world_T_vehicle: np.ndarray
    world_T_camera: np.ndarray
    K: np.ndarray
    K_crop: np.ndarray
    meta: list
    info: dict

    def __len__(self) -> int:
        return len(self.images)


_ARRAYS = ("images", "keypoints", "visible", "self_occluded", "occluded_by_other", "in_crop", "rois", "wireframes",
           "world_T_vehicle", "world_T_camera", "K", "K_crop")


def _stack(samples: list[Sample]) -> dict:
    return {
        "images": np.stack([s.image for s in samples]),
        "keypoints": np.stack([s.keypoints for s in samples]).astype(np.float32),
        "visible": np.stack([s.visible for s in samples]),
        "self_occluded": np.stack([s.self_occluded for s in samples]),
        "occluded_by_other": np.stack([s.occluded_by_other for s in samples]),
        "in_crop": np.stack([s.in_crop for s in samples]),
        "rois": np.stack([s.roi for s in samples]),
        "wireframes": np.stack([s.wireframe.vehicle_p_keypoints for s in samples]),
        "world_T_vehicle": np.stack([s.world_T_vehicle.matrix() for s in samples]),
        "world_T_camera": np.stack([s.camera.world_T_camera for s in samples]),
        "K": np.stack([s.camera.K for s in samples]),
        "K_crop": np.stack([s.crop.K for s in samples]),
        "meta": np.array([json.dumps(s.meta) for s in samples]),
    }


def sample_rng(seed: int, index: int, held_out: bool = False) -> np.random.Generator:
    """The generator of sample ``index`` of a dataset made with ``seed`` (independent streams per sample)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(bool(held_out)), int(index)]))


def make_dataset(
    n: int,
    seed: int,
    size: int = 128,
    path: str | Path = "renders",
    held_out: bool = False,
    shard_size: int = 1000,
    options: SampleOptions = SampleOptions(),
    progress=None,
    workers: int = 1,
    split: SplitSpec | None = None,
) -> list[Path]:
    """Renders ``n`` samples into ``path/shard_XXXXX.npz`` files plus ``path/dataset.json``.

    Sample ``i`` is drawn from :func:`sample_rng` ``(seed, i, held_out)``, so a dataset is
    reproducible whatever ``workers`` and ``shard_size`` are, shards can be made separately, and a
    training and a held-out set made with the same seed share nothing.

    Args:
        n: number of samples.
        seed: the dataset's seed.
        size: crop side, pixels.
        path: output directory (created).
        held_out: use :data:`HELD_OUT`.
        shard_size: samples per shard.
        options: generator ranges.
        progress: optional callable ``progress(done, n)``, called after every sample (``workers=1``)
            or every shard.
        workers: processes rendering shards in parallel (each opens its own OpenGL context).
        split: a custom :class:`SplitSpec` to draw from (e.g. :data:`TRAIN` with another
            ``library_probability``); None: :data:`TRAIN` or :data:`HELD_OUT` by ``held_out``. The samples'
            random streams are still keyed by ``held_out``.

    Returns:
        The shard paths.
    """
    if n < 0 or shard_size < 1 or workers < 1:
        raise ValueError(f"n >= 0, shard_size >= 1 and workers >= 1 expected, got {n}, {shard_size}, {workers}")
    out = Path(path)
    out.mkdir(parents=True, exist_ok=True)
    split = (HELD_OUT if held_out else TRAIN) if split is None else split
    jobs = [(seed, held_out, size, options, start, min(n, start + shard_size), str(out / f"shard_{k:05d}.npz"), split)
            for k, start in enumerate(range(0, n, shard_size))]
    shards = []
    if workers == 1 or len(jobs) <= 1:
        done = 0

        def tick(_done, _n):
            nonlocal done
            done += 1
            if progress is not None:
                progress(done, n)

        for job in jobs:
            shards.append(_make_shard(job, tick))
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            done = 0
            for job, shard in zip(jobs, pool.map(_make_shard, jobs)):
                shards.append(shard)
                done += job[5] - job[4]
                if progress is not None:
                    progress(done, n)
    info = {
        "format_version": _FORMAT_VERSION,
        "n": n,
        "seed": seed,
        "size": size,
        "split": split.name,
        "split_spec": asdict(split),
        "options": asdict(options),
        "shards": [s.name for s in shards],
        "image_channels": "RGB",
        "keypoint_names": "vfactor.keypoints.KEYPOINT_NAMES order",
        "pixels": "OpenCV centre convention; rois are (x0, y0, x1, y1) pixel edges in the full image",
    }
    (out / "dataset.json").write_text(json.dumps(info, indent=2), encoding="utf-8")
    return shards


def _make_shard(job, tick=None) -> Path:
    seed, held_out, size, options, start, stop, path, split = job
    samples = []
    for i in range(start, stop):
        samples.append(random_training_sample(sample_rng(seed, i, held_out), size, held_out, options, split))
        if tick is not None:
            tick(i + 1 - start, stop - start)
    np.savez_compressed(path, **_stack(samples))
    return Path(path)


def load_dataset(path: str | Path) -> RenderedDataset:
    """Loads a dataset written by :func:`make_dataset` (a directory, or a single shard ``.npz``)."""
    p = Path(path)
    if p.is_dir():
        info_path = p / "dataset.json"
        if info_path.is_file():
            info = json.loads(info_path.read_text(encoding="utf-8"))
            shards = [p / name for name in info["shards"]]
        else:
            info = {}
            shards = sorted(p.glob("shard_*.npz"))
        if not shards:
            raise FileNotFoundError(f"{p}: no shard_*.npz files")
    elif p.is_file():
        info, shards = {}, [p]
    else:
        raise FileNotFoundError(f"{p}: no such dataset")
    parts = {k: [] for k in _ARRAYS}
    meta = []
    for shard in shards:
        with np.load(shard, allow_pickle=False) as z:
            for k in _ARRAYS:
                parts[k].append(z[k])
            meta += [json.loads(m) for m in z["meta"]]
    arrays = {k: np.concatenate(v) for k, v in parts.items()}
    return RenderedDataset(**arrays, meta=meta, info=info)


def main(argv=None) -> int:
    """``python -m vfactor.render OUT --n N --seed S [--size 128] [--held-out] [--workers W]``."""
    import argparse
    import sys
    import time

    parser = argparse.ArgumentParser(prog="python -m vfactor.render",
                                     description="Render random vehicle crops with their 12 keypoints into .npz shards.")
    parser.add_argument("out", help="output directory")
    parser.add_argument("--n", type=int, required=True, help="number of samples")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", type=int, default=128, help="crop side, pixels")
    parser.add_argument("--held-out", action="store_true", help="the held-out split (other shapes, colours, views)")
    parser.add_argument("--shard-size", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args(argv)
    from vfactor.progress import Progress

    start = time.time()
    shards = make_dataset(args.n, args.seed, args.size, args.out, args.held_out, args.shard_size,
                          progress=Progress(args.n, "samples"), workers=args.workers)
    print(f"wrote {len(shards)} shard(s) to {args.out} in {time.time() - start:.1f} s", file=sys.stderr)
    return 0
