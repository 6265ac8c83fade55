"""``vfactor fit-ground``: a scene's road plane fitted to its own traffic (:mod:`vfactor.ground_fit`)."""

from __future__ import annotations

import dataclasses
import time
from types import SimpleNamespace

from vfactor.cli.common import EXIT_OK, check_out_file, detect, progress
from vfactor.errors import InputError

__all__ = ["fit_ground"]


def fit_ground(args) -> int:
    """``vfactor fit-ground SCENE --out SCENE_OUT [--hub-height M] [--batch] [--weights W]``: tracks SCENE (no
    plane; detections given as image boxes through the keypoint network first), fits the road plane to the tracks'
    hub centres and writes SCENE, as it was given, with the plane as its ``ground_plane``."""
    from vfactor.ground_fit import fit_ground_plane
    from vfactor.scene import load_scene, save_scene
    from vfactor.solve import SolveOptions
    from vfactor.track import TrackOptions, smooth_scene, track_scene

    out = check_out_file(args.out, "--out", [("scene file", args.scene)])
    if not (args.hub_height >= 0 and args.hub_height < float("inf")):
        raise InputError("--hub-height", f"expected a non-negative number of metres, got {args.hub_height}")
    scene = load_scene(args.scene, allow_outside_paths=args.allow_outside_paths)
    if scene.ground_plane is not None:
        raise InputError("ground_plane", f"{args.scene} gives a road plane already; remove it to fit one")
    detected = detect(scene, SimpleNamespace(weights=args.weights, save_detections=None, quiet=args.quiet))
    options = TrackOptions(solve=SolveOptions(covariance=False), covariance=False)
    t0 = time.perf_counter()
    if args.batch:
        results = smooth_scene(detected, options, progress=progress("smoothing", not args.quiet))
    else:
        results = track_scene(detected, options, progress=progress("tracking", not args.quiet)).frames
    try:
        fit = fit_ground_plane(results, args.hub_height)
    except InputError as exc:  # the scene's traffic does not make a plane
        raise InputError(args.scene, exc.problem) from None
    save_scene(dataclasses.replace(scene, ground_plane=fit.plane), out)
    if not args.quiet:
        n, d = fit.plane.normal, fit.plane.offset
        print(f"road plane {n[0]:.4f} x + {n[1]:.4f} y + {n[2]:.4f} z = {d:.3f} m ({fit.tilt_deg:.2f} deg from "
              f"horizontal), from {fit.points} tracked poses ({fit.inliers} within 3 robust scales; scale "
              f"{100 * fit.scale:.1f} cm), {time.perf_counter() - t0:.2f} s; wrote {out}")
    return EXIT_OK
