"""Ground-truth files of simulations (JSON), laid out like the result file.

```json
{"scenario": "intersection_2cam", "seed": 0,
 "frames": [
   {"t": 0.0,
    "vehicles": [
      {"id": "v1", "preset": "lincoln_mkz", "wheel_radius": 0.34,
       "world_T_vehicle": [[...4x4...]],
       "keypoints_world": [[x, y, z], "... 12 rows ..."],
       "keypoints_vehicle": [[x, y, z], "... 12 rows ..."],
       "speed": 8.1, "yaw_rate": 0.0, "acceleration": 0.0}]}]}
```

``speed`` (m/s along body x), ``yaw_rate`` (rad/s) and ``acceleration``
(m/s^2, longitudinal) are written for moving vehicles only (scenarios with
``motion``), ``body_roll`` and ``body_pitch`` (radians, the body on its suspension against the hubs' frame)
where the scenario has ``body_motion``. ``keypoints_world`` (the rigid vehicle's) is redundant (``world_T_vehicle`` applied to
``keypoints_vehicle``) and is written for readers that only want the points;
:func:`load_truth` rebuilds the truth from the pose and the body keypoints.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from vfactor.camera import as_pose3, check_rigid_transform
from vfactor.errors import CalibrationError, SceneError
from vfactor.jsonio import read_json, write_text_atomic
from vfactor.sim.simulate import Simulation, VehicleTruth
from vfactor.wireframe import Wireframe

__all__ = ["truth_to_dict", "truth_from_dict", "save_truth", "load_truth", "write_simulation"]

# Optional per-vehicle motion state (written for moving vehicles only).
_MOTION_KEYS = ("speed", "yaw_rate", "acceleration", "body_roll", "body_pitch")


def truth_to_dict(sim: Simulation) -> dict:
    """The ground truth of a simulation as a JSON-ready dict (see the module docstring)."""
    frames = []
    for frame, vehicles in zip(sim.scene.frames, sim.truth):
        entries = []
        for vid, v in vehicles.items():
            entries.append(
                {
                    "id": vid,
                    "preset": v.preset,
                    "wheel_radius": float(v.wheel_radius),
                    "world_T_vehicle": v.world_T_vehicle.matrix().tolist(),
                    "keypoints_world": v.keypoints_world.tolist(),
                    "keypoints_vehicle": v.keypoints_vehicle.tolist(),
                }
            )
            for key in _MOTION_KEYS:
                value = getattr(v, key)
                if value is not None:
                    entries[-1][key] = float(value)
        frames.append({"t": float(frame.t), "vehicles": entries})
    return {"scenario": sim.scenario.name, "seed": int(sim.seed), "frames": frames}


def truth_from_dict(data: dict) -> list[dict[str, VehicleTruth]]:
    """Per frame, vehicle id -> :class:`VehicleTruth`, from :func:`truth_to_dict`'s layout.

    Raises:
        SceneError: a missing or malformed field (named by its path).
    """
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise SceneError("frames", "expected an object with a list of frames")
    out = []
    for f, frame in enumerate(data["frames"]):
        where = f"frames[{f}]"
        if not isinstance(frame, dict) or not isinstance(frame.get("vehicles"), list):
            raise SceneError(f"{where}.vehicles", "expected a list of vehicles")
        vehicles = {}
        for k, entry in enumerate(frame["vehicles"]):
            at = f"{where}.vehicles[{k}]"
            if not isinstance(entry, dict):
                raise SceneError(at, "expected an object")
            for key in ("id", "world_T_vehicle", "keypoints_vehicle"):
                if key not in entry:
                    raise SceneError(f"{at}.{key}", "missing")
            vid = entry["id"]
            if not isinstance(vid, str) or not vid:
                raise SceneError(f"{at}.id", f"expected a non-empty string, got {vid!r}")
            if vid in vehicles:
                raise SceneError(f"{at}.id", f"duplicate vehicle id {vid!r}")
            try:
                T = check_rigid_transform(entry["world_T_vehicle"], f"{at}.world_T_vehicle")
            except CalibrationError as exc:
                raise SceneError(exc.field, exc.problem) from None
            try:
                wireframe = Wireframe(np.asarray(entry["keypoints_vehicle"], dtype=float))
            except (TypeError, ValueError) as exc:
                raise SceneError(f"{at}.keypoints_vehicle", f"expected 12 rows of 3 finite numbers ({exc})") from None
            radius = entry.get("wheel_radius", 0.33)
            if not isinstance(radius, (int, float)) or isinstance(radius, bool) or not radius > 0:
                raise SceneError(f"{at}.wheel_radius", f"expected a positive number, got {radius!r}")
            preset = entry.get("preset", "")
            if not isinstance(preset, str):
                raise SceneError(f"{at}.preset", f"expected a string, got {preset!r}")
            motion = {}
            for key in _MOTION_KEYS:
                value = entry.get(key)
                if value is None:
                    continue
                if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value):
                    raise SceneError(f"{at}.{key}", f"expected a finite number, got {value!r}")
                motion[key] = float(value)
            vehicles[vid] = VehicleTruth(as_pose3(T), wireframe, preset, float(radius), **motion)
        out.append(vehicles)
    return out


def save_truth(sim: Simulation, path: str | Path) -> None:
    """Writes the ground truth of a simulation as JSON."""
    write_text_atomic(path, json.dumps(truth_to_dict(sim), indent=1) + "\n")


def load_truth(path: str | Path) -> list[dict[str, VehicleTruth]]:
    """Reads a ground-truth file: per frame, vehicle id -> :class:`VehicleTruth`.

    Raises:
        SceneError: the file is missing, not JSON, or malformed (the field is named).
    """
    return truth_from_dict(read_json(path, SceneError))  # vfactor.jsonio: the one reader of user JSON


def write_simulation(sim: Simulation, scene_path: str | Path, truth_path: str | Path) -> None:
    """Writes the scene file (with :func:`vfactor.scene.save_scene`) and the ground-truth file."""
    from vfactor.scene import save_scene

    save_scene(sim.scene, scene_path)
    save_truth(sim, truth_path)
