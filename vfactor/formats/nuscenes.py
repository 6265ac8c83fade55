"""nuScenes detection results JSON (the devkit's ``submission`` / ``sample_result`` form).

::

    {"meta": {"use_camera": true, "use_lidar": false, "use_radar": false, "use_map": false, "use_external": false},
     "results": {sample_token: [sample_result, ...], ...}}

One sample per result frame; ``sample_token`` is the frame's index as six
digits (``"000000"``, like the KITTI file names) unless the caller gives one
token per frame (e.g. the nuScenes sample tokens of the frames). Every frame
has an entry, an empty list when it has no solved vehicle. Each
``sample_result``:

* ``translation``: the box centre in the world ("global") frame, m;
* ``size``: ``[width, length, height]``, m (nuScenes' order);
* ``rotation``: the box's full rotation (box -> world, roll and pitch kept),
  quaternion ``[w, x, y, z]`` with w >= 0 (pyquaternion's order); the
  devkit's evaluation uses only its yaw;
* ``velocity``: ``[vx, vy]`` in the world frame, m/s, from the box centres
  of the same vehicle id in the neighbouring solved frames in time (a central
  difference, one-sided at the ends of its run of frames); ``[0.0, 0.0]``
  when the id is solved in a single frame (velocity unknown);
* ``detection_name``: ``car`` or ``truck`` by :data:`NUSCENES_NAMES`
  (nuScenes files vans and SUVs as cars, pick-ups as trucks);
* ``detection_score``: the probability of that class under the body-type
  posterior (1.0 for a vehicle solved with one prior);
* ``attribute_name``: ``vehicle.moving`` when the speed exceeds
  ``moving_speed`` (0.5 m/s), ``vehicle.stopped`` otherwise, ``""`` when
  the velocity is unknown (vfactor cannot tell ``vehicle.parked``).

Unsolved vehicles have no box and are left out (:attr:`WriteReport.skipped`).
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from vfactor.errors import InputError
from vfactor.formats.common import (
    ReadBox,
    WriteReport,
    box_from_centre,
    check_output_path,
    check_results,
    class_probabilities,
    number,
    quaternion_wxyz,
    rotation_from_wxyz,
    solved_box,
    unsolved_of,
)
from vfactor.jsonio import read_json, write_text_atomic
from vfactor.observations import Scene
from vfactor.result import FrameResult

__all__ = ["NUSCENES_NAMES", "NUSCENES_DEFAULT_NAME", "MOVING_SPEED", "DEFAULT_META", "box_velocities",
           "nuscenes_dict", "write_nuscenes", "read_nuscenes"]

#: vfactor body type -> nuScenes detection class (docs/instructions_nuscenes.md of the devkit: "vehicle.car:
#: sedans, hatch-backs, wagons, vans, mini-vans, SUVs"; "vehicle.truck: ... including pick-ups"; "vehicle.bus.rigid",
#: the detection class ``bus``).
NUSCENES_NAMES = {"sedan": "car", "hatchback": "car", "estate": "car", "suv": "car", "van": "car", "pickup": "truck",
                  "bus": "bus"}
#: Class of a vehicle without a body type or with one the map lacks.
NUSCENES_DEFAULT_NAME = "car"
#: Speed above which a vehicle is ``vehicle.moving`` (m/s).
MOVING_SPEED = 0.5
#: The ``meta`` written unless the caller gives one: cameras only.
DEFAULT_META = {"use_camera": True, "use_lidar": False, "use_radar": False, "use_map": False, "use_external": False}
_DETECTION_NAMES = ("car", "truck", "bus", "trailer", "construction_vehicle", "pedestrian", "motorcycle", "bicycle",
                    "traffic_cone", "barrier")


def box_velocities(results: list[FrameResult]) -> dict[tuple[int, str], np.ndarray | None]:
    """(vx, vy) of each solved box in the world frame (m/s), keyed by (frame index, id); None when unknown.

    For each id, its solved frames sorted by ``t``: the central difference of
    the box centres between the frames before and after (in time), one-sided
    at the ends; None when it is solved at a single time.
    """
    runs: dict[str, list[tuple[float, int, np.ndarray]]] = {}
    for i, frame in enumerate(results):
        for v in frame.vehicles:
            box = solved_box(v)
            if box is not None:
                runs.setdefault(v.id, []).append((float(frame.t), i, np.asarray(box.world_T_box.translation())[:2]))
    out: dict[tuple[int, str], np.ndarray | None] = {}
    for vid, run in runs.items():
        run.sort(key=lambda r: (r[0], r[1]))
        times = [r[0] for r in run]
        for k, (t, i, _) in enumerate(run):
            before = [j for j in range(k) if times[j] < t]
            after = [j for j in range(k + 1, len(run)) if times[j] > t]
            a = before[-1] if before else k
            b = after[0] if after else k
            if times[b] > times[a]:
                out[(i, vid)] = (run[b][2] - run[a][2]) / (times[b] - times[a])
            else:
                out[(i, vid)] = None
    return out


def nuscenes_dict(results: list[FrameResult], sample_tokens: list[str] | None = None, meta: dict | None = None,
                  names: dict[str, str] | None = None, moving_speed: float = MOVING_SPEED) -> dict:
    """The results as a nuScenes detection submission dictionary (module docstring).

    Args:
        results: the frames' results.
        sample_tokens: one token per frame (default: the frame index as six digits).
        meta: the ``meta`` object (default :data:`DEFAULT_META`); five booleans.
        names: body type -> detection class (default :data:`NUSCENES_NAMES`).
        moving_speed: speed above which a vehicle is ``vehicle.moving`` (m/s).

    Raises:
        InputError: a bad argument (tokens not one unique string per frame, meta not the five booleans,
            an unknown detection class, a negative speed).
    """
    check_results(results, None, False, "nuScenes")
    if sample_tokens is None:
        tokens = [f"{i:06d}" for i in range(len(results))]
    else:
        tokens = list(sample_tokens) if isinstance(sample_tokens, (list, tuple)) else None
        if (tokens is None or len(tokens) != len(results) or not all(isinstance(t, str) and t for t in tokens)
                or len(set(tokens)) != len(tokens)):
            raise InputError("sample_tokens", f"expected {len(results)} distinct non-empty strings, one per frame")
    meta = dict(DEFAULT_META if meta is None else meta)
    if set(meta) != set(DEFAULT_META) or not all(isinstance(v, bool) for v in meta.values()):
        raise InputError("meta", f"expected the booleans {sorted(DEFAULT_META)}, got {meta!r}")
    mapping = NUSCENES_NAMES if names is None else names
    if not isinstance(mapping, dict) or any(n not in _DETECTION_NAMES for n in mapping.values()):
        raise InputError("names", f"expected a dict body type -> one of {list(_DETECTION_NAMES)}")
    if not (isinstance(moving_speed, (int, float)) and math.isfinite(moving_speed) and moving_speed >= 0):
        raise InputError("moving_speed", f"expected a non-negative number (m/s), got {moving_speed!r}")
    velocities = box_velocities(results)
    out = {}
    for i, (token, frame) in enumerate(zip(tokens, results)):
        entries = []
        for v in frame.vehicles:
            box = solved_box(v)
            if box is None:
                continue
            T = np.asarray(box.world_T_box.matrix(), dtype=float)
            length, width, height = (float(s) for s in box.size)
            velocity = velocities.get((i, v.id))
            name, score = class_probabilities(v, mapping, NUSCENES_DEFAULT_NAME)
            if velocity is None:
                attribute, velocity = "", np.zeros(2)
            else:
                attribute = "vehicle.moving" if float(np.hypot(*velocity)) > moving_speed else "vehicle.stopped"
            entries.append({"sample_token": token, "translation": [number(x) for x in T[:3, 3]],
                            "size": [number(width), number(length), number(height)],
                            "rotation": [number(x, 9) for x in quaternion_wxyz(T[:3, :3])],
                            "velocity": [number(x) for x in velocity], "detection_name": name,
                            "detection_score": number(score), "attribute_name": attribute})
        out[token] = entries
    return {"meta": meta, "results": out}


def write_nuscenes(path: str | os.PathLike, results: list[FrameResult], scene: Scene | None = None,
                   sample_tokens: list[str] | None = None, meta: dict | None = None, names: dict[str, str] | None = None,
                   moving_speed: float = MOVING_SPEED) -> WriteReport:
    """Writes the results as one nuScenes detection results JSON file, atomically (:func:`nuscenes_dict`).

    ``scene``, when given, is only checked to pair with the results (the format needs no camera).

    Returns:
        The report; ``skipped`` lists the unsolved vehicles (no box, no entry).

    Raises:
        InputError: see :func:`nuscenes_dict`.
        OSError: the file cannot be written.
    """
    path = check_output_path(path, "nuScenes")
    check_results(results, scene, False, "nuScenes")
    data = nuscenes_dict(results, sample_tokens, meta, names, moving_speed)
    write_text_atomic(path, json.dumps(data, indent=1, allow_nan=False) + "\n")
    unsolved = unsolved_of(results)
    return WriteReport("nuscenes", [path], unsolved, list(unsolved))


def read_nuscenes(path: str | os.PathLike) -> list[ReadBox]:
    """Reads the boxes of a nuScenes detection results file.

    Returns:
        One ReadBox per ``sample_result``: ``frame`` = the sample's position in ``results``, ``id`` None,
        ``label`` = ``detection_name``, ``score`` = ``detection_score``, ``extras``: ``sample_token``,
        ``velocity``, ``attribute_name``.

    Raises:
        InputError: not JSON or not the detection results form (the error names the field).
    """
    data = read_json(path, InputError)
    if not isinstance(data, dict) or not isinstance(data.get("results"), dict) or not isinstance(data.get("meta"),
                                                                                                 dict):
        raise InputError("results", "expected an object with 'meta' and 'results' objects")
    out = []
    for f, (token, entries) in enumerate(data["results"].items()):
        if not isinstance(entries, list):
            raise InputError(f"results.{token}", "expected a list of sample_result")
        for j, e in enumerate(entries):
            where = f"results.{token}[{j}]"
            try:
                centre = _numbers(e["translation"], 3, f"{where}.translation")
                width, length, height = _numbers(e["size"], 3, f"{where}.size")
                q = _numbers(e["rotation"], 4, f"{where}.rotation")
                velocity = _numbers(e["velocity"], 2, f"{where}.velocity")
                name, score, attribute = e["detection_name"], float(e["detection_score"]), e["attribute_name"]
            except (KeyError, TypeError) as exc:
                raise InputError(where, f"missing or malformed field {exc}") from None
            try:
                R = rotation_from_wxyz(q)
            except InputError as exc:
                raise InputError(f"{where}.rotation", exc.problem) from None
            if "sample_token" in e and e["sample_token"] != token:
                raise InputError(f"{where}.sample_token", f"{e['sample_token']!r} is in the results of {token!r}")
            out.append(ReadBox(frame=f, id=None, box=box_from_centre(centre, R, [length, width, height], where),
                               label=name, score=score,
                               extras={"sample_token": token, "velocity": velocity, "attribute_name": attribute}))
    return out


def _numbers(value, n: int, where: str) -> np.ndarray:
    if (not isinstance(value, list) or len(value) != n
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)):
        raise InputError(where, f"expected {n} numbers, got {value!r}")
    return np.asarray(value, dtype=float)
