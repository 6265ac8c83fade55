"""Accuracy: the final shapes of two-camera tracks without a road plane, with the plane fitted to other traffic
(``vfactor fit-ground``), and with the true plane, per body type.

The plane is fitted, as ``benchmarks/ground_fit_accuracy.py`` fits it, to the tracks of its calibration scenes
(seed 20 of the same rig); each scene is then tracked (``track_scene``, final estimates) three ways with the shape
model held out (:func:`vfactor.evaluation.held_out_scene_model`), and each track's final shape compared with the
truth (mean body-frame keypoint error, cm). Issue 10's goal: every vehicle within 5 cm.

Run: ``python benchmarks/track_shape_plane.py [--tracks-3veh A B] [--library-tracks-2cam C D]``: ``tracks_3veh``
seeds A..B-1 and ``library_tracks_2cam`` seeds C..D-1 (defaults 41-60 and 53-72; about 6 s a scene).
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from benchmarks.ground_fit_accuracy import CALIBRATION, TRUE_PLANE  # noqa: E402
from vfactor.evaluation import final_shape_errors, final_shape_table, held_out_scene_model, track_body_types  # noqa: E402
from vfactor.ground_fit import fit_ground_plane  # noqa: E402
from vfactor.sim import load_scenario, simulate  # noqa: E402
from vfactor.track import TrackOptions, track_scene  # noqa: E402


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks-3veh", type=int, nargs=2, default=(41, 61), metavar=("FIRST", "END"))
    parser.add_argument("--library-tracks-2cam", type=int, nargs=2, default=(53, 73), metavar=("FIRST", "END"))
    args = parser.parse_args(argv)

    fitted = []
    for spec in CALIBRATION:
        scenario, seed = spec.split(":")
        sim = simulate(load_scenario(scenario), seed=int(seed))
        fitted += track_scene(sim.scene, TrackOptions(covariance=False), prior=held_out_scene_model(sim)).frames
    fit = fit_ground_plane(fitted)
    print(f"plane fitted to {', '.join(CALIBRATION)}: {fit.tilt_deg:.2f} deg from the road, offset "
          f"{100 * fit.plane.offset:.1f} cm", flush=True)
    planes = {"none": None, "fitted": fit.plane, "true": TRUE_PLANE}
    errors = {name: {} for name in planes}  # plane -> body type -> final shape errors (cm)
    for scenario, (first, end) in (("tracks_3veh", args.tracks_3veh), ("library_tracks_2cam", args.library_tracks_2cam)):
        for seed in range(first, end):
            sim = simulate(load_scenario(scenario), seed=seed)
            model, types = held_out_scene_model(sim), track_body_types(sim)
            for name, plane in planes.items():
                run = track_scene(dataclasses.replace(sim.scene, ground_plane=plane), TrackOptions(covariance=False),
                                  prior=model)
                for vid, e in final_shape_errors(sim, run.frames).items():
                    errors[name].setdefault(types[vid], []).append(100 * float(np.linalg.norm(e, axis=1).mean()))
    print("\n" + final_shape_table(errors, "plane"))
    return {"fit": fit, "errors": errors}


if __name__ == "__main__":
    main()
