"""The paper's comparison (its Tables I and II) on simulated scenes: every baseline and the factor graph.

``vfactor eval paper`` runs :func:`paper_report`: the paper's three vehicles
(``paper_webots``: Lincoln MKZ, Toyota Prius, BMW X5, 50 two-camera groups
each, paper-like noise, fixed seed), every method on the same observations,
tables in the layout of the paper's Table I (per-keypoint error per vehicle and
method) and Table II (rotation, translation), and two plots: error against the
keypoint noise level and against the number of cameras (1 to 4).
"""

from __future__ import annotations

__all__ = ["METHODS", "PAPER_METHODS", "ABLATIONS", "run", "summarise", "tables", "table_one", "table_two",
           "noise_sweep", "camera_sweep", "plot_sweep", "paper_report", "shape_error_cm", "main"]

import dataclasses
import time

import numpy as np

from vfactor.baselines.cpo import CpoOptions, cpo
from vfactor.baselines.pnp import pnp
from vfactor.baselines.single_view import single_view
from vfactor.baselines.stereo import stereo
from vfactor.baselines.triangulation import triangulation
from vfactor.evaluation import summarise_methods
from vfactor.graph import observations_from_detections
from vfactor.init import umeyama
from vfactor.keypoints import KEYPOINT_NAMES
from vfactor.metrics import pose_errors
from vfactor.sim import Scenario, intersection_rig, load_scenario, simulate
from vfactor.wireframe import PRESETS
from vfactor.solve import SolveOptions, solve_observations

#: Method name -> (description, function of (observations, truth) -> list of results; the
#: best of several by keypoint error when more than one, as the paper does for [6]).
METHODS = {
    "cpo": ("CPO + HWC (the paper's method, as written)", lambda obs, truth: [cpo(obs)]),
    "cpo_mean_shape": ("CPO with the mean wireframe (no HWC)", lambda obs, truth: [cpo(obs, CpoOptions(hwc=False))]),
    "stereo": ("two-view triangulation, unweighted (the paper's stereo)", lambda obs, truth: [stereo(obs)]),
    "triangulation": ("multi-view triangulation, confidence-weighted", lambda obs, truth: [triangulation(obs)]),
    "pnp": ("PnP of the mean wireframe, best camera", lambda obs, truth: [pnp(obs)]),
    "single_view": ("deformable model, one view (Pavlakos et al.), camera chosen by fit", lambda obs, truth: [single_view(obs)]),
    "single_view_best": ("the same, the better camera by keypoint error (the paper's protocol for [6])",
                         lambda obs, truth: [single_view(obs, camera=c) for c in range(len(obs.cameras))]),
    "factor_graph": ("vfactor's factor graph (reference)",
                     lambda obs, truth: [solve_observations(obs, SolveOptions(covariance=False))]),
}


#: CPO variants for ``--ablation``: which of the paper's ingredients the numbers owe to what.
ABLATIONS = {
    "cpo": CpoOptions(),
    "cpo_literal": CpoOptions(weighting="model", weight_state="normalised", mu_update=(0.8, -1.0, 0.02), max_step_m=0.05),
    "cpo_model_weighting": CpoOptions(weighting="model"),
    "cpo_normalised_state": CpoOptions(weight_state="normalised"),
    "cpo_fixed_weights": CpoOptions(mu_update=(1.0, 0.0, 0.0)),
    "cpo_mu2_positive": CpoOptions(mu_update=(1.0, 0.1, 0.01)),
    "cpo_mu2_-1": CpoOptions(mu_update=(1.0, -1.0, 0.01)),
    "cpo_mu1_0.8": CpoOptions(mu_update=(0.8, -0.1, 0.01)),
    "cpo_mu3_0": CpoOptions(mu_update=(1.0, -0.1, 0.0)),
    "cpo_mu3_0.1": CpoOptions(mu_update=(1.0, -0.1, 0.1)),
    "cpo_no_cross_steps": CpoOptions(cross_steps=0),
    "cpo_no_single_camera_steps": CpoOptions(single_camera_steps=0),
    "cpo_max_step_5cm": CpoOptions(max_step_m=0.05),
    "cpo_max_step_1cm": CpoOptions(max_step_m=0.01),
    "cpo_100_iterations": CpoOptions(max_iterations=100),
    "cpo_mean_shape": CpoOptions(hwc=False),
}
for _name, _options in ABLATIONS.items():
    METHODS.setdefault(_name, (f"CPO variant {_name}", lambda obs, truth, _o=_options: [cpo(obs, _o)]))


def shape_error_cm(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Mean keypoint distance (cm) between two shapes after their best rigid alignment (the shape alone, any body frame)."""
    R, t, _ = umeyama(estimate, truth, with_scale=False)
    return 100 * float(np.linalg.norm(estimate @ R.T + t - truth, axis=1).mean())


def run(scenario: str | Scenario = "paper_webots", frames: int | None = 10, seed: int = 0, methods=tuple(METHODS),
        gross_errors: bool = True) -> dict[str, list[dict]]:
    """Errors of each method on every (frame, vehicle) of a simulation.

    Args:
        gross_errors: keep the scenario's outliers, left/right swaps and misses
            (False: Gaussian pixel noise only).

    Returns:
        method -> rows: :func:`vfactor.metrics.pose_errors` fields plus ``preset``,
        ``status`` and ``seconds``; a failed method's row has no error fields.
    """
    spec = load_scenario(scenario)
    if not gross_errors:
        spec = dataclasses.replace(spec, noise=dataclasses.replace(spec.noise, outlier_rate=0.0, swap_rate=0.0, missing_rate=0.0))
    sim = simulate(spec, seed=seed, num_frames=frames)
    rows: dict[str, list[dict]] = {m: [] for m in methods}
    for f, frame in enumerate(sim.scene.frames):
        for vid in frame.vehicle_ids():
            truth = sim.truth[f][vid]
            obs = observations_from_detections(frame.detections_of(vid), sim.scene.cameras)
            for method in methods:
                t0 = time.perf_counter()
                results = METHODS[method][1](obs, truth)
                seconds = time.perf_counter() - t0
                errors = [dict(pose_errors(r.world_T_vehicle, r.keypoints_world, truth.world_T_vehicle, truth.keypoints_world),
                               shape_cm=shape_error_cm(r.keypoints_vehicle, truth.keypoints_vehicle))
                          for r in results if r.ok]
                row = {"frame": f, "preset": truth.preset, "status": results[0].status.value, "seconds": seconds}
                if errors:
                    row.update(min(errors, key=lambda e: e["mean_keypoint_cm"]))
                    row["status"] = "ok"
                rows[method].append(row)
    return rows


def summarise(rows: dict[str, list[dict]]) -> dict[str, dict]:
    """:func:`vfactor.evaluation.summarise_methods` plus the shape-alone error, per-preset errors and median ms."""
    out = summarise_methods(rows)
    for method, rs in rows.items():
        ok = [r for r in rs if "rotation_deg" in r]
        presets = sorted({r["preset"] for r in ok})
        out[method].update(
            shape_cm=float(np.mean([r["shape_cm"] for r in ok])) if ok else float("nan"),
            per_preset_keypoint_cm={p: float(np.mean([r["mean_keypoint_cm"] for r in ok if r["preset"] == p]))
                                    for p in presets},
            ms=1e3 * out[method]["seconds"],
        )
    return out


def tables(summary: dict[str, dict]) -> str:
    """Markdown: the pose table (Table II's layout), the keypoint table (Table I's) and per vehicle.

    "shape alone" is :func:`shape_error_cm`: the estimated body-frame wireframe
    against the true one after their best rigid alignment.
    """
    lines = ["| method | vehicles | failed | rotation (deg) | translation (cm) | keypoint (cm) | median keypoint (cm) "
             "| shape alone (cm) | median time (ms) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for m, s in summary.items():
        lines.append(f"| {m} | {s['count']} | {s['failures']} | {s['rotation_deg']:.2f} | {s['translation_cm']:.1f} | "
                     f"{s['keypoint_cm']:.1f} | {s['median_keypoint_cm']:.1f} | {s['shape_cm']:.1f} | {s['ms']:.1f} |")
    lines += ["", "| method | " + " | ".join(f"P{k + 1}" for k in range(len(KEYPOINT_NAMES))) + " | mean |",
              "| --- " * (len(KEYPOINT_NAMES) + 2) + "|"]
    for m, s in summary.items():
        lines.append(f"| {m} | " + " | ".join(f"{e:.1f}" for e in s["per_keypoint_cm"]) + f" | {s['keypoint_cm']:.1f} |")
    presets = sorted({p for s in summary.values() for p in s["per_preset_keypoint_cm"]})
    lines += ["", "| method | " + " | ".join(presets) + " |", "| --- " * (len(presets) + 1) + "|"]
    for m, s in summary.items():
        lines.append(f"| {m} | " + " | ".join(f"{s['per_preset_keypoint_cm'].get(p, float('nan')):.1f}" for p in presets) + " |")
    return "\n".join(lines)



#: The methods of the paper's comparison, in table order.
PAPER_METHODS = ("factor_graph", "cpo", "single_view", "pnp", "stereo")


def table_one(rows: dict[str, list[dict]], methods=PAPER_METHODS) -> str:
    """The paper's Table I layout: mean error per keypoint (cm), one row per vehicle and method."""
    presets = [p for p in PRESETS if any(r["preset"] == p for rs in rows.values() for r in rs)]
    head = "| vehicle | method | " + " | ".join(f"P{k + 1}" for k in range(len(KEYPOINT_NAMES))) + " | mean |"
    lines = [head, "| --- " * (len(KEYPOINT_NAMES) + 3) + "|"]
    for preset in presets:
        for method in methods:
            ok = [r for r in rows[method] if r["preset"] == preset and "keypoint_cm" in r]
            if not ok:
                continue
            per = np.mean([r["keypoint_cm"] for r in ok], axis=0)
            lines.append(f"| {preset} | {method} | " + " | ".join(f"{e:.1f}" for e in per) + f" | {per.mean():.2f} |")
    lines += ["", "P1..P12: " + ", ".join(f"P{k + 1} {n}" for k, n in enumerate(KEYPOINT_NAMES)) + "."]
    return "\n".join(lines)


def table_two(summary: dict[str, dict], methods=PAPER_METHODS) -> str:
    """The paper's Table II layout: whole-vehicle rotation (deg) and translation (cm) error per method."""
    lines = ["| method | rotation (deg) | translation (cm) | keypoint (cm) | failed | median time (ms) |",
             "| --- | --- | --- | --- | --- | --- |"]
    for m in methods:
        s = summary[m]
        lines.append(f"| {m} | {s['rotation_deg']:.2f} | {s['translation_cm']:.2f} | {s['keypoint_cm']:.2f} | "
                     f"{s['failures']} of {s['count']} | {s['ms']:.1f} |")
    return "\n".join(lines)


def _sweep(variants, frames: int, seed: int, methods) -> dict[str, list[float]]:
    """Mean keypoint error (cm) of each method for each scenario variant (NaN where it failed on every scene)."""
    out = {m: [] for m in methods}
    for scenario in variants:
        summary = summarise(run(scenario, frames, seed, methods))
        for m in methods:
            out[m].append(summary[m]["keypoint_cm"])
    return out


def noise_sweep(levels=(0.01, 0.02, 0.03, 0.04, 0.05, 0.06), frames: int = 30, seed: int = 0, methods=PAPER_METHODS):
    """Mean keypoint error against the relative keypoint noise sigma (fraction of the box diagonal)."""
    base = load_scenario("paper_webots")
    variants = [dataclasses.replace(base, noise=dataclasses.replace(base.noise, relative_sigma=s)) for s in levels]
    return list(levels), _sweep(variants, frames, seed, methods)


def camera_sweep(counts=(1, 2, 3, 4), frames: int = 30, seed: int = 0, methods=PAPER_METHODS):
    """Mean keypoint error against the number of cameras (poles on successive corners of the intersection)."""
    base = load_scenario("paper_webots")
    variants = []
    for n in counts:
        rig = intersection_rig(num_cameras=n, distance=18.0, height=7.5, hfov_deg=45.0)
        variants.append(dataclasses.replace(base, cameras=rig, visible_in=tuple(rig)))
    return list(counts), _sweep(variants, frames, seed, methods)


def plot_sweep(x, errors: dict[str, list[float]], xlabel: str, title: str, path) -> None:
    """A PNG of error curves (Agg canvas; the caller's pyplot backend is untouched)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.2), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for method, ys in errors.items():
        ax.plot(x, ys, marker="o", label=method)
    ax.set_xticks(list(x))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("mean keypoint error (cm)")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, metadata={"Software": None})


def paper_report(frames: int | None = None, seed: int = 0, figures_dir=None, sweep_frames: int = 30) -> str:
    """Runs the whole comparison and returns it as Markdown (tables; plots written to ``figures_dir``)."""
    from pathlib import Path

    rows = run("paper_webots", frames, seed, PAPER_METHODS)
    summary = summarise(rows)
    n = summary["cpo"]["count"]
    parts = [f"#### Table II layout: whole-vehicle pose error ({n} vehicles, seed {seed})", "", table_two(summary), "",
             "#### Table I layout: error per keypoint (cm)", "", table_one(rows)]
    if figures_dir is not None:
        figures = Path(figures_dir)
        figures.mkdir(parents=True, exist_ok=True)
        x, errs = noise_sweep(frames=sweep_frames, seed=seed)
        plot_sweep([100 * v for v in x], errs, "keypoint noise sigma (% of the box diagonal)",
                   "Error against keypoint noise (paper_webots)", figures / "paper_noise.png")
        parts += ["", f"#### Error against noise ({sweep_frames} vehicles per level)", "",
                  "| method | " + " | ".join(f"{100 * v:.0f} %" for v in x) + " |", "| --- " * (len(x) + 1) + "|"]
        parts += [f"| {m} | " + " | ".join(f"{e:.1f}" for e in ys) + " |" for m, ys in errs.items()]
        parts += ["", "![error against noise](figures/paper_noise.png)"]
        x, errs = camera_sweep(frames=sweep_frames, seed=seed)
        plot_sweep(x, errs, "number of cameras", "Error against the number of cameras (paper_webots)",
                   figures / "paper_cameras.png")
        parts += ["", f"#### Error against the number of cameras ({sweep_frames} vehicles per count)", "",
                  "| method | " + " | ".join(f"{v} camera{'s' if v > 1 else ''}" for v in x) + " |",
                  "| --- " * (len(x) + 1) + "|"]
        parts += [f"| {m} | " + " | ".join("-" if not np.isfinite(e) else f"{e:.1f}" for e in ys) + " |"
                  for m, ys in errs.items()]
        parts += ["", "![error against the number of cameras](figures/paper_cameras.png)"]
    return "\n".join(parts) + "\n"


def main(argv=None) -> None:
    """``python -m vfactor.paper_comparison``: the comparison with every method and the CPO ablations."""
    import argparse

    parser = argparse.ArgumentParser(description="The paper's comparison with every baseline, or the CPO ablations.")
    parser.add_argument("--scenario", default="paper_webots")
    parser.add_argument("--frames", type=int, default=None, help="frames to simulate (default: the scenario's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", nargs="*", default=None, choices=list(METHODS),
                        help="default: the baselines (with --ablation: the CPO variants)")
    parser.add_argument("--ablation", action="store_true", help="run the CPO variants of ABLATIONS")
    parser.add_argument("--no-gross-errors", action="store_true", help="Gaussian pixel noise only (no outliers, swaps, misses)")
    args = parser.parse_args(argv)
    if args.methods is None:
        args.methods = list(ABLATIONS) if args.ablation else [m for m in METHODS if m not in ABLATIONS or m in (
            "cpo", "cpo_mean_shape")]
    t0 = time.perf_counter()
    summary = summarise(run(args.scenario, args.frames, args.seed, tuple(args.methods), not args.no_gross_errors))
    noise = ", Gaussian noise only" if args.no_gross_errors else ""
    print(f"{args.scenario}{noise}, seed {args.seed}, {next(iter(summary.values()))['count']} vehicles, "
          f"{time.perf_counter() - t0:.1f} s\n")
    print(tables(summary))


if __name__ == "__main__":
    main()
