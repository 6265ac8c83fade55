"""Simulated scenes: vehicles placed on the road, seen by a camera rig through a noisy detector.

:func:`simulate` turns a :class:`~vfactor.sim.scenario.Scenario` into a
:class:`vfactor.observations.Scene` (what the solvers read) and the ground
truth (what the metrics compare against). Everything random comes from
generators seeded by ``(seed, stream, frame)``, so the same seed gives the same
scene; with independent frames (no motion), frame ``f`` does not depend on how
many frames follow it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import gtsam
import numpy as np

from vfactor.camera import Camera
from vfactor.errors import ScenarioError
from vfactor.factors.ground_plane import GroundPlane
from vfactor.keypoints import LAYERS
from vfactor.observations import Detection, Frame, Scene
from vfactor.sim.noise import corrupt_keypoints
from vfactor.sim.routes import Trajectory, drive_profile, intersection_path
from vfactor.sim.scenario import RouteMotion, RouteSpec, Scenario, load_scenario
from vfactor.sim.vehicles import draw_vehicle, footprint, footprints_overlap, road_pose
from vfactor.sim.visibility import VehicleBody, occluded_keypoints
from vfactor.wireframe import Wireframe

__all__ = ["VehicleTruth", "DetectionTruth", "Simulation", "simulate", "vehicle_ids", "keypoints_in_view"]

# Random streams: (seed, stream, ...) seeds one generator each.
_PLACE, _NOISE, _TRACKS, _EXTRINSICS = 0, 1, 2, 3
_MAX_TRIES = 2000
_ROUTE_TRIES = 500
_ROUTE_DRAWS = 10  # uniform draws per route try, whatever is given explicitly


@dataclass(frozen=True)
class VehicleTruth:
    """The true state of one vehicle in one frame.

    Attributes:
        world_T_vehicle: body -> world pose.
        wireframe: body-frame keypoints, metres.
        preset: the vehicle model: preset name, library id, or ``"random"``.
        wheel_radius: hub height above the road, metres.
        speed: forward speed along body x, m/s (None for independent frames).
        yaw_rate: rad/s, counter-clockwise seen from above (None for independent frames).
        acceleration: longitudinal acceleration, m/s^2 (None for independent frames).
        body_roll, body_pitch: where the scenario has ``body_motion``, the body's roll and pitch on its
            suspension against the hubs' frame, radians (None: a rigid vehicle); :attr:`seen_keypoints_world`.

    With motion, the velocity is ``speed`` along the heading (the vehicle never
    slides sideways): world ``(speed * cos(yaw), speed * sin(yaw), 0)``. The pose
    is the hubs' frame (on the road); a body that rolls or pitches moves its
    lights, windshield and rear-window keypoints, not its hubs, so its 12
    keypoints are no longer its rigid :attr:`wireframe`'s.
    """

    world_T_vehicle: gtsam.Pose3
    wireframe: Wireframe
    preset: str
    wheel_radius: float = 0.33
    speed: float | None = None
    yaw_rate: float | None = None
    acceleration: float | None = None
    body_roll: float | None = None
    body_pitch: float | None = None

    @property
    def keypoints_world(self) -> np.ndarray:
        """(12, 3) keypoints of the rigid vehicle (:attr:`wireframe` at :attr:`world_T_vehicle`) in the world frame,
        metres: what an estimate of the vehicle's pose and shape is scored against."""
        return self.wireframe.in_world(self.world_T_vehicle)

    @property
    def seen_keypoints_world(self) -> np.ndarray:
        """(12, 3) the keypoints where the cameras see them, world frame, metres: :attr:`keypoints_world` with the
        body's keypoints (all but the four hubs) turned by :attr:`body_roll` (about body x) and :attr:`body_pitch`
        (about body y) around the hubs' centre, the body frame's origin; the same as :attr:`keypoints_world` for a
        rigid vehicle."""
        if not self.body_roll and not self.body_pitch:
            return self.keypoints_world
        body = np.array(self.wireframe.vehicle_p_keypoints, dtype=float)
        turn = (gtsam.Rot3.Rx(float(self.body_roll or 0.0)) * gtsam.Rot3.Ry(float(self.body_pitch or 0.0))).matrix()
        sprung = np.setdiff1d(np.arange(len(body)), LAYERS["wheel"])  # all but the hubs
        body[sprung] = body[sprung] @ turn.T
        return self.world_T_vehicle.transformFrom(body.T).T

    @property
    def keypoints_vehicle(self) -> np.ndarray:
        """(12, 3) keypoints in the body frame, metres."""
        return self.wireframe.vehicle_p_keypoints


@dataclass
class DetectionTruth:
    """What lies behind one simulated detection; arrays indexed by keypoint label.

    Attributes:
        uv_true: (12, 2) true projections, pixels.
        occluded: (12,) hidden from the camera (by the vehicle itself or another one).
        sigma_px: (12,) standard deviation of the pixel noise of the measurement
            under each label (NaN for outliers).
        outlier: (12,) the measurement is a uniform outlier.
        swapped: (12,) the label was swapped with its left/right partner.
        missing: (12,) not detected.
    """

    uv_true: np.ndarray
    occluded: np.ndarray
    sigma_px: np.ndarray
    outlier: np.ndarray
    swapped: np.ndarray
    missing: np.ndarray


@dataclass
class Simulation:
    """A simulated scene and its ground truth.

    Attributes:
        scenario: the scenario simulated.
        seed: the seed used.
        scene: cameras and detections, as a scene file would give them.
        truth: per frame, vehicle id -> :class:`VehicleTruth`.
        detection_truth: per frame, ``(camera, vehicle)`` -> :class:`DetectionTruth`,
            for every detection in :attr:`scene`.
        trajectories: with route motion, vehicle id -> :class:`~vfactor.sim.routes.Trajectory`,
            the continuous-time truth (``trajectories[vid].states(times)``); its ``info``
            holds the route after the random draws. Empty otherwise.
    """

    scenario: Scenario
    seed: int
    scene: Scene
    truth: list[dict[str, VehicleTruth]]
    detection_truth: list[dict[tuple[str, str], DetectionTruth]] = field(default_factory=list)
    trajectories: dict[str, Trajectory] = field(default_factory=dict)

    def vehicle_frames(self, vehicle: str) -> list[int]:
        """Indices of the frames in which a vehicle exists (is in :attr:`truth`)."""
        return [f for f, truth in enumerate(self.truth) if vehicle in truth]

    def occluded(self, frame: int, camera: str, vehicle: str) -> np.ndarray:
        """(12,) occlusion mask of one detection."""
        return self.detection_truth[frame][(camera, vehicle)].occluded


def vehicle_ids(count: int) -> list[str]:
    """Track ids ``v1``, ``v2``, ... of ``count`` vehicles."""
    return [f"v{k + 1}" for k in range(count)]


def keypoints_in_view(world_p: np.ndarray, cameras: list[Camera], margin_px: float = 0.0) -> bool:
    """Whether every point (N, 3) is in front of and inside the image of every camera, ``margin_px`` from its border."""
    for camera in cameras:
        uv, depth = camera.project(world_p)
        if np.any(depth <= 0.1) or not np.all(camera.in_image(uv, margin=-margin_px)):
            return False
    return True


def simulate(scenario: Scenario | str | Path, seed: int | None = None, num_frames: int | None = None) -> Simulation:
    """Simulates a scenario.

    Each vehicle stands on the road (roll = pitch = 0, hubs ``wheel_radius``
    above ``z = 0``) at a random position in ``scenario.region`` with a random
    yaw in ``scenario.yaw_range``, redrawn until its 12 keypoints project inside
    the images of ``scenario.visible_in`` (``margin_px`` from the border) and its
    footprint keeps ``min_gap`` from the other vehicles'. Each camera's
    detection of each vehicle is then corrupted by ``scenario.noise``; keypoints
    hidden by a vehicle body count as occluded. A camera that sees none of a
    vehicle's keypoints gives no detection.

    Without ``scenario.motion``, frames are independent (frame ``f`` at
    ``t = f * dt`` holds new vehicles ``v1``, ``v2``, ...). With a
    :class:`~vfactor.sim.scenario.Motion`, each id is one vehicle moving at
    constant speed and yaw rate, its position at the middle frame drawn in the
    region. With a :class:`~vfactor.sim.scenario.RouteMotion`, each id drives a
    route through the intersection (or an explicit path) with stops, and exists
    in the frames where it is in the scene; vehicles are redrawn until they
    keep ``min_gap`` from each other and meet ``require_visible``.

    The detections are those of ``scenario.cameras``; with
    ``scenario.extrinsic_error`` the scene's cameras are those cameras as a
    survey that errs gives them (:class:`~vfactor.sim.scenario.ExtrinsicError`:
    each moved by its own draw), the truth's frames the true ones.

    Args:
        scenario: a :class:`Scenario`, or a packaged scenario name or file path.
        seed: overrides ``scenario.seed`` (an integer >= 0).
        num_frames: overrides ``scenario.num_frames``.

    Returns:
        :class:`Simulation`.

    Raises:
        ScenarioError: no placement found (the region is not seen by the required cameras, or too crowded).
    """
    scenario = load_scenario(scenario)
    seed = scenario.seed if seed is None else int(seed)
    if seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, got {seed}")
    num_frames = scenario.num_frames if num_frames is None else int(num_frames)
    if num_frames < 1:
        raise ValueError(f"num_frames: expected >= 1, got {num_frames}")

    trajectories: dict[str, Trajectory] = {}
    if scenario.motion is None:
        truth = [_place_frame(scenario, np.random.default_rng([seed, _PLACE, f]), f) for f in range(num_frames)]
    elif isinstance(scenario.motion, RouteMotion):
        truth, trajectories = _place_routes(scenario, np.random.default_rng([seed, _TRACKS]), num_frames)
    else:
        truth = _place_tracks(scenario, np.random.default_rng([seed, _TRACKS]), num_frames)

    if scenario.body_motion is not None:
        truth = [{vid: scenario.body_motion.applied(v) for vid, v in frame.items()} for frame in truth]
    frames, detection_truth = _observe_frames(scenario, truth, seed)  # by the true cameras
    cameras = dict(scenario.cameras)
    if scenario.extrinsic_error is not None:  # the scene's cameras as surveyed
        cameras = scenario.extrinsic_error.surveyed(cameras, np.random.default_rng([seed, _EXTRINSICS]))
    scene = Scene(cameras=cameras, frames=frames, base_dir=None,
                  ground_plane=GroundPlane() if scenario.ground_plane else None)
    return Simulation(
        scenario=scenario, seed=seed, scene=scene, truth=truth, detection_truth=detection_truth,
        trajectories=trajectories,
    )


def redraw_noise(sim: Simulation, noise_seed: int) -> Simulation:
    """The same vehicles and motion with newly drawn detection noise.

    ``redraw_noise(sim, sim.seed)`` gives ``sim`` again; other seeds give other
    draws of the scenario's noise model for the same truth (for Monte Carlo
    studies: how much of an estimate's error is bias and how much spread).

    Args:
        sim: a simulation.
        noise_seed: seed of the detection noise (an integer >= 0).
    """
    if int(noise_seed) < 0:
        raise ValueError(f"noise_seed: expected an integer >= 0, got {noise_seed}")
    frames, detection_truth = _observe_frames(sim.scenario, sim.truth, int(noise_seed))
    scene = dataclasses.replace(sim.scene, frames=frames)
    return dataclasses.replace(sim, scene=scene, detection_truth=detection_truth)


def _pick_presets(scenario: Scenario, rng: np.random.Generator, first_slot: int) -> list[str]:
    n, names = scenario.vehicles_per_frame, scenario.vehicles
    if scenario.vehicle_order == "random":
        return [names[i] for i in rng.integers(len(names), size=n)]
    return [names[(first_slot + k) % len(names)] for k in range(n)]


def _visible(scenario: Scenario, truth: VehicleTruth) -> bool:
    """Whether a vehicle meets ``scenario.require_visible``."""
    if scenario.require_visible == "none":
        return True
    world_p, cameras = truth.keypoints_world, scenario.required_cameras()
    if scenario.require_visible == "any":
        return any(keypoints_in_view(world_p, [camera], scenario.margin_px) for camera in cameras)
    return keypoints_in_view(world_p, cameras, scenario.margin_px)


def _collides(scenario: Scenario, truth: VehicleTruth, placed) -> str | None:
    """The id of a placed vehicle (id -> truth) closer than ``min_gap``, or None."""
    mine = footprint(truth.wireframe, truth.world_T_vehicle)
    for vid, other in placed.items():
        if footprints_overlap(mine, footprint(other.wireframe, other.world_T_vehicle), scenario.min_gap):
            return vid
    return None


def _fits(scenario: Scenario, truth: VehicleTruth, placed: list[VehicleTruth]) -> bool:
    if not _visible(scenario, truth):
        return False
    return _collides(scenario, truth, dict(enumerate(placed))) is None


def _place_frame(scenario: Scenario, rng: np.random.Generator, frame: int) -> dict[str, VehicleTruth]:
    """Independent vehicles of one frame."""
    vehicles: dict[str, VehicleTruth] = {}
    presets = _pick_presets(scenario, rng, first_slot=frame * scenario.vehicles_per_frame)
    (x0, x1), (y0, y1) = scenario.region
    for vid, name in zip(vehicle_ids(scenario.vehicles_per_frame), presets):
        wireframe, radius, name = draw_vehicle(name, rng, scenario.random_shape)
        for _ in range(_MAX_TRIES):
            pose = road_pose(rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(*scenario.yaw_range), radius)
            candidate = VehicleTruth(pose, wireframe, name, radius)
            if _fits(scenario, candidate, list(vehicles.values())):
                vehicles[vid] = candidate
                break
        else:
            raise _no_placement(scenario, vid)
    return vehicles


def _track_poses(x, y, yaw, speed, yaw_rate, radius, times) -> list[gtsam.Pose3]:
    """Constant speed and turn rate: the poses at ``times`` (s) relative to the pose ``(x, y, yaw)`` at time 0."""
    poses = []
    for tau in times:
        heading = yaw + yaw_rate * tau
        if abs(yaw_rate) > 1e-9:
            px = x + speed / yaw_rate * (math.sin(heading) - math.sin(yaw))
            py = y - speed / yaw_rate * (math.cos(heading) - math.cos(yaw))
        else:
            px, py = x + speed * tau * math.cos(yaw), y + speed * tau * math.sin(yaw)
        poses.append(road_pose(px, py, heading, radius))
    return poses


def _place_tracks(scenario: Scenario, rng: np.random.Generator, num_frames: int) -> list[dict[str, VehicleTruth]]:
    """Vehicles that keep their id and shape and move over the frames."""
    motion = scenario.motion
    times = (np.arange(num_frames) - (num_frames - 1) / 2.0) * scenario.dt
    presets = _pick_presets(scenario, rng, first_slot=0)
    (x0, x1), (y0, y1) = scenario.region
    frames: list[dict[str, VehicleTruth]] = [{} for _ in range(num_frames)]
    for vid, name in zip(vehicle_ids(scenario.vehicles_per_frame), presets):
        wireframe, radius, name = draw_vehicle(name, rng, scenario.random_shape)
        for _ in range(_MAX_TRIES):
            x, y, yaw = rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(*scenario.yaw_range)
            speed, yaw_rate = rng.uniform(*motion.speed), rng.uniform(*motion.yaw_rate)
            poses = _track_poses(x, y, yaw, speed, yaw_rate, radius, times)
            track = [VehicleTruth(pose, wireframe, name, radius, speed, yaw_rate, 0.0) for pose in poses]
            if all(_fits(scenario, v, list(frame.values())) for v, frame in zip(track, frames)):
                for v, frame in zip(track, frames):
                    frame[vid] = v
                break
        else:
            raise _no_placement(scenario, vid)
    return frames


def _place_routes(
    scenario: Scenario, rng: np.random.Generator, num_frames: int
) -> tuple[list[dict[str, VehicleTruth]], dict[str, Trajectory]]:
    """Vehicles driving routes; each exists in the frames where it is in the scene."""
    motion: RouteMotion = scenario.motion
    times = np.arange(num_frames) * scenario.dt
    presets = _pick_presets(scenario, rng, first_slot=0)
    frames: list[dict[str, VehicleTruth]] = [{} for _ in range(num_frames)]
    trajectories: dict[str, Trajectory] = {}
    span = (0.0, (scenario.num_frames - 1) * scenario.dt)
    for k, vid in enumerate(vehicle_ids(scenario.vehicles_per_frame)):
        explicit = k < len(motion.routes)
        spec = motion.routes[k] if explicit else RouteSpec()
        where = f"motion.routes[{k}]" if explicit else "motion"
        name = spec.vehicle or presets[k]
        wireframe, radius, name = draw_vehicle(name, rng, scenario.random_shape)
        tries = _ROUTE_TRIES if _has_draws(spec, motion) else 1
        problem = ""
        for _ in range(tries):
            draws = rng.random(_ROUTE_DRAWS)
            try:
                trajectory = _trajectory(spec, motion, draws, radius, span)
            except ValueError as exc:  # e.g. a stop behind a path's start
                raise ScenarioError(where, str(exc)) from None
            states = trajectory.states(times)
            track = {}
            for f in np.flatnonzero(states.exists):
                pose = road_pose(float(states.x[f]), float(states.y[f]), float(states.yaw[f]), radius)
                track[int(f)] = VehicleTruth(
                    pose, wireframe, name, radius,
                    float(states.speed[f]), float(states.yaw_rate[f]), float(states.acceleration[f]),
                )
            problem = _track_problem(scenario, track, frames, times)
            if problem is None:
                for f, v in track.items():
                    frames[f][vid] = v
                trajectories[vid] = dataclasses.replace(trajectory, info={**trajectory.info, "vehicle": name})
                break
        else:
            draws_note = f" after {tries} draws" if tries > 1 else ""
            if num_frames < scenario.num_frames:  # --frames shortened a scenario whose vehicles come in over its time
                problem += (f"; the scenario's routes span its {scenario.num_frames} frames: give at least that many "
                            "frames, or a scenario with fewer vehicles")
            raise ScenarioError(where, f"no route found for vehicle {vid}{draws_note}: {problem}")
    return frames, trajectories


def _has_draws(spec: RouteSpec, motion: RouteMotion) -> bool:
    """Whether a route leaves something to chance (so that another draw may succeed)."""
    common = (spec.speed, spec.decel, spec.accel)
    if spec.path is not None:
        waits_given = spec.wait is not None or all(w is not None for _, w in spec.stops)
        return any(v is None for v in common) or not waits_given
    if any(v is None for v in common + (spec.arm, spec.turn, spec.stop)):
        return True
    if spec.turn != "straight" and spec.radius is None:
        return True
    if spec.stop and (spec.wait is None or spec.stop_at is None):
        return True
    return spec.centre_time is None and spec.stop_time is None


def _pick(value, bounds, u: float) -> float:
    return float(value) if value is not None else float(bounds[0] + u * (bounds[1] - bounds[0]))


def _trajectory(spec: RouteSpec, motion: RouteMotion, u: np.ndarray, wheel_radius: float, span) -> Trajectory:
    """The trajectory of one route, with its missing fields drawn from ``u`` (uniform draws in [0, 1))."""
    speed = _pick(spec.speed, motion.speed, u[0])
    decel = _pick(spec.decel, motion.decel, u[1])
    accel = _pick(spec.accel, motion.accel, u[2])
    wait = _pick(spec.wait, motion.wait, u[3])
    common = {"speed": speed, "decel": decel, "accel": accel}
    if spec.path is not None:
        stops = tuple((s, wait if w is None else w) for s, w in spec.stops)
        start_time = 0.0 if spec.start_time is None else spec.start_time
        v0 = speed if spec.start_speed is None else min(spec.start_speed, speed)
        profile = drive_profile(speed, accel, decel, stops, s0=0.0, t0=start_time, v0=v0)
        info = {"kind": "path", **common, "stops": [list(s) for s in stops], "start_time": start_time,
                "start_speed": v0, "loop": spec.path.loop}
        return Trajectory(spec.path, profile, wheel_radius, start_time, motion.scene_radius, info)

    arm = spec.arm or motion.arms[min(int(u[4] * len(motion.arms)), len(motion.arms) - 1)]
    turn = spec.turn or motion.turns[min(int(u[5] * len(motion.turns)), len(motion.turns) - 1)]
    radius = _pick(spec.radius, motion.radius, u[6])
    if turn != "straight" and motion.turn_lateral_accel is not None and spec.speed is None:
        speed = min(speed, math.sqrt(motion.turn_lateral_accel * radius))  # traffic slows for a turn
        common["speed"] = speed
    stop = spec.stop if spec.stop is not None else bool(u[7] < motion.stop_probability)
    stop_at = _pick(spec.stop_at, motion.stop_at, u[8])
    route = intersection_path(arm, turn, radius, motion.lane_offset, stop_at)
    stop_s = route.stop_s - route.offset  # path arc lengths
    middle_s = route.middle_s - route.offset
    if stop:
        s0 = stop_s - speed * speed / (2.0 * decel) - 1.0
        profile = drive_profile(speed, accel, decel, [(stop_s, wait)], s0=s0)
    else:
        profile = drive_profile(speed, accel, decel, s0=0.0)
    if spec.centre_time is not None or not stop:
        anchor = _pick(spec.centre_time, motion.centre_time or span, u[9])
        profile = profile.shifted(anchor - profile.time_at(middle_s))
    else:
        anchor = _pick(spec.stop_time, motion.stop_time or span, u[9])
        profile = profile.shifted(anchor - profile.time_at(stop_s))
    info = {
        "kind": "intersection", "from": arm, "turn": turn, "radius": None if turn == "straight" else radius,
        **common, "stop": stop, "stop_at": stop_at if stop else None, "wait": wait if stop else None,
        "centre_time": profile.time_at(middle_s), "stop_time": profile.time_at(stop_s) if stop else None,
        "stop_point": [float(v) for v in route.path.at(stop_s)[:2]] if stop else None,
        "lane_offset": motion.lane_offset,
    }
    return Trajectory(route.path, profile, wheel_radius, None, motion.scene_radius, info)


def _track_problem(scenario: Scenario, track: dict[int, VehicleTruth], frames, times) -> str | None:
    """Why a vehicle's track does not fit (None when it does)."""
    if not track:
        return "it is never in the scene during the frames (see motion.scene_radius and the times)"
    for f, truth in track.items():
        if not _visible(scenario, truth):
            need = "all" if scenario.require_visible == "all" else "at least one"
            return (
                f"at t = {times[f]:g} s it is not inside the images of {need} of {list(scenario.visible_in)} "
                f"({scenario.margin_px:g} px margin; require_visible = {scenario.require_visible!r})"
            )
        other = _collides(scenario, truth, frames[f])
        if other is not None:
            return f"at t = {times[f]:g} s it comes closer than min_gap = {scenario.min_gap:g} m to {other}"
    return None


def _observe_frames(scenario: Scenario, truth: list[dict[str, VehicleTruth]], seed: int):
    """Every frame's detections and their labels; frame ``f`` draws its noise from ``[seed, _NOISE, f]``."""
    frames, detection_truth = [], []
    for f, vehicles in enumerate(truth):
        frame, labels = _observe(scenario, vehicles, np.random.default_rng([seed, _NOISE, f]), t=f * scenario.dt)
        frames.append(frame)
        detection_truth.append(labels)
    return frames, detection_truth


def _observe(
    scenario: Scenario, vehicles: dict[str, VehicleTruth], rng: np.random.Generator, t: float
) -> tuple[Frame, dict[tuple[str, str], DetectionTruth]]:
    """Detections of one frame: every camera looks at every vehicle."""
    bodies = {
        vid: VehicleBody.from_vehicle(v.wireframe, v.world_T_vehicle, v.wheel_radius) for vid, v in vehicles.items()
    }
    detections, labels = [], {}
    for vid, vehicle in vehicles.items():
        others = [b for other, b in bodies.items() if other != vid]
        world_p = vehicle.seen_keypoints_world
        for camera in scenario.cameras.values():
            uv, depth = camera.project(world_p)
            occluded = occluded_keypoints(camera.center, bodies[vid], others)
            noisy = corrupt_keypoints(uv, occluded, scenario.noise, rng, camera.image_size, in_front=depth > 0)
            if noisy.missing.all():
                continue
            detections.append(Detection(camera.name, vid, noisy.keypoints, noisy.confidence))
            uv_true = np.where((depth > 0)[:, None], uv, np.nan)
            labels[(camera.name, vid)] = DetectionTruth(
                uv_true, occluded, noisy.sigma_px, noisy.outlier, noisy.swapped, noisy.missing
            )
    return Frame(t=float(t), detections=detections), labels


def _no_placement(scenario: Scenario, vid: str) -> ScenarioError:
    what = "track" if scenario.motion is not None else "position"
    return ScenarioError(
        "region",
        f"no {what} found for vehicle {vid} after {_MAX_TRIES} draws with all keypoints "
        f"{scenario.margin_px:g} px inside the images of {list(scenario.visible_in)}"
        + (f" and {scenario.min_gap:g} m from the other vehicles" if scenario.vehicles_per_frame > 1 else "")
        + ": enlarge the region or the cameras' view, or lower vehicles_per_frame / margin_px",
    )
