"""What the output formats share: box geometry, classes from body types, the write report, read-back boxes.

Frames and units follow docs/conventions.md: the world is right-handed with z
up, a box frame (``Box.world_T_box``) has the body axes (x forward, y left,
z up) and its origin at the box centre, lengths are metres, angles radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import gtsam
import numpy as np

from vfactor.box import Box
from vfactor.errors import InputError
from vfactor.observations import Scene
from vfactor.result import FrameResult, VehicleResult

__all__ = [
    "BOX_EDGES",
    "ReadBox",
    "WriteReport",
    "box_corners",
    "box_from_centre",
    "class_probabilities",
    "check_output_path",
    "check_results",
    "number",
    "quaternion_wxyz",
    "rotation_from_wxyz",
    "solved_box",
    "unsolved_of",
]

#: The 12 edges of :func:`box_corners`, as index pairs.
BOX_EDGES = ((0, 1), (1, 3), (3, 2), (2, 0), (4, 5), (5, 7), (7, 6), (6, 4), (0, 4), (1, 5), (2, 6), (3, 7))


def box_corners(box: Box) -> np.ndarray:
    """(8, 3) world corners of a box, metres.

    Corner ``i`` sits at ``(+-l/2, +-w/2, +-h/2)`` in the box frame with the
    signs from the bits of ``i``: bit 2 -> x (0: front, +l/2), bit 1 -> y
    (0: left, +w/2), bit 0 -> z (0: top, +h/2). So corners 0-3 are the front
    face and ``(0, 1, 2, 3)`` = front left top, front left bottom, front right
    top, front right bottom.
    """
    half = 0.5 * np.asarray(box.size, dtype=float)
    signs = np.array([[1 - 2 * ((i >> 2) & 1), 1 - 2 * ((i >> 1) & 1), 1 - 2 * (i & 1)] for i in range(8)], float)
    T = np.asarray(box.world_T_box.matrix(), dtype=float)
    return (signs * half) @ T[:3, :3].T + T[:3, 3]


def quaternion_wxyz(R: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion ``(w, x, y, z)`` of a 3x3 rotation matrix, with ``w >= 0``."""
    q = gtsam.Rot3(np.asarray(R, dtype=float)).toQuaternion()
    out = np.array([q.w(), q.x(), q.y(), q.z()])
    out /= np.linalg.norm(out)
    return -out if out[0] < 0 else out


def rotation_from_wxyz(q) -> np.ndarray:
    """3x3 rotation matrix of a quaternion ``(w, x, y, z)`` (normalised first).

    Raises:
        InputError: not four finite numbers with a non-zero norm.
    """
    q = np.asarray(q, dtype=float)
    n = float(np.linalg.norm(q)) if q.shape == (4,) and np.all(np.isfinite(q)) else 0.0
    if not n > 0:
        raise InputError("rotation", f"expected a quaternion of 4 finite numbers, not all 0, got {q.tolist()}")
    w, x, y, z = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def box_from_centre(centre, world_R_box: np.ndarray, size, where: str = "box", **sigmas) -> Box:
    """A :class:`~vfactor.box.Box` from its world centre (m), rotation (box -> world) and (l, w, h) size (m), as a
    reader finds them in a file.

    ``heading`` is computed from the rotation as :func:`vfactor.box.vehicle_box` does (yaw of the box x axis
    about world z); ``sigmas`` are passed on (``size_sigma``, ``heading_sigma``, ``centre_sigma``).

    Raises:
        InputError: (field ``where``) a centre or rotation that is not finite, or a size that is not positive.
    """
    if not np.all(np.isfinite(np.asarray(centre, dtype=float))) or not np.all(np.isfinite(world_R_box)):
        raise InputError(where, "a box centre and rotation must be finite numbers, got centre "
                                f"{[float(c) for c in centre]}")
    if not np.all(np.asarray(size, dtype=float) > 0):  # NaN fails too
        raise InputError(where, f"a box's length, width and height must be positive, got {[float(x) for x in size]}")
    R = np.asarray(world_R_box, dtype=float)
    u, _, vt = np.linalg.svd(R)
    R = u @ vt
    return Box(gtsam.Pose3(gtsam.Rot3(R), np.asarray(centre, dtype=float)), np.asarray(size, dtype=float),
               heading=math.atan2(R[1, 0], R[0, 0]), **sigmas)


def solved_box(vehicle: VehicleResult) -> Box | None:
    """The vehicle's box, or None when it was not solved (status degenerate / failed) or has no box."""
    return vehicle.box if vehicle.ok and vehicle.box is not None else None


def class_probabilities(vehicle: VehicleResult, mapping: dict[str, str], default: str) -> tuple[str, float]:
    """The most probable class of a vehicle under a body type -> class map, and its probability.

    The probability of a class is the sum of the body-type posterior
    (``extras["body_type_posterior"]``; else ``{body_type: body_type_probability}``)
    over the body types that map to it; body types the map lacks count for
    ``default``. A vehicle solved with a single prior (no body type) is
    ``(default, 1.0)``.
    """
    posterior = vehicle.extras.get("body_type_posterior") or (
        {vehicle.body_type: vehicle.body_type_probability if vehicle.body_type_probability is not None else 1.0}
        if vehicle.body_type is not None else {})
    sums: dict[str, float] = {}
    for body_type, p in posterior.items():
        name = mapping.get(body_type, default)
        sums[name] = sums.get(name, 0.0) + float(p)
    if not sums:
        return default, 1.0
    name = max(sums, key=lambda k: (sums[k], k == default))
    return name, min(max(sums[name], 0.0), 1.0)


def check_results(results: list[FrameResult], scene: Scene | None, needs_scene: bool, writer: str) -> None:
    """Checks the arguments every writer takes.

    Raises:
        InputError: ``results`` is not a list of :class:`~vfactor.result.FrameResult`, or
            ``scene`` is needed and missing, or its frames do not pair one to one with the results'.
    """
    if not isinstance(results, (list, tuple)) or not all(isinstance(f, FrameResult) for f in results):
        raise InputError("results", f"{writer}: expected a list of FrameResult (solve_scene, track_scene(...).frames)")
    if scene is None:
        if needs_scene:
            raise InputError("scene", f"{writer} needs the scene (its cameras) the results were solved from")
        return
    if not isinstance(scene, Scene):
        raise InputError("scene", f"{writer}: expected a vfactor Scene, got {type(scene).__name__}")
    if len(scene.frames) != len(results):
        raise InputError("scene", f"{writer}: the scene has {len(scene.frames)} frames but the results "
                                  f"{len(results)}; give the scene the results were solved from")


@dataclass
class WriteReport:
    """What a writer wrote and what it left out.

    Attributes:
        format: the format's name (:data:`vfactor.formats.FORMATS`).
        paths: the files written.
        unsolved: ``(frame index, vehicle id, status)`` of every vehicle that was not solved.
        skipped: those of ``unsolved`` the format has no place for, so they are absent from the files
            (KITTI, nuScenes); OpenLABEL and CSV keep every vehicle, so theirs is empty.
        foreign: what the output folder holds that this run did not write and a reader of the folder reads as
            well (KITTI: other cameras' folders, from an earlier run).
    """

    format: str
    paths: list[Path] = field(default_factory=list)
    unsolved: list[tuple[int, str, str]] = field(default_factory=list)
    skipped: list[tuple[int, str, str]] = field(default_factory=list)
    foreign: list[str] = field(default_factory=list)

    def note(self) -> str:
        """One line for the command line about the unsolved vehicles and what the output holds besides this
        run's; empty when there is nothing to say."""
        notes = [self._unsolved_note()] if self.unsolved else []
        if self.foreign:
            notes.append(f"the {self.format} output folder also holds {', '.join(self.foreign)}, which this run did "
                         "not write (an earlier run's?): a reader of the folder reads them too")
        return "; ".join(notes)

    def _unsolved_note(self) -> str:
        listed = ", ".join(f"frame {f} {vid} ({status})" for f, vid, status in self.unsolved[:5])
        more = f" and {len(self.unsolved) - 5} more" if len(self.unsolved) > 5 else ""
        if self.skipped:
            return (f"{len(self.skipped)} unsolved vehicle(s) left out of the {self.format} output, which has no "
                    f"place for a vehicle without a box: {listed}{more}")
        return f"{len(self.unsolved)} unsolved vehicle(s) written with their status and no box: {listed}{more}"


@dataclass
class ReadBox:
    """A box read back from an output file.

    Attributes:
        frame: frame index (the results' order; for nuScenes the order of the samples in the file).
        id: vehicle id where the format keeps one (OpenLABEL, CSV), else None.
        box: the box in the world frame; None for an unsolved vehicle (OpenLABEL, CSV).
        status: the result status where the format keeps it (OpenLABEL, CSV).
        label: the class written (KITTI type, nuScenes detection name, OpenLABEL / CSV body type).
        score: the score written (KITTI, nuScenes), or the body-type probability (CSV, OpenLABEL).
        camera: the camera of a KITTI label, else None.
        extras: the rest of the fields, as read.
    """

    frame: int
    id: str | None
    box: Box | None
    status: str | None = None
    label: str | None = None
    score: float | None = None
    camera: str | None = None
    extras: dict = field(default_factory=dict)


def unsolved_of(results: list[FrameResult]) -> list[tuple[int, str, str]]:
    """``(frame index, id, status)`` of each vehicle without a box."""
    return [(i, v.id, getattr(v.status, "value", str(v.status))) for i, frame in enumerate(results)
            for v in frame.vehicles if solved_box(v) is None]


def number(x: float, digits: int = 6) -> float:
    """A float rounded for text output (6 decimals: micrometres, microradians)."""
    return float(round(float(x), digits)) + 0.0


def check_output_path(path, what: str) -> Path:
    """``path`` as a Path; raises InputError("path", ...) for an empty or non-path value."""
    if not isinstance(path, (str, Path)) or not str(path):
        raise InputError("path", f"{what}: expected a file or folder path, got {path!r}")
    return Path(path)
