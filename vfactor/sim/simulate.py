"""Simulated scenes: vehicles placed on the road, seen by a camera rig through a noisy detector.

:func:`simulate` turns a :class:`~vfactor.sim.scenario.Scenario` into a
:class:`vfactor.observations.Scene` (what the solvers read) and the ground
truth (what the metrics compare against). Everything random comes from
generators seeded by ``(seed, stream, frame)``, so the same seed gives the same
scene; with independent frames (no motion), frame ``f`` does not depend on how
many frames follow it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import gtsam
import numpy as np

from vfactor.camera import Camera
from vfactor.errors import ScenarioError
from vfactor.observations import Detection, Frame, Scene
from vfactor.sim.noise import corrupt_keypoints
from vfactor.sim.scenario import Scenario, load_scenario
from vfactor.sim.vehicles import footprint, footprints_overlap, road_pose, vehicle_shape
from vfactor.sim.visibility import VehicleBody, occluded_keypoints
from vfactor.wireframe import Wireframe

__all__ = ["VehicleTruth", "DetectionTruth", "Simulation", "simulate", "vehicle_ids", "keypoints_in_view"]

# Random streams: (seed, stream, ...) seeds one generator each.
_PLACE, _NOISE, _TRACKS = 0, 1, 2
_MAX_TRIES = 2000


@dataclass(frozen=True)
class VehicleTruth:
    """The true state of one vehicle in one frame.

    Attributes:
        world_T_vehicle: body -> world pose.
        wireframe: body-frame keypoints, metres.
        preset: preset name, or ``"random"``.
        wheel_radius: hub height above the road, metres.
    """

    world_T_vehicle: gtsam.Pose3
    wireframe: Wireframe
    preset: str
    wheel_radius: float = 0.33

    @property
    def keypoints_world(self) -> np.ndarray:
        """(12, 3) keypoints in the world frame, metres."""
        return self.wireframe.in_world(self.world_T_vehicle)

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
    """

    scenario: Scenario
    seed: int
    scene: Scene
    truth: list[dict[str, VehicleTruth]]
    detection_truth: list[dict[tuple[str, str], DetectionTruth]] = field(default_factory=list)

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
    ``t = f * dt`` holds new vehicles ``v1``, ``v2``, ...). With it, each id is
    one vehicle moving at constant speed and yaw rate, its position at the
    middle frame drawn in the region.

    Args:
        scenario: a :class:`Scenario`, or a packaged scenario name or file path.
        seed: overrides ``scenario.seed`` (an integer >= 0).
        num_frames: overrides ``scenario.num_frames``.

    Returns:
        :class:`Simulation`.

    Raises:
        ScenarioError: no placement found (the region is not seen by the required cameras, or too crowded).
    """
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    seed = scenario.seed if seed is None else int(seed)
    if seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, got {seed}")
    num_frames = scenario.num_frames if num_frames is None else int(num_frames)
    if num_frames < 1:
        raise ValueError(f"num_frames: expected >= 1, got {num_frames}")

    if scenario.motion is None:
        truth = [_place_frame(scenario, np.random.default_rng([seed, _PLACE, f]), f) for f in range(num_frames)]
    else:
        truth = _place_tracks(scenario, np.random.default_rng([seed, _TRACKS]), num_frames)

    frames, detection_truth = [], []
    for f, vehicles in enumerate(truth):
        rng = np.random.default_rng([seed, _NOISE, f])
        frame, labels = _observe(scenario, vehicles, rng, t=f * scenario.dt)
        frames.append(frame)
        detection_truth.append(labels)
    scene = Scene(cameras=dict(scenario.cameras), frames=frames, base_dir=None)
    return Simulation(scenario=scenario, seed=seed, scene=scene, truth=truth, detection_truth=detection_truth)


def _pick_presets(scenario: Scenario, rng: np.random.Generator, first_slot: int) -> list[str]:
    n, names = scenario.vehicles_per_frame, scenario.vehicles
    if scenario.vehicle_order == "random":
        return [names[i] for i in rng.integers(len(names), size=n)]
    return [names[(first_slot + k) % len(names)] for k in range(n)]


def _fits(scenario: Scenario, truth: VehicleTruth, placed: list[VehicleTruth]) -> bool:
    if not keypoints_in_view(truth.keypoints_world, scenario.required_cameras(), scenario.margin_px):
        return False
    mine = footprint(truth.wireframe, truth.world_T_vehicle)
    return not any(
        footprints_overlap(mine, footprint(o.wireframe, o.world_T_vehicle), scenario.min_gap) for o in placed
    )


def _place_frame(scenario: Scenario, rng: np.random.Generator, frame: int) -> dict[str, VehicleTruth]:
    """Independent vehicles of one frame."""
    vehicles: dict[str, VehicleTruth] = {}
    presets = _pick_presets(scenario, rng, first_slot=frame * scenario.vehicles_per_frame)
    (x0, x1), (y0, y1) = scenario.region
    for vid, name in zip(vehicle_ids(scenario.vehicles_per_frame), presets):
        wireframe, radius = vehicle_shape(name, rng, scenario.random_shape)
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
        wireframe, radius = vehicle_shape(name, rng, scenario.random_shape)
        for _ in range(_MAX_TRIES):
            poses = _track_poses(
                rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(*scenario.yaw_range),
                rng.uniform(*motion.speed), rng.uniform(*motion.yaw_rate), radius, times,
            )
            track = [VehicleTruth(pose, wireframe, name, radius) for pose in poses]
            if all(_fits(scenario, v, list(frame.values())) for v, frame in zip(track, frames)):
                for v, frame in zip(track, frames):
                    frame[vid] = v
                break
        else:
            raise _no_placement(scenario, vid)
    return frames


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
        world_p = vehicle.keypoints_world
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
