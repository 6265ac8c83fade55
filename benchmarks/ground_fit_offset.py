"""Accuracy: the road plane fitted to a rig's traffic (``vfactor fit-ground``) with one hub height for every vehicle
and with each vehicle's body type's wheel radius.

Each scene of a calibration set is tracked (``track_scene``, the shape model held out,
:func:`vfactor.evaluation.held_out_scene_model`); the plane is fitted to all their tracks
(:func:`vfactor.ground_fit.fit_ground_plane`) both ways and printed against the simulator's road (z = 0): its
tilt (degrees) and its offset along the normal (cm; above the road where positive).

Run: ``python benchmarks/ground_fit_offset.py [--sets SET ...]``, each SET ``scenario:seed,scenario:seed,...``
(default: the two-camera rig's calibration sets of ``benchmarks/ground_fit_accuracy.py`` at seeds 20 and 21, and
two scenes of ``library_bus_tracks_2cam``; about 6 s).
"""

from __future__ import annotations

import argparse

from vfactor.evaluation import held_out_scene_model
from vfactor.graph import DEFAULT_HUB_HEIGHT
from vfactor.ground_fit import fit_ground_plane
from vfactor.sim import load_scenario, simulate
from vfactor.track import TrackOptions, track_scene

SETS = ("library_tracks_2cam:20,tracks_3veh:20", "library_tracks_2cam:21,tracks_3veh:21",
        "library_bus_tracks_2cam:45,library_bus_tracks_2cam:46")


def main(argv=None) -> list[tuple[str, str, float, float]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", nargs="+", default=list(SETS), metavar="SET")
    args = parser.parse_args(argv)
    rows = []
    print(f"| traffic | one hub height ({DEFAULT_HUB_HEIGHT} m) | each type's wheel radius |\n| --- | --- | --- |")
    for spec in args.sets:
        frames = []
        for scene in spec.split(","):
            scenario, seed = scene.split(":")
            sim = simulate(load_scenario(scenario), seed=int(seed))
            frames += track_scene(sim.scene, TrackOptions(covariance=False), prior=held_out_scene_model(sim)).frames
        cells = []
        for name, hub_height in (("one", DEFAULT_HUB_HEIGHT), ("each", None)):
            fit = fit_ground_plane(frames, hub_height)
            rows.append((spec, name, fit.tilt_deg, 100 * fit.plane.offset))
            cells.append(f"{fit.tilt_deg:.2f} deg, {100 * fit.plane.offset:+.1f} cm")
        print(f"| {spec} | {' | '.join(cells)} |", flush=True)
    return rows


if __name__ == "__main__":
    main()
