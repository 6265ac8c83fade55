"""KITTI object labels: per camera, one ``label_2/NNNNNN.txt`` and one ``calib/NNNNNN.txt`` per frame.

Each label line has the 15 fields of the KITTI object devkit's readme plus
the score (the results form)::

    type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y score

in the *label frame* of that camera: KITTI's camera coordinates, x right,
y down, z forward. With ``frame="camera"`` (default) that is the camera's
own OpenCV frame; with ``frame="level"`` it is the camera frame turned so
that its y axis points straight down (world -z) and its z axis is the
optical axis made horizontal (same origin): a tilted roadside camera's
boxes are upright in it, which KITTI's box model (yaw about y only) needs
to be exact. ``calib/NNNNNN.txt`` says which: ``P0``-``P3`` = ``K [R | 0]``
project label-frame points to pixels (``R`` = the label frame's rotation
into the camera frame; the identity for ``frame="camera"``; lens distortion
is not in it), ``R0_rect`` = identity, ``Tr_velo_to_cam`` = label frame <-
world (the world plays the velodyne's part), ``Tr_imu_to_velo`` = identity.

* ``h w l`` = the box's height, width, length (m).
* ``x y z`` = the bottom centre of the KITTI box: the box centre plus
  ``h/2`` along the label frame's y (down). The KITTI box is upright in the
  label frame, so it is our box exactly when the box's up axis is the label
  frame's -y (a level vehicle with ``frame="level"``, or a level camera);
  otherwise the centre and the size are kept and the tilt is lost.
* ``rotation_y`` = ``atan2(-f_z, f_x)`` of the box's forward axis ``f`` in
  the label frame, in (-pi, pi] (KITTI: ``f = (cos ry, 0, -sin ry)``; a box
  driving away from the camera along its optical axis has -pi/2).
* ``alpha`` = ``rotation_y - atan2(x_c, z_c)`` of the box centre, in (-pi, pi].
* ``x1 y1 x2 y2``: the box's 8 corners (and where its edges cross the plane
  0.1 m in front of the camera) projected with the camera (distortion
  included), their bounding rectangle clipped to the image
  ``[0, width - 1] x [0, height - 1]``.
* ``truncated`` = 1 - (area of the clipped rectangle / area of the unclipped
  one), so 0 when the whole projected box is inside the image; 0 when the
  image size is unknown (nothing clipped).
* ``occluded`` = 3 ("unknown"): vfactor does not estimate occlusion.
* ``type`` and ``score``: the most probable KITTI type under the body-type
  posterior (:data:`KITTI_TYPES`) and its probability.

A camera's file lists the solved vehicles whose box lies at least partly in
front of it (0.1 m) and whose rectangle meets the image. Unsolved vehicles
have no box and are left out (:attr:`WriteReport.skipped`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from vfactor.box import Box
from vfactor.camera import Camera
from vfactor.errors import InputError
from vfactor.formats.common import (
    BOX_EDGES,
    ReadBox,
    WriteReport,
    box_corners,
    box_from_centre,
    check_output_path,
    check_results,
    class_probabilities,
    solved_box,
    unsolved_of,
)
from vfactor.jsonio import write_text_atomic
from vfactor.observations import Scene
from vfactor.result import FrameResult

__all__ = ["KITTI_TYPES", "KITTI_DEFAULT_TYPE", "LABEL_FRAMES", "NEAR", "kitti_label_frame", "kitti_lines",
           "write_kitti", "read_kitti"]

#: vfactor body type -> KITTI type. KITTI's Car / Van / Truck; a pickup is a (light) truck, as nuScenes files it;
#: KITTI has no bus class, and a bus is a large vehicle as its trucks are.
KITTI_TYPES = {"sedan": "Car", "hatchback": "Car", "estate": "Car", "suv": "Car", "van": "Van", "pickup": "Truck",
               "bus": "Truck"}
#: KITTI type of a vehicle without a body type (solved with one prior) or with one the map lacks.
KITTI_DEFAULT_TYPE = "Car"
#: Values of ``frame``.
LABEL_FRAMES = ("camera", "level")
#: Distance of the clipping plane in front of the camera (m).
NEAR = 0.1


def kitti_label_frame(camera: Camera, frame: str = "camera") -> np.ndarray:
    """4x4 ``label_T_world`` of a camera's label frame (module docstring).

    Raises:
        InputError: ``frame`` is not one of :data:`LABEL_FRAMES`, or ``"level"`` for a camera looking
            straight up or down.
    """
    if frame not in LABEL_FRAMES:
        raise InputError("frame", f"expected one of {list(LABEL_FRAMES)}, got {frame!r}")
    if frame == "camera":
        return np.array(camera.camera_T_world, dtype=float)
    world_R_camera = camera.world_T_camera[:3, :3]
    forward = world_R_camera[:, 2].copy()
    forward[2] = 0.0
    if np.linalg.norm(forward) < 1e-6:
        raise InputError("frame", f"'level' needs a camera whose optical axis is not vertical ({camera.name})")
    z = forward / np.linalg.norm(forward)
    y = np.array([0.0, 0.0, -1.0])
    world_R_label = np.column_stack([np.cross(y, z), y, z])
    T = np.eye(4)
    T[:3, :3] = world_R_label.T
    T[:3, 3] = -world_R_label.T @ camera.center
    return T


def kitti_lines(results: list[FrameResult], camera: Camera, frame: str = "camera",
                types: dict[str, str] | None = None) -> list[list[str]]:
    """The label lines of one camera, one list per result frame (module docstring)."""
    label_T_world = kitti_label_frame(camera, frame)
    mapping = KITTI_TYPES if types is None else types
    out = []
    for result in results:
        lines = []
        for v in result.vehicles:
            box = solved_box(v)
            if box is None:
                continue
            fields = _label_fields(box, camera, label_T_world)
            if fields is None:
                continue
            name, score = class_probabilities(v, mapping, KITTI_DEFAULT_TYPE)
            lines.append(" ".join([name, *fields, f"{score:.4f}"]))
        out.append(lines)
    return out


def write_kitti(folder: str | os.PathLike, results: list[FrameResult], scene: Scene, cameras: list[str] | None = None,
                frame: str = "camera", types: dict[str, str] | None = None) -> WriteReport:
    """Writes KITTI labels and calibrations: ``folder/<camera>/label_2/NNNNNN.txt`` and ``.../calib/NNNNNN.txt``.

    ``NNNNNN`` is the frame's index in the results; every frame gets a file (empty when no box is seen).
    Each file is written atomically. A camera's ``NNNNNN.txt`` files from an earlier run beyond this run's frames
    are removed (they would read as this run's); other files and other cameras' folders are left as they are, and
    the report names those folders (``foreign``: :func:`read_kitti` reads them too).

    Args:
        folder: the output folder (created when missing).
        results: one FrameResult per scene frame.
        scene: the scene the results came from (its cameras).
        cameras: the cameras to write (default: all, in scene order).
        frame: ``"camera"`` or ``"level"`` (module docstring).
        types: body type -> KITTI type (default :data:`KITTI_TYPES`).

    Returns:
        The report; ``skipped`` lists the unsolved vehicles (no box, no line).

    Raises:
        InputError: bad arguments (an unknown camera, frame or type map; results not paired with the scene; a
            camera name that is not a plain folder name, such as ``../x``).
        OSError: a file cannot be written.
    """
    folder = check_output_path(folder, "KITTI")
    check_results(results, scene, True, "KITTI")
    names = list(scene.cameras) if cameras is None else cameras
    if not isinstance(names, (list, tuple)) or not names or any(n not in scene.cameras for n in names):
        raise InputError("cameras", f"expected names among {list(scene.cameras)}, got {cameras!r}")
    if types is not None and (not isinstance(types, dict) or not all(isinstance(t, str) and t.strip() and
                                                                      " " not in t for t in types.values())):
        raise InputError("types", "expected a dict body type -> KITTI type without spaces")
    for name in names:  # each camera's folder is folder/<name>: a name must not lead out of it
        if name in ("", ".", "..") or Path(name).name != name or "\\" in name:
            raise InputError(f"cameras[{list(scene.cameras).index(name)}].name",
                             f"{name!r} is not a plain folder name, which KITTI output names a camera's folder by")
    paths = []
    for name in names:
        camera = scene.cameras[name]
        label_T_world = kitti_label_frame(camera, frame)
        calib = _calib_text(camera, label_T_world)
        for i, lines in enumerate(kitti_lines(results, camera, frame, types)):
            label_path = folder / name / "label_2" / f"{i:06d}.txt"
            calib_path = folder / name / "calib" / f"{i:06d}.txt"
            write_text_atomic(label_path, "".join(line + "\n" for line in lines))
            write_text_atomic(calib_path, calib)
            paths += [label_path, calib_path]
        for kind in ("label_2", "calib"):  # an earlier run's frames beyond this run's
            for stale in (folder / name / kind).glob("[0-9][0-9][0-9][0-9][0-9][0-9].txt"):
                if int(stale.stem) >= len(results):
                    stale.unlink()
    unsolved = unsolved_of(results)
    foreign = sorted(f"{p.name}/" for p in folder.iterdir() if (p / "label_2").is_dir() and p.name not in names)
    return WriteReport("kitti", paths, unsolved, list(unsolved), foreign)


def read_kitti(folder: str | os.PathLike) -> list[ReadBox]:
    """Reads back what :func:`write_kitti` wrote: every camera folder's labels as world boxes.

    The calibration's ``Tr_velo_to_cam`` (label frame <- world) brings each
    box to the world: centre = bottom centre - h/2 along the label y axis,
    forward = ``(cos ry, 0, -sin ry)``, up = -y.

    Returns:
        ReadBoxes with ``camera``, ``label`` (type), ``score`` (None without a 16th field), ``id`` None
        (KITTI object labels keep no id; lines are in the results' vehicle order), and ``extras``
        ``alpha``, ``bbox``, ``truncated``, ``occluded``.

    Raises:
        InputError: a missing calibration, or a line or calibration that is not KITTI (names file and line).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(str(folder), "expected the KITTI output folder")
    out = []
    for camera_dir in sorted(p for p in folder.iterdir() if (p / "label_2").is_dir()):
        for label_path in sorted((camera_dir / "label_2").glob("*.txt")):
            calib_path = camera_dir / "calib" / label_path.name
            if not calib_path.is_file():
                raise InputError(str(calib_path), "missing: needed to bring the labels to the world")
            world_T_label = np.linalg.inv(_read_calib(calib_path)["Tr_velo_to_cam"])
            for n, line in enumerate(label_path.read_text(encoding="utf-8").splitlines()):
                if not line.strip():
                    continue
                where = f"{label_path}:{n + 1}"
                parts = line.split()
                if len(parts) not in (15, 16):
                    raise InputError(where, f"expected 15 or 16 fields, got {len(parts)}")
                try:
                    values = [float(p) for p in parts[1:]]
                except ValueError:
                    raise InputError(where, "expected numbers after the type") from None
                truncated, occluded, alpha, x1, y1, x2, y2, h, w, length, x, y, z, ry = values[:14]
                forward = np.array([math.cos(ry), 0.0, -math.sin(ry)])
                up = np.array([0.0, -1.0, 0.0])
                label_R_box = np.column_stack([forward, np.cross(up, forward), up])
                centre = np.array([x, y - 0.5 * h, z])
                box = box_from_centre(world_T_label[:3, :3] @ centre + world_T_label[:3, 3],
                                      world_T_label[:3, :3] @ label_R_box, [length, w, h], where)
                out.append(ReadBox(frame=int(label_path.stem), id=None, box=box, label=parts[0],
                                   score=values[14] if len(values) == 15 else None, camera=camera_dir.name,
                                   extras={"alpha": alpha, "bbox": [x1, y1, x2, y2], "truncated": truncated,
                                           "occluded": int(occluded)}))
    return out


def _label_fields(box: Box, camera: Camera, label_T_world: np.ndarray) -> list[str] | None:
    """The 14 numbers of a label line after the type, or None when the box is not in the camera's view."""
    corners = box_corners(box)
    uv = _projected_outline(corners, camera)
    if uv is None:
        return None
    x1, y1 = uv.min(axis=0)
    x2, y2 = uv.max(axis=0)
    truncated = 0.0
    if camera.image_size is not None:
        w, h = camera.image_size
        cx1, cx2 = np.clip([x1, x2], 0.0, w - 1.0)
        cy1, cy2 = np.clip([y1, y2], 0.0, h - 1.0)
        if cx2 <= cx1 or cy2 <= cy1:
            return None
        full = max((x2 - x1) * (y2 - y1), 1e-12)
        truncated = float(np.clip(1.0 - (cx2 - cx1) * (cy2 - cy1) / full, 0.0, 1.0))
        x1, x2, y1, y2 = cx1, cx2, cy1, cy2
    T = np.asarray(box.world_T_box.matrix(), dtype=float)
    R = label_T_world[:3, :3]
    centre = R @ T[:3, 3] + label_T_world[:3, 3]
    forward = R @ T[:3, 0]
    length, width, height = (float(s) for s in box.size)
    bottom = centre + np.array([0.0, 0.5 * height, 0.0])
    rotation_y = _wrap(math.atan2(-forward[2], forward[0]))
    alpha = _wrap(rotation_y - math.atan2(centre[0], centre[2]))
    return [f"{truncated:.2f}", "3", f"{alpha:.6f}", *(f"{v:.2f}" for v in (x1, y1, x2, y2)),
            *(f"{v:.6f}" for v in (height, width, length, *bottom, rotation_y))]


def _projected_outline(corners: np.ndarray, camera: Camera) -> np.ndarray | None:
    """Pixels of the corners in front of the near plane and of the edges' crossings of it; None when none."""
    p = camera.to_camera(corners)
    points = [p[i] for i in range(8) if p[i, 2] >= NEAR]
    for a, b in BOX_EDGES:
        za, zb = p[a, 2], p[b, 2]
        if (za - NEAR) * (zb - NEAR) < 0:
            s = (NEAR - za) / (zb - za)
            points.append(p[a] + s * (p[b] - p[a]))
    if not points:
        return None
    uv, _ = camera.project_camera_points(np.array(points), jacobian=False)
    return uv if np.all(np.isfinite(uv)) else None


def _calib_text(camera: Camera, label_T_world: np.ndarray) -> str:
    camera_R_label = camera.camera_T_world[:3, :3] @ label_T_world[:3, :3].T
    P = camera.K @ np.hstack([camera_R_label, np.zeros((3, 1))])

    def row(name, M):
        return f"{name}: " + " ".join(f"{v:.12e}" for v in np.asarray(M, dtype=float).ravel()) + "\n"

    return (row("P0", P) + row("P1", P) + row("P2", P) + row("P3", P) + row("R0_rect", np.eye(3))
            + row("Tr_velo_to_cam", label_T_world[:3]) + row("Tr_imu_to_velo", np.eye(4)[:3]))


def _read_calib(path: Path) -> dict[str, np.ndarray]:
    out = {}
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines()):
        if not line.strip():
            continue
        key, _, rest = line.partition(":")
        try:
            values = np.array([float(v) for v in rest.split()])
        except ValueError:
            raise InputError(f"{path}:{n + 1}", "expected 'NAME: numbers'") from None
        out[key.strip()] = values
    tr = out.get("Tr_velo_to_cam")
    if tr is None or tr.size != 12:
        raise InputError(str(path), "expected a 'Tr_velo_to_cam:' line of 12 numbers")
    T = np.eye(4)
    T[:3] = tr.reshape(3, 4)
    out["Tr_velo_to_cam"] = T
    return out


def _wrap(angle: float) -> float:
    """An angle in (-pi, pi]."""
    a = math.remainder(angle, 2.0 * math.pi)
    return math.pi if a <= -math.pi else a
