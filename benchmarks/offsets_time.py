"""Benchmark: what the detector pose offsets cost a track (``TrackOptions(detector_offsets=True)``).

Renders a track scenario and finds its keypoints with the shipped network once
(its detections carry the ``shape_sigma`` the offsets need; the simulator's do
not), then times the whole ``track_scene`` call (iSAM2, and with a fixed lag)
and ``smooth_scene`` with the offsets off and on, alternating, ``--repeats``
times each; prints the median CPU time per pose and the ratio on/off measured
in the same run. Needs the ``net`` and ``render`` extras.

Run: ``python benchmarks/offsets_time.py [--scenario tracks_3cam] [--seed 0] [--repeats 3] [--lag 0.5]``.
"""

from __future__ import annotations

import argparse
import statistics
import time

from vfactor.net.end_to_end import render_and_detect
from vfactor.track import TrackOptions, smooth_scene, track_scene


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="tracks_3cam")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--lag", type=float, default=0.5)
    args = parser.parse_args(argv)

    _, _, scene, _ = render_and_detect(args.scenario, args.seed)
    poses = sum(len(frame.vehicle_ids()) for frame in scene.frames)
    runs = {
        "isam2": lambda on: track_scene(scene, TrackOptions(detector_offsets=on)),
        f"lag {args.lag} s": lambda on: track_scene(scene, TrackOptions(detector_offsets=on, lag=args.lag)),
        "batch": lambda on: smooth_scene(scene, TrackOptions(detector_offsets=on)),
    }
    out = {}
    print(f"{args.scenario} seed {args.seed}: {len(scene.cameras)} cameras, {poses} poses from the network's keypoints")
    print(f"{'tracker':12s} {'ms/pose off':>12s} {'on':>8s} {'ratio':>7s}")
    for name, run in runs.items():
        times = {False: [], True: []}
        for _ in range(args.repeats):
            for on in (False, True):
                t0 = time.process_time()
                run(on)
                times[on].append(time.process_time() - t0)
        off, on = (1000 * statistics.median(times[k]) / poses for k in (False, True))
        out[name] = (off, on, on / off)
        print(f"{name:12s} {off:12.1f} {on:8.1f} {on / off:6.2f}x")
    return out


if __name__ == "__main__":
    main()
