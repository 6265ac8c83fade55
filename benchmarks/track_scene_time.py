"""Benchmark: whole-call time of ``track_scene`` (without and with a fixed lag) and ``smooth_scene`` on a few scenes.

What a user pays for tracking a scene file (``vfactor track``, ``vfactor track --lag``, ``vfactor track --batch``):
every frame tracked, every pose's final estimate and covariance. Run the same command on two versions of the code
one after the other, several times, and compare the totals (the machines here are shared and noisy).

Run: ``python benchmarks/track_scene_time.py [SCENARIO:SEED ...]`` (default: ``library_tracks:150 tracks_3veh:150
library_tracks_2cam:150``: three cameras with a road plane, and two without).
"""

from __future__ import annotations

import argparse
import time

from vfactor.sim import load_scenario, simulate
from vfactor.track import TrackOptions, smooth_scene, track_scene


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["library_tracks:150", "tracks_3veh:150", "library_tracks_2cam:150"],
                        help="SCENARIO:SEED of each simulated scene")
    args = parser.parse_args(argv)
    sims = [simulate(load_scenario(spec.split(":")[0]), seed=int(spec.split(":")[1])) for spec in args.scenes]
    seconds = {}
    for lag in (None, 1.0):
        t0 = time.perf_counter()
        for sim in sims:
            track_scene(sim.scene, TrackOptions(lag=lag))
        seconds[f"track_scene, lag {lag}"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    for sim in sims:
        smooth_scene(sim.scene, TrackOptions())
    seconds["smooth_scene"] = time.perf_counter() - t0
    print(f"{len(sims)} scenes ({', '.join(args.scenes)}): " + "; ".join(f"{k} {v:.2f} s" for k, v in seconds.items()))
    return seconds


if __name__ == "__main__":
    main()
