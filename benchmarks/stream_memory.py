"""Benchmark: a live stream of many frames (``vfactor track -``) holds its memory and its time per frame flat.

The stream is the ``long_track`` scene (two vehicles lapping a loop, two
cameras, 500 frames at 10 Hz) played again and again, each replay later in
time and with new vehicle ids (``v1.k``), so that tracks end and new ones
start, as at a real intersection. Every frame goes through the whole stream
path: a JSON line parsed, validated, tracked (fixed lag), the result line
serialised. Prints the resident memory and the mean time per frame over the
first and the last tenth of the frames and their ratios (flat is ~1; goal <= 1.2
for memory).

Run: ``python benchmarks/stream_memory.py [--frames 100000] [--lag 1.0]``.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from vfactor.scene import scene_to_dict
from vfactor.sim import simulate
from vfactor.solve import SolveOptions
from vfactor.stream import track_stream
from vfactor.track import TrackOptions


def rss_mib() -> float:
    """This process's resident memory (MiB), from /proc."""
    with open(f"/proc/{os.getpid()}/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def stream_lines(frames: int, seed: int = 0):
    """The header line, then ``frames`` frame lines of ``long_track`` replayed with new ids and later times."""
    data = scene_to_dict(simulate("long_track", seed=seed).scene)
    recorded = data.pop("frames")
    yield json.dumps(data) + "\n"
    period = recorded[-1]["t"] + 5.0  # a 5 s pause between replays: the old tracks end (max gap 10 s: forgotten later)
    for n in range(frames):
        k, frame = divmod(n, len(recorded))
        frame = recorded[frame]
        detections = [dict(d, vehicle=f"{d['vehicle']}.{k}") for d in frame["detections"]]
        yield json.dumps({**frame, "t": frame["t"] + k * period, "detections": detections}) + "\n"


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--lag", type=float, default=1.0)
    args = parser.parse_args(argv)
    options = TrackOptions(solve=SolveOptions(covariance=False), lag=args.lag)
    tenth = max(args.frames // 10, 1)
    times, memory, unsolved = [], [], 0
    t_start = time.perf_counter()
    last = t_start
    for item in track_stream(stream_lines(args.frames), options):
        json.dumps(item.to_dict())  # the output line, as the command writes it
        unsolved += sum(not v.ok for v in item.result.vehicles) if item.result else 1
        now = time.perf_counter()
        times.append(now - last)
        last = now
        if item.frame % 1000 == 0 or item.frame == args.frames - 1:
            memory.append((item.frame, rss_mib()))
    times = np.array(times)
    mem = np.array(memory)
    first_mem = mem[mem[:, 0] < tenth, 1].mean()
    last_mem = mem[mem[:, 0] >= args.frames - tenth, 1].mean()
    first_ms, last_ms = 1e3 * times[:tenth].mean(), 1e3 * times[-tenth:].mean()
    print(f"stream of {args.frames} frames (long_track replayed with new ids every 500 frames), lag {args.lag:g} s; "
          f"{time.perf_counter() - t_start:.0f} s in all, {unsolved} vehicles not solved")
    print(f"{'':24}{'first tenth':>14}{'last tenth':>14}{'last/first':>12}")
    print(f"{'resident memory (MiB)':24}{first_mem:14.1f}{last_mem:14.1f}{last_mem / first_mem:12.2f}")
    print(f"{'time per frame (ms)':24}{first_ms:14.2f}{last_ms:14.2f}{last_ms / first_ms:12.2f}")
    print("memory (MiB) every 10 %: " + ", ".join(f"{m:.0f}" for m in np.interp(
        np.linspace(0, args.frames - 1, 11), mem[:, 0], mem[:, 1])))
    return {"memory_ratio": last_mem / first_mem, "time_ratio": last_ms / first_ms}


if __name__ == "__main__":
    main()
