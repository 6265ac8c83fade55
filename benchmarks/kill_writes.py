"""kill -9 during result writes: a previous good result file is never replaced by a broken one.

Simulates a scene, writes a first good result with ``vfactor solve``, then runs
``vfactor solve SCENE --out RESULT`` again ``--runs`` times and kills each run
with SIGKILL: the odd runs at a seeded random moment of the whole run, the
even ones at a seeded random moment of the write itself (the kill waits for
the temporary file beside the result to appear, then up to 30 ms more). After
every kill the result file must still load with ``vfactor.load_results`` (the
old one or the new one, never a truncated or empty file). A run killed during
the write leaves its temporary file (``.result.json.*.tmp``: SIGKILL allows no
clean-up); the next write does not depend on it.

Run: ``python benchmarks/kill_writes.py [--runs 20] [--frames 300] [--seed 0]``.
Prints one line per run and a summary; exits 1 if any result was broken.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vfactor.scene import load_results
from vfactor.sim import simulate, write_simulation


def solve_command(scene: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "vfactor", "solve", str(scene), "--out", str(out), "--quiet"]


def run_and_kill(command: list[str], after: float, folder: Path | None = None) -> tuple[int | None, float, bool]:
    """Starts ``command`` and kills it with SIGKILL (if still running).

    Args:
        after: seconds after the start; with ``folder``, seconds after a
            temporary result file first appears in it.

    Returns:
        (return code, seconds run, whether a temporary file existed at the kill).
    """
    t0 = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    before = set(folder.glob(".*.tmp")) if folder is not None else set()
    if folder is not None:
        while process.poll() is None and not set(folder.glob(".*.tmp")) - before:
            time.sleep(0.0005)
    try:
        process.wait(timeout=after)
    except subprocess.TimeoutExpired:
        writing = folder is not None and bool(set(folder.glob(".*.tmp")) - before)
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        return process.returncode, time.perf_counter() - t0, writing
    return process.returncode, time.perf_counter() - t0, False


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--frames", type=int, default=300, help="frames of the simulated scene (a larger result)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    broken = 0
    with tempfile.TemporaryDirectory(prefix="vfactor_kill_") as tmp:
        folder = Path(tmp)
        scene, out = folder / "scene.json", folder / "result.json"
        write_simulation(simulate("intersection_2cam", seed=args.seed, num_frames=args.frames), scene,
                         folder / "truth.json")
        code, full, _ = run_and_kill(solve_command(scene, out), after=600.0)
        if code not in (0, 3) or not out.exists():
            print(f"the first, uninterrupted run failed (exit {code})")
            return 1
        size = out.stat().st_size
        print(f"a full run takes {full:.2f} s and writes {size / 1e6:.2f} MB")
        outcomes = {"killed": 0, "killed while writing": 0, "finished": 0}
        for run in range(args.runs):
            during_write = run % 2 == 1
            after = float(rng.uniform(0.0, 0.03) if during_write else rng.uniform(0.3, 1.0) * full)
            code, seconds, writing = run_and_kill(solve_command(scene, out), after, folder if during_write else None)
            outcomes["finished" if code != -signal.SIGKILL else "killed while writing" if writing else "killed"] += 1
            try:
                frames = load_results(out)
                state = f"valid ({len(frames)} frames)"
            except Exception as exc:  # noqa: BLE001 - any failure to read back is a broken file
                broken += 1
                state = f"BROKEN: {exc}"
            when = f"{1000 * after:.0f} ms into the write" if during_write else f"at {after:.2f} s"
            print(f"run {run + 1:>2}: kill {when} (exit {code}, {seconds:.2f} s, temporary file there: {writing}): "
                  f"result {state}")
        leftovers = len(list(folder.glob(".*.tmp")))
    print(f"{args.runs} runs ({outcomes['killed']} killed outside the write, {outcomes['killed while writing']} "
          f"during the write, {outcomes['finished']} finished first): {broken} broken result files; "
          f"{leftovers} temporary files left by kills")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
