"""Many scenes as one job: ``vfactor solve FOLDER --out RESULTS`` or a quoted glob (docs/scaling.md).

Each scene file gets its own result under the folder ``--out``, at the scene's
path relative to the scenes' common folder (``site3/scene.json`` ->
``RESULTS/site3/scene.json``; ``.csv`` for ``--format csv``, a folder for
``--format kitti``), so that scenes of the same name in different folders do
not collide.
"""

from __future__ import annotations

import argparse
import glob
import os
from pathlib import Path

from vfactor.cli.common import note
from vfactor.errors import InputError

__all__ = ["scene_jobs", "scene_files", "TRUTH_SUFFIX"]

#: Files of a folder that are ground truth of ``vfactor simulate``, not scenes: skipped (and said so).
TRUTH_SUFFIX = "_truth.json"

_SUFFIX = {"vfactor": ".json", "openlabel": ".json", "nuscenes": ".json", "csv": ".csv", "kitti": ""}


def scene_files(spec: str) -> list[Path] | None:
    """The scene files ``spec`` names: None for one scene file (or a path that does not exist: the loader
    says so); the ``*.json`` files of a folder, or a glob's matches, sorted, without the ground-truth files of
    ``vfactor simulate`` (``*_truth.json``; said in a note), unless the glob asks for them by that suffix.

    Raises:
        InputError: (field ``scene``) a folder without scene files, or a glob that matches none.
    """
    path = Path(spec)
    if path.is_dir():
        files = sorted(p for p in path.glob("*.json") if p.is_file())
    elif path.exists() or not glob.has_magic(spec):
        return None
    else:
        files = sorted(Path(p) for p in glob.glob(spec, recursive=True) if Path(p).is_file())
    truth = [] if spec.endswith(TRUTH_SUFFIX) else [p for p in files if p.name.endswith(TRUTH_SUFFIX)]
    if truth:  # a glob over simulated sites (sites/*/*.json) matches them too
        note(f"{len(truth)} ground-truth files ({TRUTH_SUFFIX}) of {spec} are not scenes: not read")
    files = [p for p in files if p not in truth]
    if not files:
        raise InputError("scene", f"the folder {spec} holds no scene file (*.json)" if path.is_dir()
                         else f"no scene file matches {spec}")
    return files


def scene_jobs(args: argparse.Namespace) -> list[argparse.Namespace] | None:
    """One copy of the command's arguments per scene of a folder or glob, with its ``scene`` and ``out``;
    None when ``args.scene`` is one scene file.

    Raises:
        InputError: ``--out`` is a file, or an option that names one file (``--plot``, ``--save-detections``)
            is given with many scenes.
    """
    files = scene_files(args.scene)
    if files is None:
        return None
    for option in ("plot", "save_detections"):
        if getattr(args, option, None):
            raise InputError(f"--{option.replace('_', '-')}", "names one file: not for many scenes")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError("--out", f"{args.out} is a file; with many scenes --out is the folder of their results")
    base = Path(os.path.commonpath([p.absolute().parent for p in files]))
    jobs = []
    for file in files:
        relative = file.absolute().relative_to(base)
        job = argparse.Namespace(**vars(args))
        job.scene, job.out = str(file), str(out / relative.with_suffix(_SUFFIX[args.format]))
        jobs.append(job)
    return jobs
