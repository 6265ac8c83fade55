"""Benchmark: a long fixed-lag track, the dogleg throughout against the default (dogleg while young, then Gauss-Newton).

``long_track`` (one vehicle, a 1 s lag unless ``--lag``, the shape model held out of the vehicle), the online
(filtered) poses by fifths of the run: rotation and translation error against the simulation's truth, pose NEES
against 6 and the share under the chi2 95 % bound, and each run's seconds.

Run: ``python benchmarks/track_long_lag.py [--seed 0] [--frames 1000] [--lag 1.0]`` (about a minute for 1000 frames).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vfactor.evaluation import held_out_scene_model, pose_rows
from vfactor.metrics import CHI2_95
from vfactor.sim import simulate
from vfactor.track import TrackOptions, track_scene


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", type=int, default=1000)
    parser.add_argument("--lag", type=float, default=1.0)
    args = parser.parse_args(argv)
    sim = simulate("long_track", seed=args.seed, num_frames=args.frames)
    model = held_out_scene_model(sim)
    out = {}
    print(f"long_track seed {args.seed}, {args.frames} frames, lag {args.lag:g} s; online poses by fifths of the run:"
          " rotation deg / translation cm / pose NEES over 6 (share under the chi2 95 % bound)")
    for optimizer in ("dogleg", "auto"):
        t0 = time.perf_counter()
        run = track_scene(sim.scene, TrackOptions(optimizer=optimizer, lag=args.lag), prior=model)
        seconds = time.perf_counter() - t0
        rows = [r for r in pose_rows(sim, run.online) if "rotation_deg" in r]
        step = max(args.frames // 5, 1)
        cells = []
        for start in range(0, args.frames, step):
            part = [r for r in rows if start <= r["frame"] < start + step]
            nees = np.array([r["pose_nees"] for r in part if r.get("pose_nees") is not None])
            cells.append((float(np.mean([r["rotation_deg"] for r in part])),
                          float(np.mean([r["translation_cm"] for r in part])),
                          float(np.mean(nees) / 6), float(np.mean(nees < CHI2_95[6]))))
        out[optimizer] = {"seconds": seconds, "fifths": cells}
        print(f"{optimizer:7s} {seconds:6.1f} s  " + " | ".join(
            f"{r:.2f} / {t:.1f} / {n:.2f}x ({100 * u:.0f} %)" for r, t, n, u in cells))
    return out


if __name__ == "__main__":
    main()
