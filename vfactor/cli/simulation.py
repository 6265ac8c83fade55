"""``vfactor simulate`` and ``vfactor demo``: simulated scenes, and the main job on one with pictures."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from vfactor.cli.common import (EXIT_OK, check_out_dir, check_out_file, check_positive, missing_extra, output, progress,
                                report_unsolved)
from vfactor.errors import InputError

__all__ = ["simulate", "demo"]


def simulate(args) -> int:
    from vfactor.sim import list_scenarios, load_scenario, simulate, write_simulation

    if args.list:
        for name in list_scenarios():
            print(f"{name:<32} {load_scenario(name).description.split('. ')[0]}")
        return EXIT_OK
    if not args.scenario or not args.out:
        raise InputError("", "give a SCENARIO and --out SCENE.json (or --list)")
    echo = output(args)
    out = check_out_file(args.out, "--out", [("scenario file", args.scenario)])
    truth = check_out_file(args.truth if args.truth else out.with_name(out.stem + "_truth.json"), "--truth",
                            [("scenario file", args.scenario), ("scene file --out", args.out)])
    if os.path.abspath(out) == os.path.abspath(truth):
        raise InputError("--truth", f"{truth} is also --out; give another file")
    sim = simulate(load_scenario(args.scenario), seed=args.seed, num_frames=check_positive(args.frames, "--frames"))
    write_simulation(sim, out, truth)
    ids = {vid for f in sim.scene.frames for vid in f.vehicle_ids()}
    echo(f"wrote {out} ({len(sim.scene.frames)} frames, {len(ids)} vehicle ids, {len(sim.scene.cameras)} cameras) "
          f"and {truth}")
    return EXIT_OK


def demo(args) -> int:
    from vfactor.baselines import triangulation
    from vfactor.graph import observations_from_detections
    from vfactor.metrics import pose_errors
    from vfactor.result import FrameResult
    from vfactor.scene import save_results
    from vfactor.sim import load_scenario, save_truth, simulate, write_simulation
    from vfactor.solve import SolveOptions, solve_observations
    from vfactor.viz import plot_estimates, write_overlays

    echo = output(args)
    if args.images:  # before anything is written: the extras it needs
        try:
            import vfactor.net.pipeline  # noqa: F401
            import vfactor.render.scenes  # noqa: F401
        except ImportError as exc:
            raise missing_extra("--images", exc, "net,render") from None
    out = check_out_dir(Path(args.out))
    scenario = load_scenario(args.scenario)
    frames = check_positive(args.frames, "--frames")
    if args.images and frames is None:
        frames = min(scenario.num_frames, 3)  # rendering takes about a second per image
    sim = simulate(scenario, seed=args.seed, num_frames=frames)
    if not 0 <= args.frame < len(sim.scene.frames):
        raise InputError("--frame", f"expected a frame index from 0 to {len(sim.scene.frames) - 1}, got {args.frame}")
    if args.images:  # the scene file is the rendered one (images and boxes), written by _demo_images
        save_truth(sim, out / "scene_truth.json")
    else:
        write_simulation(sim, out / "scene.json", out / "scene_truth.json")
    echo(f"scenario {scenario.name}: {len(sim.scene.cameras)} cameras, {len(sim.scene.frames)} frames "
          f"(seed {sim.seed}); " + (f"truth in {out}/" if args.images else f"scene and truth in {out}/"))
    scene = _demo_images(sim, out, echo) if args.images else sim.scene
    options = SolveOptions()
    results, rows = [], []
    header = f"{'frame':>5} {'vehicle':<8} {'body':<13} {'status':<10} | {'vfactor: rot deg':>16} {'trans cm':>9} {'kp cm':>7} | {'triangulation: rot':>18} {'trans':>7} {'kp':>7}"
    echo(header)
    echo("-" * len(header))
    for f, frame in enumerate(scene.frames):
        vehicles = []
        for vid in frame.vehicle_ids():
            truth = sim.truth[f][vid]
            obs = observations_from_detections(frame.detections_of(vid), scene.cameras, options.graph)
            ours, tri = solve_observations(obs, options, vid), triangulation(obs, vid)
            vehicles.append(ours)
            errs = [pose_errors(r.world_T_vehicle, r.keypoints_world, truth.world_T_vehicle, truth.keypoints_world)
                    if r.ok else None for r in (ours, tri)]
            rows.append(errs)
            cells = [_error_cells(e, widths) for e, widths in zip(errs, ((16, 9, 7), (18, 7, 7)))]
            echo(f"{f:>5} {vid:<8} {truth.preset:<13} {ours.status.value:<10} | {cells[0]} | {cells[1]}")
        results.append(FrameResult(frame.t, vehicles))
    save_results(results, out / "result.json")
    for name, col in (("vfactor", 0), ("triangulation", 1)):
        ok = [r[col] for r in rows if r[col]]
        if ok:
            echo(f"mean {name:<14} rotation {np.mean([e['rotation_deg'] for e in ok]):6.2f} deg   "
                  f"translation {np.mean([e['translation_cm'] for e in ok]):6.1f} cm   "
                  f"keypoints {np.mean([e['mean_keypoint_cm'] for e in ok]):6.1f} cm   ({len(ok)}/{len(rows)} solved)")
    f = args.frame
    truth_f = {vid: (t.world_T_vehicle, t.wireframe) for vid, t in sim.truth[f].items()}
    overlays = write_overlays(out, scene.cameras, scene.frames[f], results[f], truth=truth_f, base_dir=scene.base_dir)
    plot = plot_estimates(scene.cameras, results[f].vehicles, truth_f, out / "estimate_3d.png",
                          title=f"{scenario.name}, frame {f}: estimate (solid) and truth (dashed), 3-sigma position")
    echo("wrote " + ", ".join(str(p) for p in [out / "result.json", *overlays, plot]))
    return report_unsolved(results, scene, quiet=False)


def _demo_images(sim, out: Path, echo=print):
    """``vfactor demo --images``: renders the simulation's camera images and finds the keypoints with the network
    (:func:`demo` checked that the extras import)."""
    from vfactor.net.infer import KeypointDetector
    from vfactor.net.pipeline import detect_scene
    from vfactor.render import RenderingUnavailable
    from vfactor.render.scenes import render_simulation
    from vfactor.scene import save_scene

    t0 = time.perf_counter()
    try:
        rendered = render_simulation(sim, out, seed=sim.seed, progress=progress("rendering"))
    except RenderingUnavailable as exc:
        raise InputError("--images", f"cannot render: {exc}") from None
    except ValueError as exc:  # e.g. a scenario camera without image_size
        raise InputError("--images", str(exc)) from None
    echo(f"rendered {sum(len(f.images) for f in rendered.scene.frames)} camera images into {out / 'images'}/ "
          f"({time.perf_counter() - t0:.1f} s); boxes only in {rendered.path}")
    t0 = time.perf_counter()
    scene = detect_scene(rendered.scene, KeypointDetector(), heatmaps_dir=out / "heatmaps")
    save_scene(scene, out / "scene_keypoints.json")
    boxes = sum(len(f.detections) for f in scene.frames)
    echo(f"keypoint network: {boxes} boxes ({time.perf_counter() - t0:.1f} s); keypoints in "
          f"{out / 'scene_keypoints.json'}, heatmaps in {out / 'heatmaps'}/")
    return scene


def _error_cells(errors: dict | None, widths) -> str:
    if errors is None:
        return " ".join(f"{'-':>{w}}" for w in widths)
    values = (errors["rotation_deg"], errors["translation_cm"], errors["mean_keypoint_cm"])
    return " ".join(f"{v:>{w}.{2 if i == 0 else 1}f}" for i, (v, w) in enumerate(zip(values, widths)))

