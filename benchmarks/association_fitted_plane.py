"""Accuracy: the association of a scene without a road plane, with the plane fitted to its own traffic (as
``vfactor fit-ground`` fits it: associated and tracked first), and with the true plane.

The scene is ``association_3cam_bus`` (buses entering and leaving one camera's view; docs/scenarios.md) anonymised
as ``vfactor eval association`` anonymises it, its plane removed. Each way the scene is associated and tracked, and
CLEAR-MOT scored against the truth (2 m gate).

Run: ``python benchmarks/association_fitted_plane.py [--scenario S] [--seed N]`` (default association_3cam_bus seed
6; about 3.5 min on 2 cores).
"""

from __future__ import annotations

import argparse
import dataclasses
import time


def main(argv=None) -> dict:
    from vfactor.association import associate_scene
    from vfactor.association.evaluate import DEFAULT_NOISE
    from vfactor.association_metrics import clear_mot, positions_from_results, truth_positions
    from vfactor.ground_fit import fit_ground_plane
    from vfactor.sim import anonymise, load_scenario, simulate
    from vfactor.track import TrackOptions, track_scene

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="association_3cam_bus")
    parser.add_argument("--seed", type=int, default=6)
    args = parser.parse_args(argv)
    sim = simulate(load_scenario(args.scenario), seed=args.seed)
    anon = anonymise(sim, seed=args.seed, **DEFAULT_NOISE)
    bare = dataclasses.replace(anon.scene, ground_plane=None)
    truth = truth_positions(sim.truth)
    scores = {}

    def run(scene, name):
        t0 = time.perf_counter()
        tracked = track_scene(associate_scene(scene).scene, TrackOptions(covariance=False)).frames
        scores[name] = clear_mot(truth, positions_from_results(tracked), 2.0)
        m = scores[name]
        print(f"| {name} | {m['mota']:.3f} | {m['idf1']:.3f} | {m['num_switches']:.0f} | "
              f"{time.perf_counter() - t0:.0f} s |", flush=True)
        return tracked

    print(f"{args.scenario} seed {args.seed}\n\n| road plane | MOTA | IDF1 | ID switches | time |\n"
          "| --- | --- | --- | --- | --- |")
    fit = fit_ground_plane(run(bare, "none"))
    run(dataclasses.replace(bare, ground_plane=fit.plane), f"fitted to its tracks ({fit.tilt_deg:.2f} deg, "
                                                          f"{100 * fit.plane.offset:+.1f} cm)")
    run(anon.scene, "true")
    return scores


if __name__ == "__main__":
    main()
