"""Benchmark: the association's cost per frame against solving the same frame with the true ids.

Scenes: the packaged ``intersection_multi`` rig (three pole cameras at the
corners of an intersection) with 1, 10 and 30 vehicles drawn at once in a box
of road around its centre (more vehicles, a larger box: about 30 m^2 of road
per vehicle), paper-like noise. Per frame the run times, in the same run:
``associate_frame`` (every detection's vehicle unknown); ``solve_frame`` of
the frame so associated (together, what ``vfactor solve`` pays for a frame
without ids); and ``solve_frame`` with the true ids (what the user pays
without association). It prints their medians, the ratio of the association
and of the whole call to the solve with the true ids, and the pairwise
precision and recall of the grouping.

Run: ``python benchmarks/association_time.py [--frames 5] [--counts 1,10,30]``.

With ``--workers N`` it times instead what a whole scene's association
(``associate_scene``) costs in one process and with its frames' pair tests on
N Dask workers (a local cluster, started and warmed before the clock), in
turns (``--rounds``), on the scene of ``--counts`` vehicles (the first count)
and ``--frames`` frames without the cameras' track ids (each frame's whole
association on the workers), and on a fresh ``association_3cam`` scene (13
vehicles driving through three cameras' views, the cameras' own track ids as
hints: the grouping in this process; ``--scene-seed``), checking that both
give the same association.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import time

import numpy as np

from vfactor.association import associate_frame
from vfactor.observations import UNASSIGNED, Frame
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions, solve_frame


def scene_with(count: int, frames: int, seed: int):
    base = load_scenario("intersection_multi")
    half = max(5.0, math.sqrt(30.0 * count) / 2)
    scenario = dataclasses.replace(base, vehicles_per_frame=count, region=((-half, half), (-half, half)),
                                   require_visible="any", min_gap=0.5)
    return simulate(scenario, seed=seed, num_frames=frames)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--counts", default="1,10,30")
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--workers", type=int, default=0, help="time associate_scene on this many Dask workers")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--scene-seed", type=int, default=57)
    args = parser.parse_args()
    if args.workers:
        scene_throughput(int(args.counts.split(",")[0]), args.frames, args.seed, args.scene_seed, args.workers,
                         args.rounds)
        return
    print("| vehicles | detections per frame | association (s/frame) | solve with true ids (s/frame) | association "
          "/ solve | whole call (association + solve) / solve | pair precision | pair recall |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for count in (int(c) for c in args.counts.split(",")):
        sim = scene_with(count, args.frames, args.seed)
        t_assoc, t_solve, t_whole, tp, fp, fn, dets = [], [], [], 0, 0, 0, []
        for frame in sim.scene.frames:
            truth = [d.vehicle for d in frame.detections]
            anonymous = Frame(frame.t, [dataclasses.replace(d, vehicle=UNASSIGNED) for d in frame.detections])
            t0 = time.perf_counter()
            found = associate_frame(anonymous, sim.scene.cameras)
            t_assoc.append(time.perf_counter() - t0)
            group = {j: g for g, members in enumerate(found.groups) for j in members}
            associated = Frame(frame.t, [dataclasses.replace(d, vehicle=f"a{group[j]}")
                                         for j, d in enumerate(anonymous.detections)])
            t0 = time.perf_counter()
            solve_frame(associated, sim.scene.cameras, SolveOptions())
            t_whole.append(t_assoc[-1] + time.perf_counter() - t0)
            t0 = time.perf_counter()
            solve_frame(frame, sim.scene.cameras, SolveOptions())
            t_solve.append(time.perf_counter() - t0)
            for i, j in itertools.combinations(range(len(truth)), 2):
                if frame.detections[i].camera != frame.detections[j].camera:
                    same, together = truth[i] == truth[j], group[i] == group[j]
                    tp, fp, fn = tp + (same and together), fp + (together and not same), fn + (same and not together)
            dets.append(len(truth))
        a, s, w = float(np.median(t_assoc)), float(np.median(t_solve)), float(np.median(t_whole))
        print(f"| {count} | {np.mean(dets):.0f} | {a:.2f} | {s:.2f} | {a / s:.2f}x | {w / s:.2f}x | "
              f"{tp / max(tp + fp, 1):.3f} | {tp / max(tp + fn, 1):.3f} |", flush=True)


def scene_throughput(count: int, frames: int, seed: int, scene_seed: int, workers: int, rounds: int) -> None:
    """``associate_scene`` in one process and with its pair tests on ``workers`` Dask workers, in turns."""
    from vfactor.association import associate_scene
    from vfactor.parallel import DaskEngine
    from vfactor.sim import anonymise

    scenes = {f"{count} vehicles a frame, {frames} frames (seed {seed}), no track ids": anonymise(
                  scene_with(count, frames, seed), seed=seed, keep_tracks=False).scene,
              f"association_3cam seed {scene_seed} (13 vehicles, track ids)": anonymise(
                  simulate("association_3cam", seed=scene_seed), seed=scene_seed).scene}
    print(f"| scene | frames | one process (s) | {workers} workers (s) | speed-up |")
    print("| --- | --- | --- | --- | --- |")
    with DaskEngine(workers=workers) as engine:
        list(engine.map(_noop, range(4 * workers)))  # the workers up and warm before the clock
        for name, scene in scenes.items():
            serial, parallel = [], []
            for _ in range(rounds):
                t0 = time.perf_counter()
                one = associate_scene(scene)
                serial.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                many = associate_scene(scene, engine=engine)
                parallel.append(time.perf_counter() - t0)
                assert many.groups == one.groups and many.left_out == one.left_out, "the association differs"
            print(f"| {name} | {len(scene.frames)} | {', '.join(f'{t:.1f}' for t in serial)} | "
                  f"{', '.join(f'{t:.1f}' for t in parallel)} | "
                  f"{', '.join(f'{a / b:.2f}x' for a, b in zip(serial, parallel))} |", flush=True)


def _noop(x):
    return x


if __name__ == "__main__":
    main()
