"""``vfactor fit-ground``: a scene's road plane fitted to its own traffic (:mod:`vfactor.ground_fit`)."""

from __future__ import annotations

import dataclasses
import time

from vfactor.cli.common import EXIT_OK, detect, progress, rig_scenes
from vfactor.cli.estimate import associate
from vfactor.errors import InputError

__all__ = ["fit_ground"]


def fit_ground(args) -> int:
    """``vfactor fit-ground SCENE --out SCENE_OUT [--traffic FILE ...] [--hub-height M] [--batch] [--weights W]``:
    tracks SCENE and the ``--traffic`` scenes of the same cameras (none giving a plane; detections given as image
    boxes through the keypoint network first, detections that name no vehicle associated), fits the road plane to
    all their tracks' hub centres and writes SCENE, as it was given, with the plane as its ``ground_plane``."""
    from vfactor.ground_fit import fit_ground_plane
    from vfactor.scene import save_scene
    from vfactor.solve import SolveOptions
    from vfactor.track import TrackOptions, smooth_scene, track_scene

    if args.hub_height is not None and not (args.hub_height >= 0 and args.hub_height < float("inf")):
        raise InputError("--hub-height", f"expected a non-negative number of metres, got {args.hub_height}")
    out, scenes = rig_scenes(args, "a road plane is fitted to the traffic of one rig")
    scene = scenes[0][1]
    for name, other in scenes:
        if other.ground_plane is not None:
            raise InputError("ground_plane", f"{name} gives a road plane already; remove it to fit one")
    options = TrackOptions(solve=SolveOptions(covariance=False), covariance=False)
    t0 = time.perf_counter()
    results = []
    for name, other in scenes:
        detected, _ = associate(detect(other, args), args, force=False)  # detections that name no vehicle first
        if args.batch:
            results += smooth_scene(detected, options, progress=progress("smoothing", not args.quiet))
        else:
            results += track_scene(detected, options, progress=progress("tracking", not args.quiet)).frames
    try:
        fit = fit_ground_plane(results, args.hub_height)
    except InputError as exc:  # the scenes' traffic does not make a plane
        raise InputError(", ".join(name for name, _ in scenes), exc.problem) from None
    save_scene(dataclasses.replace(scene, ground_plane=fit.plane), out)
    if not args.quiet:
        n, d = fit.plane.normal, fit.plane.offset
        hubs = f"hubs {fit.hub_height:.3f} m above it" + ("" if args.hub_height is not None else
                                                           " on average, each at its body type's wheel radius")
        print(f"road plane {n[0]:.4f} x + {n[1]:.4f} y + {n[2]:.4f} z = {d:.3f} m ({fit.tilt_deg:.2f} deg from "
              f"horizontal), from {fit.points} tracked poses of {len(scenes)} scene(s) ({fit.inliers} within 3 "
              f"robust scales; scale {100 * fit.scale:.1f} cm; {hubs}), {time.perf_counter() - t0:.2f} s; wrote {out}")
    return EXIT_OK

