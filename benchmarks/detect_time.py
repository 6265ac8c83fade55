"""Benchmark: keypoint-network inference time per vehicle box on the CPU, batch 1 and batch 16.

Reports, in one run: milliseconds per box (forward pass, then forward pass plus
heatmap decoding) of the shipped network at batch sizes 1 and 16; the whole
detector (``KeypointDetector.detect_batch`` on a 1280 x 720 image: cropping,
network, decoding, calibration) with and without the flip test; and each as a
ratio against the one-frame graph solve of one vehicle (``solve_observations``,
default settings without covariances) timed in the same run, so that a reader
sees what the network adds to a solve.

Run: ``python benchmarks/detect_time.py [--weights PATH]`` (needs torch).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vfactor.graph import observations_from_detections
from vfactor.net.infer import KeypointDetector, benchmark_inference
from vfactor.sim import simulate
from vfactor.solve import SolveOptions, solve_observations


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--weights", help="weights file (default: the shipped weights)")
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args(argv)

    detector = KeypointDetector(args.weights, device="cpu")
    forward = benchmark_inference(detector.model, (1, 16), repeats=args.repeats)
    decoded = benchmark_inference(detector.model, (1, 16), repeats=args.repeats, decode=True)
    image = np.random.default_rng(0).integers(0, 256, (720, 1280, 3), dtype=np.uint8)
    detector_ms = {}
    for flip in (False, True):
        detector.flip_test = flip
        for b in (1, 16):
            boxes = [(40.0 + 70 * i, 200.0, 300.0 + 70 * i, 380.0) for i in range(b)]
            best = float("inf")
            for r in range(3 + args.repeats):
                t0 = time.perf_counter()
                detector.detect_batch([image], [boxes])
                if r >= 3:
                    best = min(best, time.perf_counter() - t0)
            detector_ms[(flip, b)] = 1e3 * best / b
    sim = simulate("intersection_2cam", seed=3, num_frames=10)
    options = SolveOptions(covariance=False)
    times = []
    for frame in sim.scene.frames:
        obs = observations_from_detections(frame.detections_of("v1"), sim.scene.cameras, options.graph)
        t0 = time.perf_counter()
        solve_observations(obs, options)
        times.append(time.perf_counter() - t0)
    solve_ms = 1e3 * float(np.median(times))
    cfg = detector.model.config
    print(f"network: {cfg.num_stacks} stacks, {cfg.channels} channels, {cfg.input_size} px input, CPU")
    print(f"{'batch':>6}{'forward ms/box':>16}{'+ decode ms/box':>17}{'vs one-frame solve':>20}")
    for b in (1, 16):
        print(f"{b:>6}{forward[b]:>16.2f}{decoded[b]:>17.2f}{decoded[b] / solve_ms:>20.2f}")
    print(f"\nwhole detector on a 1280 x 720 image (crop, network, decoding, calibration):")
    print(f"{'flip test':>10}{'batch':>6}{'ms/box':>10}{'vs one-frame solve':>20}")
    for (flip, b), ms in detector_ms.items():
        print(f"{'on' if flip else 'off':>10}{b:>6}{ms:>10.2f}{ms / solve_ms:>20.2f}")
    print(f"one-frame solve of one vehicle (reference): {solve_ms:.2f} ms")
    return {"forward_ms": forward, "decoded_ms": decoded, "detector_ms": detector_ms, "solve_ms": solve_ms}


if __name__ == "__main__":
    main()
