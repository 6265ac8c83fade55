"""Accuracy: tracks whose detections carry a 2D detector's class (``"class"``) against the same without.

Each scene of a scenario is simulated, and tracked as :func:`vfactor.evaluation.compare_tracking` tracks it
(frame by frame, iSAM2, batch; the shape model held out) twice: as simulated (no classes) and with a COCO-like
class on every detection from its vehicle's true body type (a bus ``bus``, a pickup or a van ``truck``, the other
types ``car``). Prints per method and body type the mean rotation (deg) and translation (cm) errors, each track's
final shape (iSAM2, mean body-frame keypoint error, cm: mean and worst) and the body types the tracks were given.

Run: ``python benchmarks/track_classes.py [--scenario S] [--seed N] [--seeds K]`` (default:
``library_bus_tracks_2cam`` seeds 40-49; about 2 min on 2 cores).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

#: The class a COCO-trained detector gives each body type.
COCO_CLASS = {"bus": "bus", "pickup": "truck", "van": "truck", "suv": "car", "sedan": "car", "hatchback": "car",
              "estate": "car", "pascal3d": "car"}


def _unit(unit: tuple) -> tuple[bool, dict, list, dict]:
    from vfactor.evaluation import body_type_of, compare_tracking
    from vfactor.observations import Frame
    from vfactor.sim import load_scenario, simulate

    scenario, seed, classed = unit
    sim = simulate(load_scenario(scenario), seed=seed)
    types = {vid: body_type_of(t.preset) for f in sim.truth for vid, t in f.items()}
    if classed:
        frames = [Frame(f.t, [dataclasses.replace(d, vehicle_class=COCO_CLASS[types[d.vehicle]])
                              for d in f.detections], f.images) for f in sim.scene.frames]
        sim = dataclasses.replace(sim, scene=dataclasses.replace(sim.scene, frames=frames))
    out = compare_tracking(sim)
    rows: dict = {}
    for method in ("frame_by_frame", "isam2", "batch"):
        for r in out["errors"][method]:
            rows.setdefault((method, types[r["vehicle"]]), []).append((r["rotation_deg"], r["translation_cm"]))
    shapes = [(types[vid], cm) for vid, cm in out["shape_cm"]["isam2"].items()]
    return classed, rows, shapes, {f"{seed}:{vid}": t for vid, t in out["shape_types"].items()}


def main(argv=None) -> list:
    from vfactor.parallel.engine import open_engine

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="library_bus_tracks_2cam")
    parser.add_argument("--seed", type=int, default=40)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    units = [(args.scenario, s, c) for c in (False, True) for s in range(args.seed, args.seed + args.seeds)]
    done = list(open_engine(workers=args.workers).map(_unit, units))
    for classed in (False, True):
        pooled, shapes, given = {}, {}, {}
        for c, rows, unit_shapes, unit_types in done:
            if c != classed:
                continue
            for key, errors in rows.items():
                pooled.setdefault(key, []).extend(errors)
            for body_type, cm in unit_shapes:
                shapes.setdefault(body_type, []).append(cm)
            given.update(unit_types)
        print(f"\n## {'with' if classed else 'without'} classes, {args.scenario} seeds {args.seed}-"
              f"{args.seed + args.seeds - 1}")
        for (method, body_type), errors in sorted(pooled.items()):
            rotation, translation = np.mean(errors, axis=0)
            print(f"{method:15s} {body_type:10s} {len(errors):4d} poses  {rotation:.2f} deg  {translation:.1f} cm")
        for body_type, cms in sorted(shapes.items()):
            print(f"final shape {body_type:10s} {np.mean(cms):.1f} cm (worst {np.max(cms):.1f})")
        print("tracks given:", ", ".join(f"{k} {v}" for k, v in sorted(given.items())))
    return done


if __name__ == "__main__":
    main()
