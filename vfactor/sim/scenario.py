"""Simulation scenarios: camera rig, vehicles, placement, noise and frames, from JSON.

A scenario file (``graphs/*.json``, installed as ``vfactor.graphs``) is validated field by field on
load; every problem raises :class:`vfactor.errors.ScenarioError` whose
``field`` is the path of the offending entry (``cameras[1].height``,
``noise.outlier_rate``). The fields are listed in :data:`SCENARIO_FIELDS` and in
``docs/``; see :func:`scenario_from_dict`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import gtsam
import numpy as np

from vfactor.camera import Camera, extrinsic_sigma
from vfactor.errors import CalibrationError, ScenarioError
from vfactor.jsonio import read_json
from vfactor.sim import _checks as chk
from vfactor.sim.noise import NoiseModel
from vfactor.sim.rig import intrinsics_from_hfov, look_at
from vfactor.sim.routes import ARMS, TURNS
from vfactor.sim.routes import Path as RoutePath
from vfactor.sim.vehicles import RANDOM, RandomShape, check_vehicle_name

__all__ = [
    "BodyMotion",
    "ExtrinsicError",
    "Motion",
    "RouteMotion",
    "RouteSpec",
    "REQUIRE_VISIBLE",
    "MOTION_FIELDS",
    "ROUTE_MOTION_FIELDS",
    "ROUTE_FIELDS",
    "Scenario",
    "SCENARIO_FIELDS",
    "CAMERA_FIELDS",
    "noise_from_value",
    "load_scenario",
    "scenario_from_dict",
    "scenario_on_cameras",
    "scenario_path",
    "list_scenarios",
]

#: Top-level keys of a scenario file and what each holds.
SCENARIO_FIELDS: dict[str, str] = {
    "name": "scenario name (default: the file's stem)",
    "description": "free text",
    "cameras": "list of cameras (required); see CAMERA_FIELDS",
    "vehicles": 'list of vehicle names (required): presets, library ids, "library", "library:<body type>" '
    'or "random" (a random PASCAL3D+ car)',
    "vehicle_order": '"cycle" (default: frame f, slot k takes vehicles[(f * n + k) % len]) or "random"',
    "vehicles_per_frame": "integer >= 1 (default 1); ids v1, v2, ...",
    "random_shape": '{"wheelbase": [2.5, 3.0], "jitter": 0.03, "wheel_radius": 0.33}, for "random" vehicles',
    "region": '{"x": [min, max], "y": [min, max]}: world box of vehicle positions, metres (default +-2 m)',
    "yaw_deg": "[min, max] heading range, degrees (default [0, 360])",
    "visible_in": '"all" (default) or a list of camera names whose images must hold all 12 keypoints',
    "require_visible": '"all" (default: every visible_in camera holds every vehicle in every frame), '
    '"any" (at least one of them does, in every frame the vehicle exists) or "none" (vehicles may leave the views)',
    "margin_px": "margin inside the image for that check, pixels (default 20)",
    "min_gap": "minimum distance between vehicles' footprints, metres (default 0.5)",
    "noise": 'noise settings (see NoiseModel) or "paper" (default), "noiseless", "gaussian"',
    "num_frames": "integer >= 1 (default 10)",
    "dt": "seconds between frames (default 0.1)",
    "seed": "integer >= 0 (default 0)",
    "ground_plane": "true to write the road plane z = 0 into the scene (solving and tracking then add a ground-plane "
    "factor); "
    "default false",
    "motion": 'null (default: independent frames), {"speed": [min, max] m/s, "yaw_rate_deg": [min, max] deg/s} '
    '(constant speed and turn rate) or {"kind": "route", ...} '
    "(routes through the intersection; see ROUTE_MOTION_FIELDS)",
    "body_motion": 'null (default: rigid vehicles) or {"roll_deg_per_g": 5.0, "pitch_deg_per_g": 2.0}: with motion, '
    "the body rolls and pitches on its suspension with the accelerations while its hubs stay on the road",
    "extrinsic_error": 'null (default: the scene\'s cameras as they are) or {"rotation_deg": 0.3, "translation_m": '
    '0.05, "declared": true}: each camera of the simulated scene (its world_T_camera) errs by a draw of these '
    'standard deviations per axis (the detections are seen by the true cameras); declared: the scene\'s cameras '
    'carry them as extrinsic_sigma',
}

#: Values of ``require_visible``.
REQUIRE_VISIBLE = ("all", "any", "none")

#: Keys of ``motion`` with ``"kind": "constant"`` (the default kind).
MOTION_FIELDS: dict[str, str] = {
    "kind": '"constant" (default) or "route"',
    "speed": "[min, max] uniform speed, m/s (default [3, 8])",
    "yaw_rate_deg": "[min, max] uniform yaw rate, deg/s (default [-11.46, 11.46])",
}

#: Keys of ``motion`` with ``"kind": "route"``. A range is ``[min, max]`` or one number.
ROUTE_MOTION_FIELDS: dict[str, str] = {
    "kind": '"route"',
    "routes": "list of routes, one per vehicle v1, v2, ... (see ROUTE_FIELDS); missing fields are drawn "
    "from the ranges below; vehicles beyond the list are drawn entirely",
    "speed": "cruise speed range, m/s (default [5, 12])",
    "from": 'arms vehicles come from, drawn uniformly (default ["west", "south", "east", "north"])',
    "turn": 'manoeuvres, drawn uniformly (default ["straight", "left", "right"])',
    "radius": "turn radius range of the hub centroid, m (default [6, 15])",
    "stop_probability": "probability that a vehicle stops before the intersection (default 0.3)",
    "stop_at": "distance of the stop point before the centre, m (default 7)",
    "wait": "range of the time at rest at a stop, s (default [1, 3])",
    "decel": "range of the braking deceleration, m/s^2 (default [2, 3])",
    "accel": "range of the acceleration when setting off, m/s^2 (default [1.5, 2.5])",
    "centre_time": "range of the time at the middle of the manoeuvre of a vehicle that does not stop, s "
    "(default [0, (num_frames - 1) * dt])",
    "stop_time": "range of the time a stopping vehicle comes to rest, s (default [0, (num_frames - 1) * dt])",
    "lane_offset": "distance of the lanes from the road axes, m (default 1.75; negative: left-hand traffic)",
    "scene_radius": "null (default) or metres: a vehicle exists only while within this distance of the origin",
    "turn_lateral_accel": "null (default: turns at cruise speed) or m/s^2: a turning vehicle's cruise speed is at "
    "most sqrt(turn_lateral_accel * radius), as traffic slows for a turn (about 2-4 m/s^2)",
}

#: Keys of one entry of ``motion.routes``; every one is optional.
ROUTE_FIELDS: dict[str, str] = {
    "vehicle": 'a vehicle name as in "vehicles" (default: from "vehicles" by "vehicle_order")',
    "from": '"west", "south", "east" or "north": the arm the vehicle comes from',
    "turn": '"straight", "left" or "right"',
    "radius": "turn radius, m",
    "speed": "cruise speed, m/s",
    "stop": "true: halt at the stop point, wait, set off again",
    "stop_at": "distance of the stop point before the centre, m",
    "wait": "time at rest at each stop, s",
    "decel": "braking deceleration, m/s^2",
    "accel": "acceleration when setting off, m/s^2",
    "centre_time": "time at the middle of the manoeuvre, s (not with stop_time)",
    "stop_time": "time the vehicle comes to rest at its stop, s (implies stop: true)",
    "path": '{"start": [x, y, yaw_deg], "segments": [{"straight": m} | {"arc_deg": deg, "radius": m}], '
    '"loop": false}: an explicit path instead of from/turn/radius',
    "stops": 'with path: [{"at": m along the path, "wait": s}], in increasing order',
    "start_speed": "with path: speed at start_time, m/s (default the cruise speed)",
    "start_time": "with path: time at the path's start, s (default 0); the vehicle exists from then on",
}

_INTERSECTION_ONLY = ("from", "turn", "radius", "stop", "stop_at", "centre_time", "stop_time")
_PATH_ONLY = ("stops", "start_speed", "start_time")

CAMERA_FIELDS: dict[str, str] = {
    "name": "unique camera name (required)",
    "pole": "[x, y] of the pole's foot on the road, metres",
    "height": "camera height above the road, metres (> 0)",
    "look_at": "[x, y, z] world point at the image centre (default [0, 0, 0])",
    "world_T_camera": "4x4 camera -> world, instead of pole/height/look_at",
    "hfov_deg": "horizontal field of view, degrees, in (0, 180) (or K)",
    "K": "3x3 intrinsics (instead of hfov_deg)",
    "image_size": "[width, height] pixels (default [1280, 720])",
    "dist": "OpenCV distortion [k1, k2, p1, p2(, k3)] (default none)",
}

_NOISE_PRESETS = {
    "paper": NoiseModel(),
    "noiseless": NoiseModel.noiseless(),
    "gaussian": NoiseModel.gaussian_only(),
}


@dataclass(frozen=True)
class BodyMotion:
    """The body rolling and pitching on its suspension with the vehicle's accelerations (quasi-static).

    A real vehicle's body rolls outwards in a turn and pitches nose-down when braking, about a degree or a few per
    g of acceleration (roll gradients of passenger cars 3-7 deg/g, pitch gradients 1-3 deg/g), while its wheels
    stay on the road. With it, the simulated vehicle's pose stays the hubs' frame and its body keypoints (lights,
    windshield and rear-window tops) turn about the hubs' centre: roll ``roll_deg_per_g * a_lat / g`` (``a_lat =
    speed * yaw_rate``, to the left), pitch ``-pitch_deg_per_g * a_long / g`` (nose down when ``a_long < 0``).

    Attributes:
        roll_deg_per_g: degrees of body roll per g of lateral acceleration, in [0, :attr:`MAX_DEG_PER_G`].
        pitch_deg_per_g: degrees of body pitch per g of longitudinal acceleration, in the same range.
    """

    #: The largest gradient a scenario (or ``vfactor eval tracks --body-motion``) may give, degrees per g.
    MAX_DEG_PER_G = 20.0

    roll_deg_per_g: float = 0.0
    pitch_deg_per_g: float = 0.0

    def applied(self, truth):
        """The :class:`~vfactor.sim.simulate.VehicleTruth` ``truth`` with its body's roll and pitch set from its
        speed, yaw rate and acceleration (unchanged where they are not known: independent frames)."""
        if truth.speed is None or truth.yaw_rate is None or truth.acceleration is None:
            return truth
        g = 9.81
        roll = math.radians(self.roll_deg_per_g) * truth.speed * truth.yaw_rate / g
        pitch = -math.radians(self.pitch_deg_per_g) * truth.acceleration / g
        return dataclasses.replace(truth, body_roll=roll, body_pitch=pitch)


@dataclass(frozen=True)
class ExtrinsicError:
    """Cameras whose ``world_T_camera`` errs, as a survey or a calibration does (a simulated scene's cameras).

    The detections are seen by the scenario's cameras; the scene the solver gets holds each camera at
    ``world_T_camera * Exp(xi)^-1`` (so that the true pose is the scene's times ``Exp(xi)``, as
    :attr:`vfactor.camera.Camera.extrinsic_sigma` states it), ``xi`` drawn per camera and seed with these
    standard deviations about and along each camera axis.

    Attributes:
        rotation_deg: orientation error about each camera axis, degrees (>= 0).
        translation_m: position error along each camera axis, metres (>= 0).
        declared: the scene's cameras carry these as their ``extrinsic_sigma`` (what a user who knows the survey's
            accuracy gives); False: they carry none.
    """

    #: The largest rotation error a scenario (or ``vfactor eval --extrinsic-error``) may give, degrees.
    MAX_ROTATION_DEG = 10.0
    #: The largest translation error, metres.
    MAX_TRANSLATION_M = 5.0

    rotation_deg: float = 0.0
    translation_m: float = 0.0
    declared: bool = True

    def __post_init__(self):
        for name, hi in (("rotation_deg", self.MAX_ROTATION_DEG), ("translation_m", self.MAX_TRANSLATION_M)):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and 0.0 <= value <= hi):
                raise ScenarioError(f"extrinsic_error.{name}", f"expected a number in [0, {hi:g}], got {value!r}")
        if not isinstance(self.declared, bool):
            raise ScenarioError("extrinsic_error.declared", f"expected true or false, got {self.declared!r}")

    def surveyed(self, cameras: dict[str, Camera], rng: np.random.Generator) -> dict[str, Camera]:
        """The cameras as the scene gives them: each moved by its own draw, with ``extrinsic_sigma`` if declared."""
        sigma = extrinsic_sigma(self.rotation_deg, self.translation_m)
        out = {}
        for name, camera in cameras.items():
            xi = rng.normal(0.0, 1.0, 6) * sigma
            world_T_camera = camera.world_T_camera @ gtsam.Pose3.Expmap(xi).inverse().matrix()
            out[name] = dataclasses.replace(camera, world_T_camera=world_T_camera,
                                            extrinsic_sigma=sigma if self.declared else None)
        return out


@dataclass(frozen=True)
class Motion:
    """Constant-speed, constant-turn-rate motion of each vehicle over the frames.

    Attributes:
        speed: ``(min, max)`` of the uniform speed, m/s (forward, along body x).
        yaw_rate: ``(min, max)`` of the uniform yaw rate, rad/s.
    """

    speed: tuple[float, float] = (3.0, 8.0)
    yaw_rate: tuple[float, float] = (-0.2, 0.2)


@dataclass(frozen=True)
class RouteSpec:
    """One vehicle's route as a scenario gives it; a None field is drawn from :class:`RouteMotion`'s ranges.

    Either an intersection route (``arm``, ``turn``, ``radius``, ``stop``...) or
    an explicit ``path`` (with ``stops``, ``start_speed``, ``start_time``).

    Attributes:
        vehicle: preset name or ``"random"``.
        arm: arm the vehicle comes from (``"west"``, ``"south"``, ``"east"``, ``"north"``; the file's ``from``).
        turn: ``"straight"``, ``"left"`` or ``"right"``.
        radius: turn radius, metres.
        speed: cruise speed, m/s.
        stop: whether it halts at the stop point.
        stop_at: distance of the stop point before the centre, metres.
        wait: time at rest at each stop, s.
        decel: braking deceleration, m/s^2.
        accel: acceleration when setting off, m/s^2.
        centre_time: time at the middle of the manoeuvre, s.
        stop_time: time it comes to rest at its stop, s (implies ``stop=True``).
        path: explicit path (instead of an intersection route).
        stops: with ``path``: ``(arc_length, wait or None)`` pairs.
        start_speed: with ``path``: speed at ``start_time``.
        start_time: with ``path``: time at the path's start (the vehicle exists from then on).
    """

    vehicle: str | None = None
    arm: str | None = None
    turn: str | None = None
    radius: float | None = None
    speed: float | None = None
    stop: bool | None = None
    stop_at: float | None = None
    wait: float | None = None
    decel: float | None = None
    accel: float | None = None
    centre_time: float | None = None
    stop_time: float | None = None
    path: RoutePath | None = None
    stops: tuple[tuple[float, float | None], ...] = ()
    start_speed: float | None = None
    start_time: float | None = None

    def __post_init__(self):
        if self.stop_time is not None:
            if self.stop is False:
                raise ValueError("RouteSpec: a vehicle with stop=False has no stop_time")
            object.__setattr__(self, "stop", True)


@dataclass(frozen=True)
class RouteMotion:
    """Vehicles driving routes through the intersection at the origin (``"kind": "route"``).

    Ranges are ``(min, max)`` of uniform draws. See :data:`ROUTE_MOTION_FIELDS`.

    Attributes:
        routes: one :class:`RouteSpec` per vehicle (``v1``, ``v2``, ...); vehicles beyond them are drawn entirely.
        speed: cruise speed, m/s.
        arms: arms the vehicles come from.
        turns: manoeuvres.
        radius: turn radius, metres.
        stop_probability: probability that a vehicle stops before the intersection.
        stop_at: distance of the stop point before the centre, metres.
        wait: time at rest at a stop, s.
        decel: braking deceleration, m/s^2.
        accel: acceleration when setting off, m/s^2.
        centre_time: time at the middle of the manoeuvre (None: ``[0, (num_frames - 1) * dt]``).
        stop_time: time a stopping vehicle comes to rest (None: ``[0, (num_frames - 1) * dt]``).
        lane_offset: distance of the lanes from the road axes, metres.
        scene_radius: a vehicle exists only while within this distance of the origin (None: always).
        turn_lateral_accel: a turning vehicle's cruise speed is at most ``sqrt(turn_lateral_accel * radius)``
            (m/s^2; None: turns are driven at the drawn cruise speed, up to 1.5 g at the defaults).
    """

    routes: tuple[RouteSpec, ...] = ()
    speed: tuple[float, float] = (5.0, 12.0)
    arms: tuple[str, ...] = tuple(ARMS)
    turns: tuple[str, ...] = tuple(TURNS)
    radius: tuple[float, float] = (6.0, 15.0)
    stop_probability: float = 0.3
    stop_at: tuple[float, float] = (7.0, 7.0)
    wait: tuple[float, float] = (1.0, 3.0)
    decel: tuple[float, float] = (2.0, 3.0)
    accel: tuple[float, float] = (1.5, 2.5)
    centre_time: tuple[float, float] | None = None
    stop_time: tuple[float, float] | None = None
    lane_offset: float = 1.75
    scene_radius: float | None = None
    turn_lateral_accel: float | None = None


@dataclass(frozen=True)
class Scenario:
    """Everything :func:`vfactor.sim.simulate` needs.

    Attributes:
        cameras: camera name -> :class:`Camera`, in file order.
        vehicles: vehicle names (:func:`vfactor.sim.vehicles.draw_vehicle`): presets, library
            ids, ``"library"``, ``"library:<body type>"`` or ``"random"``.
        name: scenario name.
        description: free text.
        vehicle_order: ``"cycle"`` or ``"random"``: how each vehicle slot picks from ``vehicles``.
        vehicles_per_frame: vehicles in each frame (ids ``v1``, ``v2``, ...).
        random_shape: how ``"random"`` shapes are drawn.
        region: ``((x_min, x_max), (y_min, y_max))`` world box of vehicle positions, metres
            (with :attr:`motion`: the positions at the middle frame).
        yaw_range: ``(min, max)`` heading, radians.
        visible_in: cameras whose images must hold all 12 keypoints (with ``margin_px``).
        require_visible: ``"all"``: every ``visible_in`` camera holds every vehicle in every
            frame; ``"any"``: at least one of them does in every frame the vehicle exists;
            ``"none"``: no requirement (vehicles may leave the views).
        margin_px: margin for that check, pixels.
        min_gap: minimum gap between two vehicles' footprints, metres.
        noise: keypoint noise.
        num_frames: number of frames.
        dt: time between frames, seconds.
        seed: default random seed.
        ground_plane: write the road plane ``z = 0`` into the simulated scene.
        motion: None for independent frames (a new vehicle in every frame), or
            the motion of vehicles that keep their id and shape over the frames:
            :class:`Motion` (constant speed and turn rate) or :class:`RouteMotion`
            (routes through the intersection, or explicit paths, with stops).
        body_motion: with :attr:`motion`, the body's roll and pitch with the accelerations
            (:class:`BodyMotion`); None: rigid vehicles (roll and pitch 0, as on a flat road).
        extrinsic_error: the simulated scene's cameras err from the true ones (:class:`ExtrinsicError`); None:
            they are the true ones.
    """

    cameras: dict[str, Camera]
    vehicles: tuple[str, ...]
    name: str = "scenario"
    description: str = ""
    vehicle_order: str = "cycle"
    vehicles_per_frame: int = 1
    random_shape: RandomShape = field(default_factory=RandomShape)
    region: tuple[tuple[float, float], tuple[float, float]] = ((-2.0, 2.0), (-2.0, 2.0))
    yaw_range: tuple[float, float] = (0.0, 2.0 * math.pi)
    visible_in: tuple[str, ...] | None = None
    require_visible: str = "all"
    margin_px: float = 20.0
    min_gap: float = 0.5
    noise: NoiseModel = field(default_factory=NoiseModel)
    num_frames: int = 10
    dt: float = 0.1
    seed: int = 0
    motion: Motion | RouteMotion | None = None
    ground_plane: bool = False
    body_motion: BodyMotion | None = None
    extrinsic_error: ExtrinsicError | None = None

    def __post_init__(self):
        if self.visible_in is None:
            object.__setattr__(self, "visible_in", tuple(self.cameras))

    def required_cameras(self) -> list[Camera]:
        """The cameras whose images must hold every keypoint of every vehicle (all or one: :attr:`require_visible`)."""
        return [self.cameras[name] for name in self.visible_in]


def scenario_path(name_or_path: str | Path) -> Path:
    """Resolves a packaged scenario name (``"intersection_2cam"``) or a file path.

    A value naming an existing file is returned as is; otherwise a bare name
    (with or without ``.json``) is looked up among the packaged scenarios (``graphs/``).

    Raises:
        ScenarioError: neither a file nor a packaged scenario (the message lists the packaged ones).
    """
    path = Path(name_or_path)
    if path.is_file():
        return path
    if path.parent == Path(".") and path.suffix in ("", ".json"):
        packaged = _graphs_dir() / f"{path.stem}.json"
        if packaged.is_file():
            return packaged
    raise ScenarioError(
        "", f"scenario {str(name_or_path)!r}: no such file or packaged scenario; packaged: {list_scenarios()}"
    )


def list_scenarios() -> list[str]:
    """Names of the scenarios packaged in ``graphs/`` (``vfactor.graphs``)."""
    return sorted(p.stem for p in _graphs_dir().glob("*.json"))


def _graphs_dir() -> Path:
    return Path(str(resources.files("vfactor.graphs")))


def load_scenario(name_or_path: str | Path | Scenario) -> Scenario:
    """Loads and validates a scenario file (a packaged name or a path); a :class:`Scenario` is returned as it is
    (so that every function taking a scenario takes a name, a file or one built in code).

    Raises:
        ScenarioError: the file is missing, not JSON, or a field is wrong (the error names it).
    """
    if isinstance(name_or_path, Scenario):
        return name_or_path
    path = scenario_path(name_or_path)
    data = read_json(path, ScenarioError)  # vfactor.jsonio: numbers out of range and deep nesting are input errors
    return scenario_from_dict(data, default_name=path.stem)


def scenario_on_cameras(base: Scenario, cameras: dict[str, Camera], name: str | None = None) -> Scenario:
    """``base``'s vehicles, noise and motion seen by another rig (a user's calibrated cameras): how vfactor does there.

    The rig is moved along the road (a horizontal translation of the world, which changes no error) so that the
    point it looks at, the median of the points where its cameras' optical axes meet the road (the world's ``z = 0``
    plane), is the world origin, around which ``base`` puts its vehicles (its ``region``, or its routes through the
    intersection). Independent frames (``base`` without motion) need each vehicle whole in at least one camera's
    image (``require_visible="any"``): where the views overlap little, some vehicles are seen by one camera, and
    ``vfactor eval`` reports per camera count; tracks keep ``base``'s requirement. The cameras' ``extrinsic_sigma``
    is dropped: a scenario's cameras are the true ones (its ``extrinsic_error`` simulates a survey's error).

    Args:
        base: the scenario to take the vehicles, noise, motion and frames from (``load_scenario("library_2cam")``
            for frames, ``"library_tracks_2cam"`` for tracks).
        cameras: camera name -> :class:`~vfactor.camera.Camera` (a scene's ``cameras``).
        name: the scenario's name (default: ``base``'s with ``" on your cameras"``).

    Raises:
        ScenarioError: (field ``cameras``) no camera, or none whose optical axis meets the road in front of it.
    """
    if not cameras:
        raise ScenarioError("cameras", "expected at least one camera")
    on_road = []
    for camera in cameras.values():
        centre, axis = camera.world_T_camera[:3, 3], camera.world_T_camera[:3, 2]
        if axis[2] < -1e-6 and centre[2] > 0:  # looking down from above the road
            on_road.append(centre[:2] - centre[2] / axis[2] * axis[:2])
    if not on_road:
        raise ScenarioError("cameras", "no camera's optical axis meets the road (the world's z = 0 plane, world z "
                            "up) in front of it: check world_T_camera (docs/conventions.md)")
    x, y = (float(v) for v in np.median(on_road, axis=0))
    moved = {}
    for camera_name, camera in cameras.items():
        world_T_camera = camera.world_T_camera.copy()
        world_T_camera[:2, 3] -= (x, y)
        moved[camera_name] = dataclasses.replace(camera, world_T_camera=world_T_camera, extrinsic_sigma=None)
    return dataclasses.replace(
        base, cameras=moved, name=name or f"{base.name} on your cameras",
        description=f"{base.name}'s vehicles seen by {len(moved)} given camera(s), moved by ({-x:.1f}, {-y:.1f}) m "
                    "along the road so that the point they look at is the world origin",
        visible_in=tuple(moved), require_visible=base.require_visible if base.motion is not None else "any")


def scenario_from_dict(data: dict, default_name: str = "scenario") -> Scenario:
    """Validates a scenario (the parsed JSON) and builds a :class:`Scenario`.

    See :data:`SCENARIO_FIELDS` and :data:`CAMERA_FIELDS` for the keys.

    Raises:
        ScenarioError: unknown key, missing key, wrong type or out-of-range value,
            with the field path.
    """
    chk.check_mapping(data, "", SCENARIO_FIELDS, required=("cameras", "vehicles"))
    kw: dict = {"name": chk.string(data.get("name", default_name), "name")}
    if "description" in data:
        if not isinstance(data["description"], str):
            raise ScenarioError("description", f"expected a string, got {data['description']!r}")
        kw["description"] = data["description"]

    cameras = data["cameras"]
    if not isinstance(cameras, list) or not cameras:
        raise ScenarioError("cameras", "expected a non-empty list of cameras")
    kw["cameras"] = {}
    for i, entry in enumerate(cameras):
        camera = _camera(entry, f"cameras[{i}]")
        if camera.name in kw["cameras"]:
            raise ScenarioError(f"cameras[{i}].name", f"duplicate camera name {camera.name!r}")
        kw["cameras"][camera.name] = camera

    vehicles = data["vehicles"]
    if not isinstance(vehicles, list) or not vehicles:
        raise ScenarioError("vehicles", f'expected a non-empty list of vehicle names (presets, library ids, '
                                        f'"library", "library:<body type>" or "{RANDOM}")')
    kw["vehicles"] = tuple(_vehicle_name(v, f"vehicles[{i}]") for i, v in enumerate(vehicles))
    if "vehicle_order" in data:
        kw["vehicle_order"] = chk.string(data["vehicle_order"], "vehicle_order", choices={"cycle", "random"})
    if "vehicles_per_frame" in data:
        kw["vehicles_per_frame"] = chk.number(
            data["vehicles_per_frame"], "vehicles_per_frame", lo=1, hi=20, integer=True
        )
    if "random_shape" in data:
        kw["random_shape"] = _random_shape(data["random_shape"], "random_shape")
    if "region" in data:
        region = chk.check_mapping(data["region"], "region", ("x", "y"), required=("x", "y"))
        kw["region"] = (chk.interval(region["x"], "region.x"), chk.interval(region["y"], "region.y"))
    if "yaw_deg" in data:
        lo, hi = chk.interval(data["yaw_deg"], "yaw_deg", lo=-360.0, hi=720.0)
        if hi - lo > 360.0:
            raise ScenarioError("yaw_deg", f"expected a range of at most 360 degrees, got {[lo, hi]}")
        kw["yaw_range"] = (math.radians(lo), math.radians(hi))
    if "visible_in" in data:
        kw["visible_in"] = _visible_in(data["visible_in"], kw["cameras"])
    if "ground_plane" in data:
        if not isinstance(data["ground_plane"], bool):
            raise ScenarioError("ground_plane", f"expected true or false, got {data['ground_plane']!r}")
        kw["ground_plane"] = data["ground_plane"]
    if "require_visible" in data:
        kw["require_visible"] = chk.string(data["require_visible"], "require_visible", choices=set(REQUIRE_VISIBLE))
    if "margin_px" in data:
        kw["margin_px"] = chk.number(data["margin_px"], "margin_px", lo=0.0)
    if "min_gap" in data:
        kw["min_gap"] = chk.number(data["min_gap"], "min_gap", lo=0.0)
    if "noise" in data:
        kw["noise"] = noise_from_value(data["noise"], "noise")
    if "num_frames" in data:
        kw["num_frames"] = chk.number(data["num_frames"], "num_frames", lo=1, integer=True)
    if "dt" in data:
        kw["dt"] = chk.number(data["dt"], "dt", lo=0.0, lo_open=True)
    if "seed" in data:
        kw["seed"] = chk.number(data["seed"], "seed", lo=0, integer=True)
    if data.get("motion") is not None:
        kw["motion"] = _motion(data["motion"], "motion")
        routes = getattr(kw["motion"], "routes", ())
        if routes:
            if "vehicles_per_frame" not in kw:
                kw["vehicles_per_frame"] = len(routes)
            elif kw["vehicles_per_frame"] < len(routes):
                raise ScenarioError(
                    "motion.routes",
                    f"{len(routes)} routes for vehicles_per_frame = {kw['vehicles_per_frame']}: "
                    "give at most one route per vehicle (or leave vehicles_per_frame out)",
                )
    if data.get("body_motion") is not None:
        if "motion" not in kw:
            raise ScenarioError("body_motion", "needs motion: vehicles of independent frames have no accelerations")
        value = chk.check_mapping(data["body_motion"], "body_motion", ("roll_deg_per_g", "pitch_deg_per_g"))
        kw["body_motion"] = BodyMotion(**{key: chk.number(value[key], f"body_motion.{key}", lo=0.0,
                                                          hi=BodyMotion.MAX_DEG_PER_G)
                                          for key in ("roll_deg_per_g", "pitch_deg_per_g") if key in value})
    if data.get("extrinsic_error") is not None:
        value = chk.check_mapping(data["extrinsic_error"], "extrinsic_error",
                                  ("rotation_deg", "translation_m", "declared"))
        kw["extrinsic_error"] = ExtrinsicError(**value)  # which checks its fields, naming them
    return Scenario(**kw)


def noise_from_value(value, field: str = "noise") -> NoiseModel:
    """A :class:`NoiseModel` from a scenario's ``noise`` entry (an object or a preset name)."""
    if isinstance(value, str):
        return _NOISE_PRESETS[chk.string(value, field, choices=set(_NOISE_PRESETS))]
    defaults = NoiseModel()
    names = list(defaults.to_dict())
    chk.check_mapping(value, field, names)
    kw = {}
    for key in ("relative_sigma", "outlier_box_growth"):
        if key in value:
            kw[key] = chk.number(value[key], chk.join(field, key), lo=0.0, hi=10.0)
    if "occluded_factor" in value:
        where = chk.join(field, "occluded_factor")
        kw["occluded_factor"] = chk.number(value["occluded_factor"], where, lo=0.0, hi=100.0)
    for key in ("outlier_rate", "swap_rate", "missing_rate"):
        if key in value:
            kw[key] = chk.number(value[key], chk.join(field, key), lo=0.0, hi=1.0)
    for key in ("confidence_visible", "confidence_occluded"):
        if key in value:
            lo, hi = chk.interval(value[key], chk.join(field, key), lo=0.0, hi=1.0)
            if lo <= 0.0:
                raise ScenarioError(
                    chk.join(field, key), f"expected a lowest confidence > 0 (0 means unseen), got {lo}"
                )
            kw[key] = (lo, hi)
    return NoiseModel(**kw)


def _camera(entry, field: str) -> Camera:
    chk.check_mapping(entry, field, CAMERA_FIELDS, required=("name",))
    name = chk.string(entry["name"], chk.join(field, "name"))
    size = entry.get("image_size", [1280, 720])
    if (
        not isinstance(size, list)
        or len(size) != 2
        or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in size)
    ):
        raise ScenarioError(
            chk.join(field, "image_size"), f"expected [width, height], two positive integers, got {size!r}"
        )
    size = (size[0], size[1])

    if ("hfov_deg" in entry) == ("K" in entry):
        raise ScenarioError(field, "give exactly one of hfov_deg and K")
    if "hfov_deg" in entry:
        hfov = chk.number(entry["hfov_deg"], chk.join(field, "hfov_deg"), lo=0.0, hi=180.0, lo_open=True, hi_open=True)
        K = intrinsics_from_hfov(hfov, size)
    else:
        K = chk.matrix(entry["K"], chk.join(field, "K"), (3, 3))

    placed = [k for k in ("pole", "height", "look_at") if k in entry]
    if "world_T_camera" in entry:
        if placed:
            raise ScenarioError(
                chk.join(field, placed[0]), "give either world_T_camera or pole/height/look_at, not both"
            )
        world_T_camera = chk.matrix(entry["world_T_camera"], chk.join(field, "world_T_camera"), (4, 4))
    else:
        for key in ("pole", "height"):
            if key not in entry:
                raise ScenarioError(chk.join(field, key), "missing (or give world_T_camera)")
        pole = chk.vector(entry["pole"], chk.join(field, "pole"), 2)
        height = chk.number(entry["height"], chk.join(field, "height"), lo=0.0, lo_open=True)
        target = chk.vector(entry.get("look_at", [0.0, 0.0, 0.0]), chk.join(field, "look_at"), 3)
        try:
            world_T_camera = look_at([pole[0], pole[1], height], target)
        except ValueError as exc:
            raise ScenarioError(chk.join(field, "look_at"), str(exc).removeprefix("look_at: ")) from None

    dist = None
    if "dist" in entry:
        d = entry["dist"]
        if not isinstance(d, list) or len(d) not in (4, 5):
            raise ScenarioError(chk.join(field, "dist"), f"expected 4 or 5 numbers [k1, k2, p1, p2(, k3)], got {d!r}")
        dist = chk.vector(d, chk.join(field, "dist"), len(d))
    try:
        return Camera(name=name, K=K, world_T_camera=world_T_camera, dist=dist, image_size=size)
    except CalibrationError as exc:
        raise ScenarioError(chk.join(field, exc.field), exc.problem) from None


def _visible_in(value, cameras: dict) -> tuple[str, ...]:
    if value == "all":
        return tuple(cameras)
    if not isinstance(value, list) or not value:
        raise ScenarioError("visible_in", f'expected "all" or a non-empty list of camera names, got {value!r}')
    names = tuple(chk.string(v, f"visible_in[{i}]", choices=set(cameras)) for i, v in enumerate(value))
    if len(set(names)) != len(names):
        raise ScenarioError("visible_in", f"camera names repeat: {list(names)}")
    return names


def _random_shape(value, field: str) -> RandomShape:
    chk.check_mapping(value, field, ("wheelbase", "jitter", "wheel_radius"))
    kw = {}
    if "wheelbase" in value:
        kw["wheelbase"] = chk.interval(value["wheelbase"], chk.join(field, "wheelbase"), lo=1.5, hi=4.5)
    if "jitter" in value:
        kw["jitter"] = chk.number(value["jitter"], chk.join(field, "jitter"), lo=0.0, hi=0.2)
    if "wheel_radius" in value:
        kw["wheel_radius"] = chk.number(value["wheel_radius"], chk.join(field, "wheel_radius"), lo=0.1, hi=1.0)
    return RandomShape(**kw)


def _motion(value, field: str) -> Motion | RouteMotion:
    if isinstance(value, dict) and "kind" in value:
        kind = chk.string(value["kind"], chk.join(field, "kind"), choices={"constant", "route"})
        if kind == "route":
            return _route_motion(value, field)
    if isinstance(value, dict):
        for key in value:
            if key in ROUTE_MOTION_FIELDS and key not in MOTION_FIELDS:
                raise ScenarioError(
                    chk.join(field, key), 'unknown key for "kind": "constant"; it needs "kind": "route"'
                )
    chk.check_mapping(value, field, MOTION_FIELDS)
    kw = {}
    if "speed" in value:
        kw["speed"] = chk.interval(value["speed"], chk.join(field, "speed"), lo=0.0, hi=70.0)
    if "yaw_rate_deg" in value:
        lo, hi = chk.interval(value["yaw_rate_deg"], chk.join(field, "yaw_rate_deg"), lo=-180.0, hi=180.0)
        kw["yaw_rate"] = (math.radians(lo), math.radians(hi))
    return Motion(**kw)


# Bounds of the route quantities: (lo, hi, lo_open).
_SPEED = (0.0, 70.0, True)
_RADIUS = (2.0, 200.0, False)
_STOP_AT = (0.0, 200.0, False)
_WAIT = (0.0, 600.0, False)
_ACCEL = (0.0, 10.0, True)
_TIME = (-1e6, 1e6, False)


def _range(value, field: str, bounds) -> tuple[float, float]:
    """``[min, max]`` or one number (a fixed value), within ``bounds``."""
    lo, hi, lo_open = bounds
    if chk.is_number(value):
        x = chk.number(value, field, lo=lo, hi=hi, lo_open=lo_open)
        return (x, x)
    a, b = chk.interval(value, field, lo=lo, hi=hi)
    if lo_open and a <= lo:
        raise ScenarioError(field, f"expected values > {lo}, got {list(value)}")
    return a, b


def _scalar(value, field: str, bounds) -> float:
    lo, hi, lo_open = bounds
    return chk.number(value, field, lo=lo, hi=hi, lo_open=lo_open)


def _choices(value, field: str, allowed) -> tuple[str, ...]:
    if not isinstance(value, list) or not value:
        raise ScenarioError(field, f"expected a non-empty list of {sorted(allowed)}, got {value!r}")
    names = tuple(chk.string(v, chk.join(field, i), choices=set(allowed)) for i, v in enumerate(value))
    if len(set(names)) != len(names):
        raise ScenarioError(field, f"names repeat: {list(names)}")
    return names


def _boolean(value, field: str) -> bool:
    if not isinstance(value, bool):
        raise ScenarioError(field, f"expected true or false, got {value!r}")
    return value


def _route_motion(value, field: str) -> RouteMotion:
    chk.check_mapping(value, field, ROUTE_MOTION_FIELDS)
    kw: dict = {}
    where = lambda key: chk.join(field, key)  # noqa: E731
    for key, bounds in (("speed", _SPEED), ("radius", _RADIUS), ("stop_at", _STOP_AT), ("wait", _WAIT),
                        ("decel", _ACCEL), ("accel", _ACCEL)):
        if key in value:
            kw[key] = _range(value[key], where(key), bounds)
    for key in ("centre_time", "stop_time"):
        if value.get(key) is not None:
            kw[key] = _range(value[key], where(key), _TIME)
    if "from" in value:
        kw["arms"] = _choices(value["from"], where("from"), ARMS)
    if "turn" in value:
        kw["turns"] = _choices(value["turn"], where("turn"), TURNS)
    if "stop_probability" in value:
        kw["stop_probability"] = chk.number(value["stop_probability"], where("stop_probability"), lo=0.0, hi=1.0)
    if "lane_offset" in value:
        kw["lane_offset"] = chk.number(value["lane_offset"], where("lane_offset"), lo=-20.0, hi=20.0)
    if value.get("scene_radius") is not None:
        kw["scene_radius"] = chk.number(value["scene_radius"], where("scene_radius"), lo=0.0, lo_open=True)
    if value.get("turn_lateral_accel") is not None:
        kw["turn_lateral_accel"] = chk.number(value["turn_lateral_accel"], where("turn_lateral_accel"), lo=0.0,
                                              hi=15.0, lo_open=True)
    if "routes" in value:
        routes = value["routes"]
        if not isinstance(routes, list):
            raise ScenarioError(where("routes"), f"expected a list of routes, got {routes!r}")
        kw["routes"] = tuple(_route(r, chk.join(where("routes"), i)) for i, r in enumerate(routes))
    return RouteMotion(**kw)


def _vehicle_name(value, field: str) -> str:
    try:
        return check_vehicle_name(chk.string(value, field))
    except ValueError as exc:
        if isinstance(exc, ScenarioError):
            raise
        raise ScenarioError(field, str(exc).split(": ", 1)[1]) from None


def _route(value, field: str) -> RouteSpec:
    chk.check_mapping(value, field, ROUTE_FIELDS)
    where = lambda key: chk.join(field, key)  # noqa: E731
    kw: dict = {}
    if "vehicle" in value:
        kw["vehicle"] = _vehicle_name(value["vehicle"], where("vehicle"))
    for key, bounds in (("speed", _SPEED), ("wait", _WAIT), ("decel", _ACCEL), ("accel", _ACCEL)):
        if key in value:
            kw[key] = _scalar(value[key], where(key), bounds)
    if "path" in value:
        for key in _INTERSECTION_ONLY:
            if key in value:
                raise ScenarioError(where(key), 'not with "path" (an explicit path sets its own course and stops)')
        kw["path"] = _path(value["path"], where("path"))
        if "stops" in value:
            kw["stops"] = _stops(value["stops"], where("stops"))
        if "start_speed" in value:
            kw["start_speed"] = chk.number(value["start_speed"], where("start_speed"), lo=0.0, hi=70.0)
            if "speed" in kw and kw["start_speed"] > kw["speed"]:
                raise ScenarioError(
                    where("start_speed"), f"expected at most the cruise speed {kw['speed']}, got {kw['start_speed']}"
                )
        if "start_time" in value:
            kw["start_time"] = _scalar(value["start_time"], where("start_time"), _TIME)
        return RouteSpec(**kw)

    for key in _PATH_ONLY:
        if key in value:
            raise ScenarioError(where(key), 'only with "path"')
    if "from" in value:
        kw["arm"] = chk.string(value["from"], where("from"), choices=set(ARMS))
    if "turn" in value:
        kw["turn"] = chk.string(value["turn"], where("turn"), choices=set(TURNS))
    if "radius" in value:
        kw["radius"] = _scalar(value["radius"], where("radius"), _RADIUS)
    if "stop" in value:
        kw["stop"] = _boolean(value["stop"], where("stop"))
    if "stop_at" in value:
        kw["stop_at"] = _scalar(value["stop_at"], where("stop_at"), _STOP_AT)
    if "centre_time" in value and "stop_time" in value:
        raise ScenarioError(where("stop_time"), "give at most one of centre_time and stop_time")
    if "centre_time" in value:
        kw["centre_time"] = _scalar(value["centre_time"], where("centre_time"), _TIME)
    if "stop_time" in value:
        if kw.get("stop") is False:
            raise ScenarioError(where("stop_time"), "a vehicle with stop: false has no stop time")
        kw["stop_time"] = _scalar(value["stop_time"], where("stop_time"), _TIME)
        kw["stop"] = True
    return RouteSpec(**kw)


def _path(value, field: str) -> RoutePath:
    chk.check_mapping(value, field, ("start", "segments", "loop"), required=("start", "segments"))
    x, y, yaw_deg = chk.vector(value["start"], chk.join(field, "start"), 3)
    segments_value = value["segments"]
    where = chk.join(field, "segments")
    if not isinstance(segments_value, list) or not segments_value:
        raise ScenarioError(where, "expected a non-empty list of segments")
    segments = []
    for i, seg in enumerate(segments_value):
        at = chk.join(where, i)
        if isinstance(seg, dict) and "straight" in seg:
            chk.check_mapping(seg, at, ("straight",))
            segments.append((chk.number(seg["straight"], chk.join(at, "straight"), lo=0.0, lo_open=True), 0.0))
        else:
            chk.check_mapping(seg, at, ("arc_deg", "radius"), required=("arc_deg", "radius"))
            angle = chk.number(seg["arc_deg"], chk.join(at, "arc_deg"), lo=-3600.0, hi=3600.0)
            if angle == 0.0:
                raise ScenarioError(chk.join(at, "arc_deg"), "expected a non-zero angle (left positive)")
            radius = _scalar(seg["radius"], chk.join(at, "radius"), _RADIUS)
            segments.append((abs(math.radians(angle)) * radius, math.copysign(1.0 / radius, angle)))
    loop = _boolean(value.get("loop", False), chk.join(field, "loop"))
    try:
        return RoutePath((float(x), float(y), math.radians(yaw_deg)), tuple(segments), loop)
    except ValueError as exc:
        raise ScenarioError(field, str(exc).removeprefix("Path: ")) from None


def _stops(value, field: str) -> tuple[tuple[float, float | None], ...]:
    if not isinstance(value, list):
        raise ScenarioError(field, f'expected a list of {{"at": m, "wait": s}}, got {value!r}')
    stops, last = [], -math.inf
    for i, stop in enumerate(value):
        at = chk.join(field, i)
        chk.check_mapping(stop, at, ("at", "wait"), required=("at",))
        s = chk.number(stop["at"], chk.join(at, "at"), lo=0.0)
        if s <= last:
            raise ScenarioError(chk.join(at, "at"), f"expected stops in increasing order, got {s} after {last}")
        wait = _scalar(stop["wait"], chk.join(at, "wait"), _WAIT) if "wait" in stop else None
        stops.append((s, wait))
        last = s
    return tuple(stops)
