"""Benchmark: the final shapes of two-camera tracks without a road plane, with the plane fitted to other traffic
(``vfactor fit-ground``), and with the true plane, per body type.

The plane is fitted, as ``benchmarks/ground_fit_accuracy.py`` fits it, to the tracks of its calibration scenes
(seed 20 of the same rig); each scene is then tracked (``track_scene``, final estimates) three ways with the shape
model held out (:func:`vfactor.evaluation.held_out_scene_model`), and each track's final shape compared with the
truth (mean body-frame keypoint error, cm). Issue 10's goal: every vehicle within 5 cm.

Run: ``python benchmarks/track_shape_plane.py A B C D``: ``tracks_3veh`` seeds A..B-1 and ``library_tracks_2cam``
seeds C..D-1 (about 6 s a scene).
"""
import dataclasses
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from benchmarks.ground_fit_accuracy import CALIBRATION, TRUE_PLANE  # noqa: E402
from vfactor.evaluation import body_type_of, final_shape_errors, held_out_scene_model  # noqa: E402
from vfactor.ground_fit import fit_ground_plane  # noqa: E402
from vfactor.sim import load_scenario, simulate  # noqa: E402
from vfactor.track import TrackOptions, track_scene  # noqa: E402
fitted = []
for spec in CALIBRATION:
    scen, seed = spec.split(":"); sim = simulate(load_scenario(scen), seed=int(seed))
    fitted += track_scene(sim.scene, TrackOptions(covariance=False), prior=held_out_scene_model(sim)).frames
fit = fit_ground_plane(fitted)
print(f"plane fitted to {', '.join(CALIBRATION)}: {fit.tilt_deg:.2f} deg from the road, offset "
      f"{100 * fit.plane.offset:.1f} cm", flush=True)
planes = {"none": None, "fitted": fit.plane, "true": TRUE_PLANE}
out = {p: {} for p in planes}
for scen, a, b in (("tracks_3veh", int(sys.argv[1]), int(sys.argv[2])), ("library_tracks_2cam", int(sys.argv[3]), int(sys.argv[4]))):
    for seed in range(a, b):
        sim = simulate(load_scenario(scen), seed=seed); model = held_out_scene_model(sim)
        for name, plane in planes.items():
            scene = dataclasses.replace(sim.scene, ground_plane=plane)
            run = track_scene(scene, TrackOptions(covariance=False), prior=model)
            for vid, e in final_shape_errors(sim, run.frames).items():
                preset = next(t[vid].preset for t in sim.truth if vid in t)
                out[name].setdefault(body_type_of(preset), []).append(100 * float(np.linalg.norm(e, axis=1).mean()))
print("\n| plane | " + " | ".join(sorted(out["none"])) + " |\n| --- |" + " --- |" * len(out["none"]))
for name, d in out.items():
    print(f"| {name} | " + " | ".join(f"{np.mean(v):.2f} (worst {np.max(v):.2f}, {sum(x > 5 for x in v)}/{len(v)} over 5 cm)"
                                     for _, v in sorted(d.items())) + " |")
