"""Accuracy of the shape-prior choices on held-out vehicles: which prior the second solve uses.

Every variant solves the same simulated vehicles (leave-one-model-out: a
library vehicle or PASCAL3D+ car is never in the priors it is solved with),
with the estimated noise scale:

- ``default``: the body-type model, the moment-matched mixture of the types'
  priors and the pooled prior (``ShapeModel.pooled_probability = 1/7``);
- ``types_only``: the same without the pooled component;
- ``pooled``: the pooled prior alone, no body types;
- ``car_prior``: the paper's PASCAL3D+ car prior and car HWC bounds (not held
  out: it is learnt from the PASCAL3D+ cars it solves), fixed sigmas: vfactor
  before issue 10.

Run: ``python benchmarks/prior_ablation.py [--scenario library_2cam] [--level paper] [--seed 1]``.
Prints the mean keypoint error (cm) per body type.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from vfactor.evaluation import NOISE_LEVELS, body_type_of, held_out_model, noise_variant
from vfactor.graph import observations_from_detections
from vfactor.metrics import pose_errors
from vfactor.shape_model import car_hwc_bounds, default_shape_prior
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions, solve_observations


def variants(model):
    estimated, fixed = SolveOptions(covariance=False), SolveOptions(covariance=False, estimate_noise=False)
    return {
        "default": (estimated, model, model.bounds),
        "types_only": (estimated, dataclasses.replace(model, pooled_probability=0.0, _variants={}), model.bounds),
        "pooled": (estimated, model.pooled, model.bounds),
        "car_prior": (fixed, default_shape_prior(), car_hwc_bounds()),
    }


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="library_2cam")
    parser.add_argument("--level", default="paper", choices=list(NOISE_LEVELS))
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--frames", type=int)
    args = parser.parse_args(argv)
    sim = simulate(noise_variant(load_scenario(args.scenario), **NOISE_LEVELS[args.level]), seed=args.seed,
                   num_frames=args.frames)
    errors: dict[str, dict[str, list[float]]] = {}
    for f, frame in enumerate(sim.scene.frames):
        for vid in frame.vehicle_ids():
            truth = sim.truth[f][vid]
            obs = observations_from_detections(frame.detections_of(vid), sim.scene.cameras)
            for name, (options, prior, bounds) in variants(held_out_model(truth.preset)).items():
                result = solve_observations(obs, options, vid, prior, bounds)
                if result.ok:
                    e = pose_errors(result.world_T_vehicle, result.keypoints_world, truth.world_T_vehicle,
                                    truth.keypoints_world)
                    errors.setdefault(name, {}).setdefault(body_type_of(truth.preset), []).append(e["mean_keypoint_cm"])
    types = sorted({t for rows in errors.values() for t in rows})
    print(f"{args.scenario}, {args.level} noise, seed {args.seed}: mean keypoint error (cm)")
    print(f"{'variant':<12}" + "".join(f"{t:>11}" for t in types) + f"{'all':>9}")
    for name, rows in errors.items():
        print(f"{name:<12}" + "".join(f"{np.mean(rows.get(t, [np.nan])):>11.2f}" for t in types)
              + f"{np.mean(sum(rows.values(), [])):>9.2f}")
    return errors


if __name__ == "__main__":
    main()
