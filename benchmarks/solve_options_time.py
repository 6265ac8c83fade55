"""What the one-frame solve's options cost and give up: the whole call's time and the accuracy of each choice.

For a city-scale user who does not need every part of the default solve: each variant of
:class:`vfactor.solve.SolveOptions` solves the same simulated vehicles (leave-one-model-out: each with the shape
model learnt without it, as ``vfactor eval`` does), with the keypoints' sigmas sized by the vehicle as
:func:`vfactor.solve.solve_vehicle` sizes them. Printed per variant: the median time of the whole call per vehicle
and its ratio to the default's (the variants take turns vehicle by vehicle, so that a busy machine slows them
alike), the mean rotation, translation and keypoint errors, the vehicles not solved, and where there are
covariances the pose NEES (mean, x 6) with the share under the chi-square 95 % bound.

- ``default``: ``SolveOptions()``;
- ``no covariance``: ``covariance=False`` (no marginals, sandwich or box sigmas);
- ``one start``: ``num_starts=1`` (no second start where the first solution explains few keypoints);
- ``no relabelling``: ``relabel_swaps=False`` (left/right swaps left to the robust loss);
- ``fixed sigmas``: ``estimate_noise=False`` (the detector's sigmas as given; the body type still chosen);
- ``lean``: the first three together.

Run: ``python benchmarks/solve_options_time.py [--level paper] [--seed 351] [--seeds 3] [--scenario library_2cam]``
(about a minute for three seeds of ``library_2cam``).
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import numpy as np

from vfactor.evaluation import NOISE_LEVELS, noise_variant, solve_held_out
from vfactor.graph import observations_from_detections, resized_observations
from vfactor.metrics import nees_summary, pose_errors, pose_nees
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions

VARIANTS = {
    "default": {},
    "no covariance": {"covariance": False},
    "one start": {"num_starts": 1},
    "no relabelling": {"relabel_swaps": False},
    "fixed sigmas": {"estimate_noise": False},
    "lean": {"covariance": False, "num_starts": 1, "relabel_swaps": False},
}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="library_2cam")
    parser.add_argument("--level", default="paper", choices=list(NOISE_LEVELS))
    parser.add_argument("--seed", type=int, default=351)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args(argv)
    scenario = noise_variant(load_scenario(args.scenario), **NOISE_LEVELS[args.level])
    rows = {name: {"seconds": [], "errors": [], "nees": [], "failed": 0} for name in VARIANTS}
    vehicles = 0
    for seed in range(args.seed, args.seed + args.seeds):
        sim = simulate(scenario, seed=seed)
        for f, frame in enumerate(sim.scene.frames):
            for vid in frame.vehicle_ids():
                truth, detections = sim.truth[f][vid], frame.detections_of(vid)
                # untimed: the held-out shape and box models are built (then cached), and their priors make their
                # factors on first use, which the first variant would pay alone
                solve_held_out(observations_from_detections(detections, sim.scene.cameras), truth.preset)
                vehicles += 1
                for name, changes in VARIANTS.items():
                    options = SolveOptions(**changes)
                    t0 = time.perf_counter()  # the whole call as solve_vehicle makes it, the observations included
                    obs = observations_from_detections(detections, sim.scene.cameras, options.graph)
                    result = solve_held_out(obs, truth.preset, options, vid, resize=partial(
                        resized_observations, detections, sim.scene.cameras, options.graph))
                    row = rows[name]
                    row["seconds"].append(time.perf_counter() - t0)
                    if not result.ok:
                        row["failed"] += 1
                        continue
                    row["errors"].append(pose_errors(result.world_T_vehicle, result.keypoints_world,
                                                     truth.world_T_vehicle, truth.keypoints_world))
                    if result.pose_covariance is not None:
                        row["nees"].append(pose_nees(result.world_T_vehicle, result.pose_covariance,
                                                     truth.world_T_vehicle))
    reference = np.median(rows["default"]["seconds"])
    print(f"{args.scenario}, {args.level} noise, seeds {args.seed}-{args.seed + args.seeds - 1}: {vehicles} vehicles, "
          "each held out of the shape model\n")
    print("| variant | ms per vehicle | vs default | rotation (deg) | translation (cm) | keypoint (cm) | not solved "
          "| pose NEES (x 6) / under chi2 95 % |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    out = {}
    for name, row in rows.items():
        median = float(np.median(row["seconds"]))
        mean = {key: float(np.mean([e[key] for e in row["errors"]]))
                for key in ("rotation_deg", "translation_cm", "mean_keypoint_cm")}
        nees = nees_summary(row["nees"], 6)
        consistency = f"{nees['ratio']:.2f}x / {100 * nees['under_95']:.1f} %" if nees["count"] else "-"
        print(f"| {name} | {1e3 * median:.2f} | {median / reference:.2f}x | {mean['rotation_deg']:.2f} | "
              f"{mean['translation_cm']:.2f} | {mean['mean_keypoint_cm']:.2f} | {row['failed']} | {consistency} |")
        out[name] = {"median_s": median, "ratio": median / reference, **mean, "failed": row["failed"]}
    return out


if __name__ == "__main__":
    main()
