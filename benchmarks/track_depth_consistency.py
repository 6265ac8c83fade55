"""Consistency: where a track's pose covariances are too narrow, split along each camera's ray (depth) and across it.

Each scene is tracked (``track_scene``: the final, smoothed iSAM2 estimates) and batch-smoothed (``smooth_scene``)
with the shape model held out (:func:`vfactor.evaluation.held_out_scene_model`). For every pose seen by one camera,
its translation error is split into the component along that camera's ray and the two across it, each whitened by
the same block of the pose's covariance (:func:`vfactor.metrics.ray_nees`): a consistent covariance gives a mean of 1
along the ray (chi2 with 1 dof: median 0.45, 5 % beyond 3.84) and 1 across it (2 dof, as a ratio to 2). Poses seen
by two or more cameras get their pose NEES (ratio to 6) for comparison.

Run: ``python benchmarks/track_depth_consistency.py [--scenes SCENARIO:SEED ...] [--gaussian-only]
[--motion FIELD=VALUE ...] [--noise FIELD=VALUE ...]``; defaults
``library_tracks_2cam`` seeds 90-95 and ``tracks_3veh`` seeds 80-85 (about 5 s a scene); ``--gaussian-only``
simulates the keypoints without outliers, left/right swaps or misses; ``--motion`` sets the motion model's
fields (:class:`vfactor.factors.motion.MotionModel`), ``--noise`` the simulated keypoints' (:class:`vfactor.sim.noise.NoiseModel`,
pairs as ``a,b``).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from vfactor.evaluation import held_out_scene_model, noise_variant  # noqa: E402
from vfactor.factors.motion import MotionModel  # noqa: E402
from vfactor.metrics import CHI2_95, pose_nees, ray_nees  # noqa: E402
from vfactor.sim import load_scenario, simulate  # noqa: E402
from vfactor.track import TrackOptions, smooth_scene, track_scene  # noqa: E402

DEFAULT_SCENES = ([f"library_tracks_2cam:{s}" for s in range(90, 96)] + [f"tracks_3veh:{s}" for s in range(80, 86)])


def scene_rows(spec: str, noise: dict | None = None, options: TrackOptions = TrackOptions()) -> dict[str, list[tuple]]:
    """Method -> rows ``(cameras, along m, along z2, across z2, pose NEES)`` of every pose with a covariance;
    ``noise``: :class:`~vfactor.sim.noise.NoiseModel` fields changed in the scenario."""
    scenario, seed = spec.split(":")
    scenario = load_scenario(scenario)
    if noise:
        scenario = noise_variant(scenario, **noise)
    sim = simulate(scenario, seed=int(seed))
    model = held_out_scene_model(sim)
    methods = {"isam2": track_scene(sim.scene, options, prior=model).frames,
               "batch": smooth_scene(sim.scene, options, prior=model)}
    out = {}
    for method, frames in methods.items():
        rows = out.setdefault(method, [])
        for f, frame in enumerate(frames):
            for v in frame.vehicles:
                if not v.ok or v.pose_covariance is None:
                    continue
                truth = sim.truth[f][v.id].world_T_vehicle
                cameras = sorted({d.camera for d in sim.scene.frames[f].detections if d.vehicle == v.id})
                nees = pose_nees(v.world_T_vehicle, v.pose_covariance, truth)
                if len(cameras) == 1:
                    camera = sim.scene.cameras[cameras[0]].center
                    rows.append((1, *ray_nees(v.world_T_vehicle, v.pose_covariance, truth, camera), nees))
                else:
                    rows.append((len(cameras), np.nan, np.nan, np.nan, nees))
    return out


def table(rows: dict[str, list[tuple]]) -> str:
    lines = ["| method | one-camera poses | along the ray: mean abs error (cm) | along: whitened square mean / median "
             "(consistent 1 / 0.45) | along: beyond chi2 95 % (5 %) | across: ratio to 2 dof | pose NEES, one camera "
             "| pose NEES, two or more cameras |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for method, mine in rows.items():
        r = np.array(mine, dtype=float)
        one, more = r[r[:, 0] == 1], r[r[:, 0] > 1]
        lines.append(
            f"| {method} | {len(one)} | {100 * np.abs(one[:, 1]).mean():.1f} | {one[:, 2].mean():.2f} / "
            f"{np.median(one[:, 2]):.2f} | {100 * np.mean(one[:, 2] > CHI2_95[1]):.0f} % | {one[:, 3].mean() / 2:.2f}x "
            f"| {one[:, 4].mean() / 6:.2f}x | {more[:, 4].mean() / 6:.2f}x ({len(more)}) |")
    return "\n".join(lines)


def main(argv=None) -> dict[str, list[tuple]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=DEFAULT_SCENES, metavar="SCENARIO:SEED")
    parser.add_argument("--gaussian-only", action="store_true")
    parser.add_argument("--motion", nargs="+", default=[], metavar="FIELD=VALUE",
                        help="motion model settings (vfactor.factors.motion.MotionModel), e.g. sigma_acceleration=4")
    parser.add_argument("--noise", nargs="+", default=[], metavar="FIELD=VALUE",
                        help="keypoint noise settings (vfactor.sim.noise.NoiseModel), e.g. relative_sigma=0.003 "
                             "confidence_visible=1,1")
    args = parser.parse_args(argv)
    try:
        motion = MotionModel(**{k: float(v) for k, v in (item.split("=", 1) for item in args.motion)})
    except (TypeError, ValueError) as exc:
        parser.error(f"--motion: expected FIELD=NUMBER with FIELD a MotionModel field ({exc})")
    noise = {"outlier_rate": 0.0, "swap_rate": 0.0, "missing_rate": 0.0} if args.gaussian_only else {}
    try:
        for item in args.noise:
            field, value = item.split("=", 1)
            numbers = tuple(float(x) for x in value.split(","))
            noise[field] = numbers[0] if len(numbers) == 1 else numbers
        noise_variant(load_scenario(args.scenes[0].split(":")[0]), **noise)  # unknown fields fail here, not later
    except (TypeError, ValueError) as exc:
        parser.error(f"--noise: expected FIELD=NUMBER[,NUMBER] with FIELD a NoiseModel field ({exc})")
    options = TrackOptions(motion=motion)
    rows: dict[str, list[tuple]] = {}
    for spec in args.scenes:
        for method, mine in scene_rows(spec, noise, options).items():
            rows.setdefault(method, []).extend(mine)
        print(f"  {spec}", flush=True)
    print(f"\n{len(args.scenes)} scenes{', Gaussian pixel noise only' if args.gaussian_only else ''}"
          f"{', noise ' + ' '.join(args.noise) if args.noise else ''}"
          f"{', motion ' + ' '.join(args.motion) if args.motion else ''}\n")
    print(table(rows))
    return rows


if __name__ == "__main__":
    main()
