"""Other tools' file formats: vfactor's results written as OpenLABEL, KITTI, nuScenes or CSV
(docs/output-formats.md), and detections of other keypoint detectors read into scene files
(:mod:`vfactor.formats.coco` with the keypoint sets of :mod:`vfactor.formats.keypoint_sets`,
docs/keypoint-sets.md).

:func:`write_results` is the one entry point (``vfactor solve`` and ``vfactor
track`` call it for ``--format``); each format also has its own writer and a
reader that gives the boxes back (:class:`~vfactor.formats.common.ReadBox`).
Every file is written atomically. A vehicle that was not solved (status
``degenerate`` / ``failed``) has no box; OpenLABEL and CSV keep it with its
status, KITTI and nuScenes have no place for it and leave it out, and
:attr:`WriteReport.skipped` lists it (``WriteReport.note()`` gives a line to print).
"""

from __future__ import annotations

import inspect
import os
from pathlib import Path

from vfactor.errors import InputError
from vfactor.jsonio import describe
from vfactor.formats.common import ReadBox, WriteReport, box_corners, unsolved_of
from vfactor.formats.csv_table import CSV_COLUMNS, read_csv, write_csv
from vfactor.formats.kitti import KITTI_TYPES, read_kitti, write_kitti
from vfactor.formats.nuscenes import NUSCENES_NAMES, read_nuscenes, write_nuscenes
from vfactor.formats.openlabel import read_openlabel, write_openlabel
from vfactor.observations import Scene
from vfactor.result import FrameResult

__all__ = [
    "FORMATS",
    "write_results",
    "WriteReport",
    "ReadBox",
    "box_corners",
    "write_openlabel",
    "read_openlabel",
    "write_kitti",
    "read_kitti",
    "KITTI_TYPES",
    "write_nuscenes",
    "read_nuscenes",
    "NUSCENES_NAMES",
    "write_csv",
    "read_csv",
    "CSV_COLUMNS",
]

#: Format name -> one-line description (the CLI's ``--format`` choices).
FORMATS = {
    "vfactor": "vfactor's own result file (JSON, docs/scene-format.md): poses, wireframes, covariances, boxes",
    "openlabel": "ASAM OpenLABEL 1.0.0 JSON: cameras, objects, per-frame world cuboids, 3D and 2D keypoints",
    "kitti": "KITTI object labels (folder): per camera label_2/NNNNNN.txt and calib/NNNNNN.txt, camera frame",
    "nuscenes": "nuScenes detection results JSON: world-frame boxes, velocity, class, score per sample",
    "csv": "CSV table: one row per vehicle per frame, world box, Z-Y-X angles, sigmas, status",
}


def _write_vfactor(path, results, scene=None) -> WriteReport:
    """The one format written as the results come: ``results`` may be an iterator (each frame is written as
    it is yielded; the file appears, atomically, after the last)."""
    from vfactor.scene import save_results

    seen: list[FrameResult] = []

    def frames():
        for frame in results:
            seen.append(frame)
            yield frame
        if scene is not None and len(scene.frames) != len(seen):  # raised before the file is moved into place
            raise InputError("scene", f"the scene has {len(scene.frames)} frames but the results {len(seen)}")

    save_results(frames(), path)
    return WriteReport("vfactor", [Path(path)], unsolved_of(seen), [])


_WRITERS = {"vfactor": _write_vfactor, "openlabel": write_openlabel, "kitti": write_kitti, "nuscenes": write_nuscenes,
            "csv": write_csv}


def write_results(path: str | os.PathLike, results: list[FrameResult], scene: Scene | None, format: str,
                  **options) -> WriteReport:
    """Writes results in one of :data:`FORMATS`.

    Args:
        path: the file (a folder for ``kitti``).
        results: one :class:`~vfactor.result.FrameResult` per scene frame, in the scene's order
            (``solve_scene(scene)`` or ``track_scene(scene).frames``); for ``vfactor``, also an iterator
            (``iter_solve_scene(scene)``), each frame written as it comes.
        scene: the scene they were solved from; needed by ``openlabel`` and ``kitti`` (cameras,
            keypoints), checked against the results by the others; None allowed for those.
        format: a key of :data:`FORMATS`.
        **options: the format writer's own keywords: ``openlabel``: ``name``, ``world``;
            ``kitti``: ``cameras``, ``frame`` (``"camera"`` / ``"level"``), ``types``;
            ``nuscenes``: ``sample_tokens``, ``meta``, ``names``, ``moving_speed``; ``csv``, ``vfactor``: none.

    Returns:
        The :class:`WriteReport` (files written, unsolved vehicles, those left out).

    Raises:
        InputError: an unknown format or option, or a bad argument (the error names it).
        OSError: a file cannot be written.
    """
    writer = _WRITERS.get(format) if isinstance(format, str) else None
    if writer is None:
        raise InputError("format", f"expected one of {list(FORMATS)}, got {describe(format)}")
    if format != "vfactor":  # the other formats need every frame at once
        results = list(results)
    allowed = [p for p in inspect.signature(writer).parameters if p not in ("path", "folder", "results", "scene")]
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise InputError("format", f"{format!r} takes the options {allowed or 'none'}, not {unknown}")
    return writer(path, results, scene, **options)
