"""Benchmark: time per frame of iSAM2 tracking over a long track, with and without a fixed lag.

Reports, in one run on the same simulated frames:

* the mean time of ``Tracker.add_frame`` over the first and the last 50 frames
  of a long track, and their ratio (flat is ~1; goal <= 1.5 with the fixed lag);
* the per-frame cost per vehicle of tracking as a ratio against the one-frame
  batch solve of the same frames (``solve_observations``, the default settings
  without covariances, as the tracker computes its own), and against the
  default one-frame solve with covariances (what ``solve_vehicle`` costs; the
  tracker gives each pose its covariance too).

Run: ``python benchmarks/track_time.py [--frames 500] [--lag 1.0] [--lag-only]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vfactor.graph import observations_from_detections
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions, solve_observations
from vfactor.track import Tracker, TrackOptions


def time_tracker(scene, options: TrackOptions) -> np.ndarray:
    tracker = Tracker(scene.cameras, options)
    times = []
    for i, frame in enumerate(scene.frames):
        t0 = time.perf_counter()
        tracker.add_frame(frame, i)
        times.append(time.perf_counter() - t0)
    return np.array(times)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="long_track")
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--lag", type=float, default=1.0)
    parser.add_argument("--window", type=int, default=50)
    parser.add_argument("--lag-only", action="store_true",
                        help="time the fixed lag only (the full iSAM2 grows with the track: minutes at 500 frames)")
    args = parser.parse_args(argv)

    sim = simulate(load_scenario(args.scenario), num_frames=args.frames)
    scene = sim.scene
    vehicles_per_frame = np.array([len(f.vehicle_ids()) for f in scene.frames])
    w = args.window
    rows = {}
    trackers = [("fixed lag %.1f s" % args.lag, TrackOptions(lag=args.lag)), ("no lag (full iSAM2)", TrackOptions())]
    for label, options in trackers[:1] if args.lag_only else trackers:
        per_frame = time_tracker(scene, options)
        per_vehicle = per_frame / np.maximum(vehicles_per_frame, 1)
        rows[label] = (per_vehicle[:w].mean(), per_vehicle[-w:].mean(), per_vehicle.mean())
    references = {}
    for name, solve_options in (("without covariances", SolveOptions(covariance=False)),
                                ("default, with covariances (solve_vehicle)", SolveOptions())):
        one_frame = []
        for frame in scene.frames[:: max(1, len(scene.frames) // 100)]:
            for vid in frame.vehicle_ids():
                obs = observations_from_detections(frame.detections_of(vid), scene.cameras, solve_options.graph)
                t0 = time.perf_counter()
                solve_observations(obs, solve_options, vid)
                one_frame.append(time.perf_counter() - t0)
        references[name] = float(np.mean(one_frame))
    reference = references["without covariances"]
    print(f"{args.scenario}: {len(scene.frames)} frames, {vehicles_per_frame.mean():.1f} vehicles per frame, "
          f"{len(scene.cameras)} cameras")
    print(f"{'tracker':<24}{'first %d ms' % w:>14}{'last %d ms' % w:>14}{'last/first':>12}{'mean ms':>10}{'vs one-frame solve':>20}")
    for label, (first, last, mean) in rows.items():
        print(f"{label:<24}{1e3 * first:>14.2f}{1e3 * last:>14.2f}{last / first:>12.2f}{1e3 * mean:>10.2f}"
              f"{mean / reference:>20.2f}")
    print(f"one-frame batch solve (reference): {1e3 * reference:.2f} ms per vehicle")
    full = references["default, with covariances (solve_vehicle)"]
    for label, (_, _, mean) in rows.items():
        print(f"{label}: {mean / full:.2f}x the default one-frame solve with covariances ({1e3 * full:.2f} ms), "
              "what solve_vehicle costs")
    return {"rows": rows, "one_frame_s": reference, "one_frame_covariance_s": full}


if __name__ == "__main__":
    main()
