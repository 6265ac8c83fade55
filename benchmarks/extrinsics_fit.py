"""Accuracy: a rig's cameras fitted to its traffic (``vfactor fit-extrinsics``), on other traffic of the same rig.

Each draw: a survey that errs (``ExtrinsicError``: every camera off by ``--error DEG,M`` per axis, declared as its
``extrinsic_sigma``) gives the cameras of ``--traffic`` scenes of the rig (seeds ``seed .. seed + traffic - 1``; their
detections are the true cameras'); :func:`vfactor.extrinsics_fit.fit_extrinsics` fits the cameras to their vehicles.
A further scene (seed ``seed + traffic``: other vehicles, the same rig) is then solved one frame at a time and
tracked (iSAM2, smoothed) with the surveyed cameras, the fitted ones and the true ones. Printed per scenario:

* the cameras: mean rotation error (degrees) and position error (cm) against the true cameras, surveyed and fitted;
  the relative rotation of each pair (what vehicles seen by two cameras show); the fitted error's NEES against the
  fit's covariance (6 dof: consistent at 6, 95 % under 12.59);
* the later scene: one-frame and tracked translation errors (cm, the keypoints' centroid) per body type and per
  camera count, and the one-frame pose NEES (the fitted cameras carry the fit's sigma).

Every solve, the fit's included, takes the shape model learnt without any vehicle of the draw's scenes
(:func:`vfactor.evaluation.held_out_model`).

Run: ``python benchmarks/extrinsics_fit.py --scenario library_tracks --seed 400 --draws 8 [--traffic 2]
[--error 0.3,0.05] [--rounds 2] [--workers 2]``; ``--time``: what the fit costs against the one-frame
solves of its traffic (``--scenario``, ``--seed``, ``--traffic``).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor

import numpy as np

CHI2_6_95 = 12.5916


def _draw(unit: tuple) -> dict:
    """One draw: fit the cameras to ``traffic`` scenes of seed ``seed`` on, evaluate on the next seed's scene."""
    import gtsam

    from vfactor.evaluation import body_type_of, held_out_model
    from vfactor.extrinsics_fit import fit_extrinsics
    from vfactor.metrics import pose_nees
    from vfactor.sim import load_scenario, simulate
    from vfactor.sim.scenario import ExtrinsicError
    from vfactor.solve import SolveOptions, solve_scene
    from vfactor.track import TrackOptions, track_scene

    name, seed, traffic, rotation_deg, translation_m, rounds = unit
    scenario = dataclasses.replace(load_scenario(name), extrinsic_error=ExtrinsicError(rotation_deg, translation_m))
    true = dict(scenario.cameras)
    sims = [simulate(scenario, seed=seed + i) for i in range(traffic + 1)]  # the traffic fitted to, then the later
    later = sims[-1]
    model = held_out_model(*{v.preset for sim in sims for frame in sim.truth for v in frame.values()})
    surveyed = sims[0].scene.cameras
    fit = fit_extrinsics([dataclasses.replace(sim.scene, cameras=surveyed) for sim in sims[:-1]], rounds=rounds,
                         model=model)
    out = {"poses": fit.poses, "cameras": {}, "rows": [], "scale": fit.residual_scale}
    for label, cameras in (("surveyed", surveyed), ("fitted", fit.cameras)):
        rotation = [np.degrees(np.linalg.norm(gtsam.Rot3.Logmap(cameras[n].pose.rotation().between(
            true[n].pose.rotation())))) for n in true]
        position = [100 * np.linalg.norm(cameras[n].pose.translation() - true[n].pose.translation()) for n in true]
        relative = [np.degrees(np.linalg.norm(gtsam.Rot3.Logmap(
            cameras[a].pose.rotation().between(cameras[b].pose.rotation()).between(
                true[a].pose.rotation().between(true[b].pose.rotation())))))
            for a, b in itertools.combinations(sorted(true), 2)]
        out["cameras"][label] = (float(np.mean(rotation)), float(np.mean(position)), float(np.mean(relative)))
    out["nees"] = []
    for n, xi in fit.corrections.items():
        left = gtsam.Pose3.Logmap(surveyed[n].pose.inverse().compose(true[n].pose)) - xi
        out["nees"].append(float(left @ np.linalg.solve(fit.covariances[n], left)))
    for label, cameras in (("surveyed", surveyed), ("fitted", fit.cameras), ("true", true)):
        scene = dataclasses.replace(later.scene, cameras=cameras)
        frames = solve_scene(scene, SolveOptions(), prior=model)
        tracked = track_scene(scene, TrackOptions(covariance=False), prior=model).frames
        for f, (one, smoothed) in enumerate(zip(frames, tracked)):
            by_id = {v.id: v for v in smoothed.vehicles}
            for v in one.vehicles:
                truth = later.truth[f][v.id]
                row = {"cameras": label, "body_type": body_type_of(truth.preset),
                       "views": len({d.camera for d in later.scene.frames[f].detections_of(v.id)})}
                if v.ok:
                    row["frame_cm"] = 100 * float(np.linalg.norm(v.keypoints_world.mean(0)
                                                                 - truth.keypoints_world.mean(0)))
                    if v.pose_covariance is not None:
                        row["nees"] = pose_nees(v.world_T_vehicle, v.pose_covariance, truth.world_T_vehicle)
                t = by_id.get(v.id)
                if t is not None and t.ok:
                    row["track_cm"] = 100 * float(np.linalg.norm(t.keypoints_world.mean(0)
                                                                 - truth.keypoints_world.mean(0)))
                out["rows"].append(row)
    return out


def _time(name: str, seed: int, traffic: int, repeats: int = 2) -> None:
    """What the fit costs against the one-frame solves of the traffic it is fitted to (``vfactor solve`` of those
    scenes, without covariances), alternating in one run."""
    import time

    from vfactor.extrinsics_fit import fit_extrinsics
    from vfactor.sim import ExtrinsicError, load_scenario, simulate
    from vfactor.solve import SolveOptions, solve_scene

    scenario = dataclasses.replace(load_scenario(name), extrinsic_error=ExtrinsicError(0.3, 0.05))
    sims = [simulate(scenario, seed=seed + i) for i in range(traffic)]
    scenes = [dataclasses.replace(sim.scene, cameras=sims[0].scene.cameras) for sim in sims]
    solves, fits = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for scene in scenes:
            solve_scene(scene, SolveOptions(covariance=False))
        solves.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        fit = fit_extrinsics(scenes)
        fits.append(time.perf_counter() - t0)
    ratios = ", ".join(f"{f / s:.2f}x" for f, s in zip(fits, solves))
    print(f"{name} seeds {seed}-{seed + traffic - 1}, {fit.poses} vehicle poses: the one-frame solves "
          f"{', '.join(f'{s:.2f}' for s in solves)} s, fit_extrinsics {', '.join(f'{f:.2f}' for f in fits)} s: "
          f"{ratios}")


def _cell(rows, key: str) -> str:
    values = [r[key] for r in rows if key in r]
    return f"{np.mean(values):.1f}" if values else "-"


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="library_tracks")
    parser.add_argument("--seed", type=int, default=400)
    parser.add_argument("--draws", type=int, default=8)
    parser.add_argument("--traffic", type=int, default=2, help="scenes of traffic the cameras are fitted to")
    parser.add_argument("--error", default="0.3,0.05", help="the survey's error, DEG,M per camera axis")
    parser.add_argument("--rounds", type=int, default=2, help="fit_extrinsics' rounds")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--time", action="store_true",
                        help="time the fit against the one-frame solves of its traffic instead (seeds from --seed)")
    args = parser.parse_args(argv)
    if args.time:
        _time(args.scenario, args.seed, args.traffic)
        return {}
    rotation_deg, translation_m = (float(x) for x in args.error.split(","))
    step = args.traffic + 1
    units = [(args.scenario, args.seed + i * step, args.traffic, rotation_deg, translation_m, args.rounds)
             for i in range(args.draws)]
    with ProcessPoolExecutor(args.workers) as pool:
        draws = list(pool.map(_draw, units))
    print(f"{args.scenario}, survey off by {args.error} (deg, m) per camera axis, {args.draws} draws (seeds "
          f"{args.seed}-{args.seed + args.draws * step - 1}), cameras fitted to {args.traffic} scene(s) of traffic "
          f"({np.mean([d['poses'] for d in draws]):.0f} vehicle poses on average)\n")
    print("| cameras | rotation error (deg) | position error (cm) | relative rotation of a pair (deg) |\n"
          "| --- | --- | --- | --- |")
    for label in ("surveyed", "fitted"):
        r, p, q = np.mean([d["cameras"][label] for d in draws], axis=0)
        print(f"| {label} | {r:.2f} | {p:.1f} | {q:.2f} |")
    nees = np.concatenate([d["nees"] for d in draws])
    scales = [d["scale"] for d in draws]
    print(f"\nthe fitted cameras' error against the fit's covariance: NEES {nees.mean():.2f} (6 dof), "
          f"{100 * np.mean(nees < CHI2_6_95):.0f} % under {CHI2_6_95}, {len(nees)} cameras; the keypoints' residual "
          f"scale at the fit {np.mean(scales):.2f} (per draw {', '.join(f'{x:.2f}' for x in scales)})\n")
    rows = [r for d in draws for r in d["rows"]]
    groups = defaultdict(list)
    for r in rows:
        groups[("all", "")].append(r)
        groups[("body type", r["body_type"])].append(r)
        groups[("cameras", str(r["views"]))].append(r)
    print("| vehicles | n | one frame: surveyed / fitted / true cameras (cm) | tracked | one-frame pose NEES, "
          "surveyed / fitted / true (x 6; under the bound) |\n| --- | --- | --- | --- | --- |")
    for (kind, value), members in sorted(groups.items(), key=lambda kv: (kv[0][0] != "all", kv[0])):
        by = {label: [r for r in members if r["cameras"] == label] for label in ("surveyed", "fitted", "true")}
        nees_cells = []
        for label in ("surveyed", "fitted", "true"):
            values = np.array([r["nees"] for r in by[label] if "nees" in r])
            nees_cells.append(f"{values.mean() / 6:.2f}x ({100 * np.mean(values < CHI2_6_95):.0f} %)"
                              if len(values) else "-")
        print(f"| {kind} {value} | {len(by['true'])} | {' / '.join(_cell(by[l], 'frame_cm') for l in by)} | "
              f"{' / '.join(_cell(by[l], 'track_cm') for l in by)} | {' / '.join(nees_cells)} |")
    return {"draws": draws}


if __name__ == "__main__":
    main()
