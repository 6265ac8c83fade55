"""Benchmark: ``vfactor solve`` and ``vfactor track`` on a Dask cluster (docs/scaling.md), in one run.

Reports, on the ``city_intersection`` scene (4 cameras, 10 vehicles in view in
every frame; ``--frames``, default 2000):

* **throughput** of the whole command (``vfactor solve SCENE --out R --workers N``, ``vfactor track ... --lag 1``
  in a new process: cluster start, loading, the work, writing), with 1 and 2
  workers, and the speed-up (goal >= 1.7x on a 2-core machine); the result files
  of 1 and 2 workers must be byte-identical;
* **the scheduler's cost per unit**: the first ``--overhead-frames`` frames'
  vehicles solved in process and on a one-worker cluster (warm), the difference
  per vehicle against a one-vehicle solve (goal < 10 %), and the round trip of
  an empty task (one unit per task);
* **cold start**: a fresh process's import of vfactor, and its first one-vehicle
  solve of a scene file against the same process's next solves (goal <= 2x;
  the kernels are compiled ahead of time into vfactor._kernels, nothing is
  compiled or loaded by numba at run time). Alone: ``python -c "import
  benchmarks.scale_time as b; b.cold_start()"``.

Run: ``python benchmarks/scale_time.py [--frames 2000] [--what solve track] [--workers 1 2]``.
Use a quiet machine: the speed-up needs both cores.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vfactor.parallel import DaskEngine, InProcess
from vfactor.scene import save_scene
from vfactor.sim import simulate
from vfactor.solve import solve_scene

_COLD = """
import sys, time
t0 = time.perf_counter()
import vfactor
from vfactor.scene import load_scene
from vfactor.solve import solve_scene
t1 = time.perf_counter()
scene = load_scene(sys.argv[1])
frames = [type(scene)(scene.cameras, [f], scene.base_dir, scene.ground_plane) for f in scene.frames]
times = []
for one in frames:
    s = time.perf_counter(); solve_scene(one); times.append(time.perf_counter() - s)
again = []  # the first frame once more, warm: like for like
for _ in range(3):
    s = time.perf_counter(); solve_scene(frames[0]); again.append(time.perf_counter() - s)
loaded = [m for m in ("numba", "scipy.special") if m in sys.modules]
print(t1 - t0, *times, min(again), ",".join(loaded) or "-")
"""


def _noop(x):
    return x


def run_command(args: list[str]) -> float:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "vfactor", *args, "-q"], capture_output=True, text=True)
    if done.returncode not in (0, 3):
        raise RuntimeError(f"vfactor {' '.join(args)} failed ({done.returncode}): {done.stderr[-2000:]}")
    return time.perf_counter() - t0


def throughput(scene_file: Path, folder: Path, what: str, workers: list[int], vehicles: int) -> None:
    print(f"\nvfactor {what}{' --lag 1' if what == 'track' else ''} on {vehicles} vehicle-frames, whole command in "
          "a new process")
    print(f"{'workers':>8}{'seconds':>10}{'vehicles/s':>12}{'speed-up':>10}")
    base, first = None, None
    for n in workers:
        out = folder / f"{what}_{n}.json"
        extra = ["--lag", "1"] if what == "track" else []  # a long scene is tracked with a fixed lag (track_time.py)
        seconds = run_command([what, str(scene_file), "--out", str(out), "--workers", str(n), *extra])
        base = base or seconds
        print(f"{n:>8}{seconds:>10.1f}{vehicles / seconds:>12.1f}{base / seconds:>10.2f}")
        if first is None:
            first = out
        elif not filecmp.cmp(first, out, shallow=False):
            raise AssertionError(f"{out} differs from {first}")
    print(f"result files of {workers} workers identical: yes")


def overhead(scene, frames: int) -> None:
    part = type(scene)(scene.cameras, scene.frames[:frames], scene.base_dir, scene.ground_plane)
    units = sum(len(f.vehicle_ids()) for f in part.frames)
    with DaskEngine(workers=1) as engine:
        solve_scene(part, engine=engine)  # warm: the worker's caches, as in a long job
        t0 = time.perf_counter()
        serial = solve_scene(part, engine=InProcess())
        t_serial = time.perf_counter() - t0
        t0 = time.perf_counter()
        solve_scene(part, engine=engine)
        t_dask = time.perf_counter() - t0
        tasks = 200
        one_by_one = DaskEngine(client=engine.client, chunk=1, in_flight=8, warm=False)
        t0 = time.perf_counter()
        list(one_by_one.map(_noop, range(tasks)))
        t_noop = (time.perf_counter() - t0) / tasks
    per_vehicle = t_serial / units
    extra = (t_dask - t_serial) / units
    print(f"\nscheduler cost: {units} vehicles ({frames} frames), in process and on a warm one-worker cluster")
    print(f"  one-vehicle solve in process          {1e3 * per_vehicle:8.2f} ms")
    print(f"  on the cluster, per vehicle            {1e3 * t_dask / units:8.2f} ms")
    print(f"  the cluster's extra cost per vehicle   {1e3 * extra:8.2f} ms = {100 * extra / per_vehicle:5.1f} % of a solve")
    print(f"  round trip of an empty task (1 unit)   {1e3 * t_noop:8.2f} ms = {100 * t_noop / per_vehicle:5.1f} % of a solve")
    assert len(serial) == frames


def cold_start(repeats: int = 5, frames: int = 8) -> None:
    """A fresh process (``python -c _COLD scene.json``, as ``vfactor solve`` starts): import, then each frame's
    one-vehicle solve, then the first frame's again (warm, like for like); the medians over ``repeats`` processes."""
    print(f"\ncold start: {repeats} fresh processes, each imports vfactor, loads a scene file and solves its {frames} "
          "frames (one vehicle each)")
    with tempfile.TemporaryDirectory() as tmp:
        scene_file = Path(tmp) / "scene.json"
        save_scene(simulate("intersection_2cam", seed=0, num_frames=frames).scene, scene_file)
        runs, loaded = [], set()
        for _ in range(repeats):
            done = subprocess.run([sys.executable, "-c", _COLD, str(scene_file)], capture_output=True, text=True,
                                  check=True)
            *numbers, modules = done.stdout.split()
            runs.append([float(x) for x in numbers])
            loaded |= set(modules.split(",")) - {"-"}
    runs = np.array(runs)
    # warm: the third frame on; again: the first frame's vehicle solved again, warm
    imports, first, warm, again = runs[:, 0], runs[:, 1], np.median(runs[:, 3:-1], axis=1), runs[:, -1]
    print(f"  import vfactor (+ scene, solve)   {np.median(imports):8.3f} s")
    print(f"  first one-vehicle solve           {1e3 * np.median(first):8.2f} ms")
    print(f"  warm solves (median)              {1e3 * np.median(warm):8.2f} ms")
    print(f"  first / warm solve, per process   {', '.join(f'{r:.2f}' for r in first / warm)}x; median "
          f"{np.median(first / warm):.2f}x (goal <= 2x)")
    print(f"  first / the same vehicle warm     {', '.join(f'{r:.2f}' for r in first / again)}x; median "
          f"{np.median(first / again):.2f}x (issue 14: <= 1.5x)")
    print(f"  whole start (import + first)      {np.median(imports + first):8.3f} s")
    print(f"  loaded by then: {', '.join(sorted(loaded)) or 'neither numba nor scipy.special'}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--what", nargs="+", default=["solve", "track"], choices=("solve", "track"))
    parser.add_argument("--workers", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--overhead-frames", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    print(f"{os.cpu_count()} cores; city_intersection, {args.frames} frames, seed {args.seed}")
    cold_start()
    scene = simulate("city_intersection", seed=args.seed, num_frames=max(args.frames, args.overhead_frames)).scene
    overhead(scene, args.overhead_frames)
    scene.frames = scene.frames[:args.frames]
    vehicles = sum(len(f.vehicle_ids()) for f in scene.frames)
    with tempfile.TemporaryDirectory() as tmp:
        scene_file = Path(tmp) / "city.json"
        save_scene(scene, scene_file)
        for what in args.what:
            throughput(scene_file, Path(tmp), what, args.workers, vehicles)


if __name__ == "__main__":
    main()
