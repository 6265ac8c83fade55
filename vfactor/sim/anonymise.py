"""Simulated scenes as an association sees them: no vehicle ids, per-camera tracks, misses and false detections.

:func:`anonymise` turns a :class:`~vfactor.sim.simulate.Simulation` into the input of
:mod:`vfactor.association`: every detection's vehicle becomes
:data:`~vfactor.observations.UNASSIGNED`; each camera's detections carry the
track ids a per-camera 2D tracker would give them (:attr:`Detection.track`);
some detections are dropped, some false ones (a vehicle that is not there) are
added, and each frame's detections are shuffled so that their order says
nothing about identity. :attr:`AnonymousScene.truth_ids` keeps the answer.

Per-camera tracks, camera by camera:

- a vehicle *is in a camera's view* in frame ``f`` when the simulation has a
  detection of it in that camera (at least one keypoint seen);
- when it comes into the view (frame 0, or after a frame out of it), it gets a
  new track id: the camera's next number (``"1"``, ``"2"``, ...; each camera
  counts on its own, so the same string in two cameras means nothing), the
  vehicles that come in together numbered in random order;
- the id stays while the vehicle stays in the view, also through frames whose
  detection :func:`anonymise` drops as missed (the tracker coasts);
- in each frame, with probability ``track_switch_rate``, the camera's tracker
  swaps the ids of two of the vehicles it already tracked in the previous frame
  (an identity switch): one drawn uniformly, and the one whose keypoint centre
  lies nearest to it in the image; each keeps the other's id from then on;
- a false detection is a track of its own, one frame long (a new number).

Randomness: generators seeded by ``(seed, stream, frame)``, one stream per
purpose (switches, misses, false detections, numbering and shuffling), with the
same number of draws whatever the rates (except the false detections', which
depend on their number), so the same arguments give the same scene.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vfactor.errors import SceneError
from vfactor.jsonio import read_json, write_text_atomic
from vfactor.observations import UNASSIGNED, Detection, Frame, Scene
from vfactor.sim.noise import corrupt_keypoints
from vfactor.sim.simulate import Simulation
from vfactor.sim.vehicles import LIBRARY, draw_vehicle, footprint, footprints_overlap, road_pose
from vfactor.sim.visibility import VehicleBody, occluded_keypoints

__all__ = ["AnonymousScene", "TrackSwitch", "FALSE_ROAD_HALF_WIDTH", "FALSE_MIN_SEEN", "anonymise",
           "write_anonymised", "load_truth_ids"]

#: False detections stand within this distance of a road axis (world x or y), metres.
FALSE_ROAD_HALF_WIDTH = 7.0
#: A false detection shows at least this many keypoints (of 12).
FALSE_MIN_SEEN = 6
_FALSE_RADIUS = 25.0  # metres from the centre when the scenario gives no scene_radius
_FALSE_TRIES = 100
_FALSE_YAW_SIGMA = math.radians(10.0)

# Random streams: (seed, stream, frame) seeds one generator each.
_SWITCH, _MISS, _FALSE, _ORDER = 0, 1, 2, 3


@dataclass(frozen=True)
class TrackSwitch:
    """One identity switch of a camera's tracker: from ``frame`` on, the two vehicles carry each other's track id.

    Attributes:
        frame: frame index.
        camera: camera name.
        vehicles: the two true vehicle ids whose track ids were swapped.
    """

    frame: int
    camera: str
    vehicles: tuple[str, str]


@dataclass
class AnonymousScene:
    """A simulated scene without vehicle ids, and the answer.

    Attributes:
        scene: the scene: the simulation's cameras and frames, every detection's
            ``vehicle`` :data:`~vfactor.observations.UNASSIGNED`, ``track`` its
            per-camera track id (None everywhere with ``keep_tracks=False``),
            each frame's detections shuffled.
        truth_ids: per frame, one entry per detection of that frame (in the
            scene's order): the true vehicle id, or None for a false detection.
        switches: the identity switches of the cameras' trackers, in frame order.
        missed: ``(frame, camera, vehicle)`` of each simulated detection dropped as missed.
        settings: the arguments of :func:`anonymise` (seed, rates, keep_tracks).
    """

    scene: Scene
    truth_ids: list[list[str | None]]
    switches: list[TrackSwitch] = field(default_factory=list)
    missed: list[tuple[int, str, str]] = field(default_factory=list)
    settings: dict = field(default_factory=dict)

    def track_truth(self) -> list[list[tuple[str, str | None, str | None]]]:
        """Per frame, per detection: ``(camera, track, true vehicle id or None)``."""
        return [[(d.camera, d.track, vid) for d, vid in zip(frame.detections, ids)]
                for frame, ids in zip(self.scene.frames, self.truth_ids)]


def anonymise(
    sim: Simulation,
    seed: int = 0,
    track_switch_rate: float = 0.0,
    false_rate: float = 0.0,
    miss_rate: float = 0.0,
    keep_tracks: bool = True,
) -> AnonymousScene:
    """The simulation's scene as an association must solve it (see the module docstring).

    Args:
        sim: a simulation (its detections carry the true vehicle ids).
        seed: seed of the anonymiser's draws (an integer >= 0), independent of ``sim.seed``.
        track_switch_rate: probability, per camera per frame, that the camera's tracker swaps the
            track ids of two vehicles it tracked in the previous frame (when it tracks at least two).
        false_rate: mean number of false detections per camera per frame (Poisson): a library vehicle
            at a random pose on the roads (within :data:`FALSE_ROAD_HALF_WIDTH` of a road axis and the
            scenario's ``motion.scene_radius``, else 25 m, of the centre, heading along the road within
            about 10 degrees, clear of the real vehicles' footprints) projected into that camera only,
            hidden where the real vehicles or its own body hide it, with the scenario's keypoint noise;
            drawn again until :data:`FALSE_MIN_SEEN` keypoints are seen.
        miss_rate: probability that a simulated detection is dropped (the vehicle keeps its track).
        keep_tracks: False: ``track`` is None on every detection (association across cameras and
            frames from geometry alone).

    Returns:
        :class:`AnonymousScene`.

    Raises:
        ValueError: a rate outside its range, or a negative seed.
    """
    seed = int(seed)
    if seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, got {seed}")
    for name, value in (("track_switch_rate", track_switch_rate), ("miss_rate", miss_rate)):
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"{name}: expected a probability in [0, 1], got {value}")
    if not 0.0 <= false_rate <= 100.0:
        raise ValueError(f"false_rate: expected a mean number per camera per frame in [0, 100], got {false_rate}")

    cameras = sim.scene.cameras
    current: dict[str, dict[str, str]] = {c: {} for c in cameras}  # camera -> vehicle -> track id
    counter = {c: 0 for c in cameras}
    frames, truth_ids, switches, missed = [], [], [], []
    for f, frame in enumerate(sim.scene.frames):
        rng_switch, rng_miss, rng_false, rng_order = (
            np.random.default_rng([seed, stream, f]) for stream in (_SWITCH, _MISS, _FALSE, _ORDER))
        in_view: dict[str, dict[str, Detection]] = {c: {} for c in cameras}
        for det in frame.detections:
            in_view[det.camera][det.vehicle] = det

        def new_track(camera: str) -> str:
            counter[camera] += 1
            return str(counter[camera])

        for camera in cameras:
            tracks = current[camera]
            for vid in [v for v in tracks if v not in in_view[camera]]:
                del tracks[vid]  # left the view: the track ends
            continuing = sorted(tracks)
            arriving = [v for v in sorted(in_view[camera]) if v not in tracks]
            for i in rng_order.permutation(len(arriving)):
                tracks[arriving[i]] = new_track(camera)
            u_switch, u_pick = rng_switch.random(2)
            if len(continuing) >= 2 and u_switch < track_switch_rate:
                a = continuing[min(int(u_pick * len(continuing)), len(continuing) - 1)]
                b = _nearest(a, continuing, in_view[camera])
                tracks[a], tracks[b] = tracks[b], tracks[a]
                switches.append(TrackSwitch(f, camera, (a, b)))

        detections: list[Detection] = []
        ids: list[str | None] = []
        u_miss = rng_miss.random(len(frame.detections))
        for det, u in zip(frame.detections, u_miss):
            if u < miss_rate:
                missed.append((f, det.camera, det.vehicle))
                continue
            detections.append(_anonymous(det, current[det.camera][det.vehicle] if keep_tracks else None))
            ids.append(det.vehicle)

        if false_rate > 0.0:
            bodies = None
            for camera in cameras:
                for _ in range(int(rng_false.poisson(false_rate))):
                    if bodies is None:
                        bodies = [VehicleBody.from_vehicle(v.wireframe, v.world_T_vehicle, v.wheel_radius)
                                  for v in sim.truth[f].values()]
                    det = _false_detection(sim, f, cameras[camera], bodies, rng_false)
                    if det is not None:
                        detections.append(dataclasses.replace(det, track=new_track(camera) if keep_tracks else None))
                        ids.append(None)

        order = rng_order.permutation(len(detections))
        frames.append(Frame(t=frame.t, detections=[detections[i] for i in order],
                            images=None if frame.images is None else dict(frame.images)))
        truth_ids.append([ids[i] for i in order])

    scene = dataclasses.replace(sim.scene, cameras=dict(sim.scene.cameras), frames=frames)
    settings = {"seed": seed, "track_switch_rate": float(track_switch_rate), "false_rate": float(false_rate),
                "miss_rate": float(miss_rate), "keep_tracks": bool(keep_tracks)}
    return AnonymousScene(scene, truth_ids, switches, missed, settings)


def _anonymous(det: Detection, track: str | None) -> Detection:
    """A copy of a detection without its vehicle id, with a track id."""
    return dataclasses.replace(det, vehicle=UNASSIGNED, track=track, keypoints=np.array(det.keypoints),
                               confidence=np.array(det.confidence))


def _centre(det: Detection) -> np.ndarray:
    """Mean pixel of a detection's seen keypoints."""
    return det.keypoints[det.seen].mean(axis=0)


def _nearest(vehicle: str, candidates: list[str], detections: dict[str, Detection]) -> str:
    """The candidate (other than ``vehicle``) whose keypoint centre is nearest to ``vehicle``'s in the image."""
    here = _centre(detections[vehicle])
    others = [v for v in candidates if v != vehicle]
    distances = [float(np.linalg.norm(_centre(detections[v]) - here)) for v in others]
    return others[int(np.argmin(distances))]


def _false_detection(sim: Simulation, f: int, camera, bodies, rng: np.random.Generator) -> Detection | None:
    """The detection, in one camera, of a library vehicle that is not there (None if no pose fits)."""
    scenario = sim.scenario
    radius_m = getattr(scenario.motion, "scene_radius", None) or _FALSE_RADIUS
    wireframe, wheel_radius, _ = draw_vehicle(LIBRARY, rng, scenario.random_shape)
    real = [footprint(v.wireframe, v.world_T_vehicle) for v in sim.truth[f].values()]
    for _ in range(_FALSE_TRIES):
        along = rng.uniform(-radius_m, radius_m)
        across = rng.uniform(-FALSE_ROAD_HALF_WIDTH, FALSE_ROAD_HALF_WIDTH)
        axis, direction = int(rng.integers(2)), int(rng.integers(2))
        yaw = axis * 0.5 * math.pi + direction * math.pi + rng.normal(0.0, _FALSE_YAW_SIGMA)
        x, y = (along, across) if axis == 0 else (across, along)
        pose = road_pose(x, y, yaw, wheel_radius)
        mine = footprint(wireframe, pose)
        if any(footprints_overlap(mine, other) for other in real):
            continue
        world_p = wireframe.in_world(pose)
        uv, depth = camera.project(world_p)
        if np.any(depth <= 0.1) or camera.in_image(uv).sum() < FALSE_MIN_SEEN:
            continue
        body = VehicleBody.from_vehicle(wireframe, pose, wheel_radius)
        occluded = occluded_keypoints(camera.center, body, bodies)
        noisy = corrupt_keypoints(uv, occluded, scenario.noise, rng, camera.image_size, in_front=depth > 0)
        if int((~noisy.missing).sum()) >= FALSE_MIN_SEEN:
            return Detection(camera.name, UNASSIGNED, noisy.keypoints, noisy.confidence)
    return None


def write_anonymised(anon: AnonymousScene, scene_path: str | Path, truth_ids_path: str | Path) -> None:
    """Writes the anonymised scene file (:func:`vfactor.scene.save_scene`: detections without ``vehicle``,
    with ``track``) and its truth ids as JSON.

    The truth-ids file::

        {"anonymise": {"seed": 0, "track_switch_rate": 0.02, ...},
         "frames": [{"t": 0.0, "truth_ids": ["v3", null, "v1", ...]}, ...]}

    ``truth_ids`` lines up with the frame's ``detections`` in the scene file (null: a false detection).
    A frame without ``track`` ids whose detections are each of another camera loads back with one named
    vehicle (docs/scene-format.md), so write such scenes with ``keep_tracks=True``.
    """
    from vfactor.scene import save_scene

    save_scene(anon.scene, scene_path)
    data = {"anonymise": anon.settings,
            "frames": [{"t": float(frame.t), "truth_ids": ids} for frame, ids in zip(anon.scene.frames, anon.truth_ids)]}
    write_text_atomic(truth_ids_path, json.dumps(data, indent=1) + "\n")


def load_truth_ids(path: str | Path) -> list[list[str | None]]:
    """Reads a truth-ids file of :func:`write_anonymised`: per frame, the true vehicle id of each detection.

    Raises:
        SceneError: the file is missing, not JSON, or malformed (the field is named).
    """
    data = read_json(path, SceneError)
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise SceneError("frames", "expected an object with a list of frames")
    out = []
    for f, frame in enumerate(data["frames"]):
        ids = frame.get("truth_ids") if isinstance(frame, dict) else None
        if not isinstance(ids, list) or not all(v is None or (isinstance(v, str) and v) for v in ids):
            raise SceneError(f"frames[{f}].truth_ids", "expected a list of vehicle ids (strings) or null")
        out.append(list(ids))
    return out
