"""``vfactor fit-extrinsics``: a rig's camera poses fitted to its own traffic (:mod:`vfactor.extrinsics_fit`)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from vfactor.cli.common import EXIT_OK, degrees_metres, detect, note, open_command_engine, progress, rig_scenes
from vfactor.cli.estimate import associate
from vfactor.errors import CalibrationError, InputError

__all__ = ["fit_extrinsics"]


def fit_extrinsics(args) -> int:
    """``vfactor fit-extrinsics SCENE --out SCENE_OUT [--traffic FILE ...] [--extrinsic-sigma DEG,M] [--shape-per-frame]
    [--workers N | --scheduler ADDRESS] [--weights W]``:
    solves every vehicle of SCENE and of the ``--traffic`` scenes of the same cameras one frame at a time
    (detections given as image boxes through the keypoint network first, detections that name no vehicle
    associated), fits the errors of the cameras that declare an ``extrinsic_sigma`` (or all, given
    ``--extrinsic-sigma``) to all of them, and writes SCENE, as it was given, with each camera moved by its fitted
    error and the fit's sigma as its ``extrinsic_sigma``."""
    from vfactor.camera import extrinsic_sigma
    from vfactor.extrinsics_fit import fit_extrinsics as fit
    from vfactor.parallel import check_engine_options
    from vfactor.scene import save_scene
    from vfactor.solve import SolveOptions, solve_scene

    default = None
    if args.extrinsic_sigma is not None:
        try:
            default = extrinsic_sigma(*degrees_metres(args.extrinsic_sigma, "--extrinsic-sigma"), "--extrinsic-sigma")
        except CalibrationError as exc:
            raise InputError("--extrinsic-sigma", f"{exc.field.split('.')[-1]}: {exc.problem}") from None
        if not np.all(default > 0):
            raise InputError("--extrinsic-sigma", f"expected two numbers > 0, got {args.extrinsic_sigma!r}")
    check_engine_options(args.workers, args.scheduler)
    out, scenes = rig_scenes(args, "the cameras of one rig are fitted to its traffic")
    scene = scenes[0][1]
    options = SolveOptions(covariance=False)
    t0 = time.perf_counter()
    engine = open_command_engine(args.workers, args.scheduler) if args.workers or args.scheduler else None
    try:
        detected, results = [], []
        for _, other in scenes:
            # detections naming no vehicle first
            found, _ = associate(detect(other, args, engine), args, force=False, engine=engine)
            detected.append(found)
            results.append(solve_scene(found, options, progress=progress("solving", not args.quiet), engine=engine))
        fitted = fit(detected, results, options, default, shared_shape=not args.shape_per_frame, engine=engine)
    except InputError as exc:
        if exc.field != "scenes":
            raise
        raise InputError(", ".join(name for name, _ in scenes), exc.problem) from None
    finally:
        if engine is not None:
            engine.close()
    save_scene(dataclasses.replace(scene, cameras={name: fitted.cameras[name] for name in scene.cameras}), out)
    for message in fitted.notes:
        note(message)
    if not args.quiet:
        for name, xi in fitted.corrections.items():
            before = scene.cameras[name].extrinsic_sigma
            before = default if before is None else before
            after = fitted.cameras[name].extrinsic_sigma
            print(f"camera {name}: turned {np.degrees(np.linalg.norm(xi[:3])):.2f} deg, moved "
                  f"{100 * np.linalg.norm(xi[3:]):.1f} cm; sigma {_sigma(before)} -> {_sigma(after)} "
                  f"({fitted.views[name]} views)")
        print(f"fitted the cameras to {fitted.poses} vehicle poses seen by two cameras or more, of {len(scenes)} "
              f"scene(s), solved again with the cameras as first fitted (keypoints' residual scale "
              f"{fitted.residual_scale:.2f}), {time.perf_counter() - t0:.2f} s; wrote {out}")
    return EXIT_OK


def _sigma(sigma: np.ndarray) -> str:
    """A camera's (6,) extrinsic sigma as 'R deg / T cm' (the largest over its axes)."""
    return f"{np.degrees(np.max(sigma[:3])):.2f} deg / {100 * np.max(sigma[3:]):.1f} cm"
