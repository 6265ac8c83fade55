"""``vfactor eval``: accuracy and consistency against simulated ground truth (frames, tracks, paper, images)."""

from __future__ import annotations

import dataclasses
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from vfactor.cli.common import (EXIT_OK, check_out_file, check_positive, degrees_metres, missing_extra,
                                open_command_engine, output, progress)
from vfactor.errors import InputError
from vfactor.jsonio import write_text_atomic

__all__ = ["evaluate"]

#: ``eval tracks``' fixed lag of its isam2_lag row (seconds) and ``eval paper``'s vehicles per point of its plots,
#: where not given.
DEFAULT_LAG = 0.5
DEFAULT_SWEEP_FRAMES = 30


def evaluate(args) -> int:
    t0 = time.perf_counter()
    if args.markdown:
        check_out_file(args.markdown, "--markdown")
    frames = check_positive(args.frames, "--frames")
    check_positive(args.seeds, "--seeds")
    if args.draws < 0:
        raise InputError("--draws", f"expected an integer >= 0, got {args.draws}")
    if args.lag is not None and not (np.isfinite(args.lag) and args.lag > 0):
        raise InputError("--lag", f"expected a positive number of seconds, got {args.lag}")
    body_motion = _body_motion(args.body_motion) if args.body_motion is not None else None
    extrinsic_error = (_extrinsic_error(args.extrinsic_error, not args.undeclared_extrinsics)
                       if args.extrinsic_error is not None else None)
    if args.undeclared_extrinsics and extrinsic_error is None:
        raise InputError("--undeclared-extrinsics", "only with --extrinsic-error (the cameras' error it leaves out)")
    roofs = "--real-roofs" if args.real_roofs else "--no-real-roofs"
    cluster = "--workers" if args.workers is not None else "--scheduler"
    for flag, given, takers, why in (  # an option another experiment takes is bad input here, never dropped
            ("--body-motion", body_motion is not None, ("tracks",), "simulates no accelerations (eval tracks does)"),
            ("--levels", args.levels is not None, ("frames", "association"),
             "has no noise levels (frames and association have)"),
            ("--weights", args.weights is not None, ("images",), "uses no keypoint network (eval images does)"),
            (roofs, args.real_roofs is not None, ("images",), "renders no images (eval images does)"),
            (cluster, args.workers is not None or args.scheduler is not None, ("frames", "tracks", "association"),
             "runs in this process (frames, tracks and association take a cluster)"),
            ("--seeds", args.seeds != 1, ("frames", "tracks", "images", "association"),
             "runs one seed (--seed); frames, tracks, images and association take several"),
            ("--scenario", args.scenario is not None, ("frames", "tracks", "images", "association"),
             "uses its own scenario (paper_webots)"),
            ("--draws", args.draws != 0, ("tracks",), None), ("--lag", args.lag is not None, ("tracks",), None),
            ("--figures", args.figures is not None, ("paper",), None),
            ("--sweep-frames", args.sweep_frames is not None, ("paper",), None),
            ("--clipped-boxes", args.clipped_boxes, ("images",), None),
            ("--road-plane", args.road_plane, ("frames",), None),
            ("--extrinsic-error", extrinsic_error is not None, ("frames", "tracks"), None),
            ("--rig", args.rig is not None, ("frames", "tracks"), None),
            ("--detector-offsets", args.detector_offsets is not None, ("images",), None)):
        if given and args.experiment not in takers:
            raise InputError(flag, f"eval {args.experiment} {why}" if why else
                             f"only eval {' and '.join(takers)} takes it, not eval {args.experiment}")
    if args.amodal_pass and not (args.experiment == "images" and args.clipped_boxes):
        raise InputError("--amodal-pass", "only with eval images --clipped-boxes (whole boxes stop at no image border)")
    if args.experiment in ("frames", "tracks", "association"):
        with open_command_engine(args.workers, args.scheduler) as engine:
            if args.experiment == "frames":
                sections = _eval_frames(_scenario(args, "library_2cam", extrinsic_error), frames, args.seed,
                                        _levels(args.levels or "clean,paper,hard"), args.seeds, engine,
                                        args.road_plane)
            elif args.experiment == "tracks":
                sections = _eval_tracks(_scenario(args, "tracks_3veh", extrinsic_error), frames, args.seed,
                                        args.seeds, args.draws,
                                        DEFAULT_LAG if args.lag is None else args.lag, engine, body_motion)
            else:
                sections = _eval_association(args.scenario, frames, args.seed, args.seeds, engine,
                                             _levels(args.levels) if args.levels else (None,))
    elif args.experiment == "images":
        sections = _eval_images(args.scenario or "accuracy_2cam", frames, args.seed, args.weights,
                                args.detector_offsets, args.clipped_boxes, args.amodal_pass,
                                args.real_roofs is not False, args.seeds)
    else:
        from vfactor.paper_comparison import paper_report

        sweep = DEFAULT_SWEEP_FRAMES if args.sweep_frames is None else check_positive(args.sweep_frames,
                                                                                        "--sweep-frames")
        sections = [paper_report(frames, args.seed, args.figures, sweep)]
    default = {"frames": "library_2cam", "tracks": "tracks_3veh", "paper": None, "images": "accuracy_2cam",
               "association": None}[args.experiment]
    command = "vfactor eval" + (f" {args.experiment}" if args.experiment != "frames" else "") + \
        (f" --scenario {args.scenario}" if args.scenario and args.scenario != default else "") + \
        (f" --frames {args.frames}" if args.frames else "") + (f" --seed {args.seed}" if args.seed else "") + \
        (f" --seeds {args.seeds}" if args.seeds != 1 else "") + (f" --draws {args.draws}" if args.draws else "") + \
        (f" --lag {args.lag:g}" if args.lag is not None else "") + \
        (f" --body-motion {args.body_motion}" if body_motion is not None else "") + \
        (f" --levels {args.levels}" if args.levels and not (args.experiment == "frames" and
                                                             args.levels == "clean,paper,hard") else "") + \
        (f" --figures {args.figures}" if args.figures else "") + \
        (f" --sweep-frames {args.sweep_frames}" if args.sweep_frames is not None else "") + \
        (f" --weights {args.weights}" if args.weights else "") + (" --clipped-boxes" if args.clipped_boxes else "") + \
        (" --amodal-pass" if args.amodal_pass else "") + (" --road-plane" if args.road_plane else "") + \
        (f" --rig {args.rig}" if args.rig is not None else "") + \
        (f" --extrinsic-error {args.extrinsic_error}" if extrinsic_error is not None else "") + \
        (" --undeclared-extrinsics" if args.undeclared_extrinsics else "") + \
        {True: " --real-roofs", False: " --no-real-roofs"}.get(args.real_roofs, "") + \
        {True: " --detector-offsets", False: " --no-detector-offsets"}.get(args.detector_offsets, "")
    echo = output(args)
    for section in sections:
        echo(section)
    echo(f"({command}; {time.perf_counter() - t0:.1f} s)")
    if args.markdown:
        write_text_atomic(args.markdown, f"<!-- made by: {command} -->\n\n" + "\n".join(sections))
    return EXIT_OK


def _on_rig(scenario: str, scene_file: str):
    """``--rig``: the scenario's vehicles seen by the cameras of ``scene_file``, the rig moved along the road so
    that where it looks is the scenario's centre (:func:`vfactor.sim.scenario_on_cameras`).

    Raises:
        InputError: (``--rig``) the scene file does not load, its road plane is not the world's ``z = 0`` (on
            which the simulator's vehicles stand), or no camera looks at that road.
    """
    from vfactor.errors import ScenarioError
    from vfactor.scene import load_scene
    from vfactor.sim import load_scenario, scenario_on_cameras

    try:
        scene = load_scene(scene_file)
    except InputError as exc:
        raise InputError("--rig", str(exc)) from None
    plane = scene.ground_plane  # n . x = offset, n of unit length
    if plane is not None and (abs(plane.offset) > 0.05 or np.degrees(np.arccos(min(plane.normal[2], 1.0))) > 1.0):
        raise InputError("--rig", f"{scene_file}'s road plane is not the world's z = 0 plane, on which the simulated "
                         "vehicles stand: give the rig in a world frame whose road is z = 0")
    try:
        return scenario_on_cameras(load_scenario(scenario), scene.cameras,
                                   name=f"{scenario} on {Path(scene_file).stem}")
    except ScenarioError as exc:
        raise InputError("--rig", f"{scene_file}: {exc}") from None


def _levels(text: str) -> tuple[str, ...]:
    from vfactor.evaluation import NOISE_LEVELS

    levels = tuple(t.strip() for t in text.split(",") if t.strip())
    unknown = [t for t in levels if t not in NOISE_LEVELS]
    if not levels or unknown:
        raise InputError("--levels", f"expected a comma-separated list of {', '.join(NOISE_LEVELS)}, got {text!r}")
    return levels


def _eval_frames(scenario_name, frames, seed: int, levels=("clean", "paper", "hard"), seeds: int = 1,
                 engine=None, road_plane: bool = False) -> list[str]:
    """``vfactor eval`` (frames) of ``scenario_name``: a packaged name, a file, or a
    :class:`~vfactor.sim.Scenario` (``--rig``)."""
    from vfactor.evaluation import (accuracy_table, body_type_table, consistency_table, keypoint_table, run_accuracy,
                                    poor_fit_summary, summarise_methods)
    from vfactor.factors.ground_plane import GroundPlane
    from vfactor.solve import SolveOptions

    sections = []
    which = f"seed {seed}" if seeds == 1 else f"seeds {seed}-{seed + seeds - 1}"
    which += ", the road plane given" if road_plane else ""
    options = SolveOptions(ground_plane=GroundPlane()) if road_plane else SolveOptions()  # the simulator's road
    for scenario, rows in run_accuracy(scenario_name, frames, seed, levels, options, seeds=seeds, engine=engine):
        n, off = scenario.noise, scenario.extrinsic_error
        summary = summarise_methods(rows)
        title = (f"### {scenario.name}: {n.outlier_rate:.0%} outliers, {n.swap_rate:.0%} left/right swaps, "
                 f"{n.missing_rate:.0%} missing, sigma {n.relative_sigma:.1%} of the box diagonal "
                 f"(x{n.occluded_factor:g} when self-occluded), {which}")
        if off is not None:
            title += (f", each camera off by draws of {off.rotation_deg:g} deg and {off.translation_m:g} m per axis "
                      f"({'its extrinsic_sigma' if off.declared else 'no extrinsic_sigma'})")
        sections.append(f"{title}\n\n{accuracy_table(summary)}\n\nPer body type (each vehicle solved with a "
                        f"shape model learnt without it):\n\n{body_type_table(rows)}\n\n{poor_fit_summary(rows)}\n\n"
                        f"Consistency of the factor "
                        f"graph's covariances (NEES; consistent: 1.00x and 95 %):\n\n{consistency_table(rows)}\n\n"
                        f"Mean error per keypoint (cm):\n\n{keypoint_table(summary)}\n")
        if len({r["cameras"] for r in rows["factor_graph"]}) > 1:  # vehicles seen by different numbers of cameras
            sections.append(f"Per camera count (the cameras that saw at least one keypoint of the vehicle):\n\n"
                            f"{body_type_table(rows, by='cameras')}\n\n{consistency_table(rows, by='cameras')}\n")
    return sections


def _eval_images(scenario_name: str, frames, seed: int, weights: str | None = None,
                 detector_offsets: bool | None = None, clipped_boxes: bool = False,
                 amodal_pass: bool = False, real_roofs: bool = True, seeds: int = 1) -> list[str]:
    """``vfactor eval images``: one report per seed from ``seed`` on, then (several seeds) the factor graph's
    errors and covariances per body type with the seeds pooled."""
    try:
        from vfactor.net.end_to_end import evaluate_images, images_report, network_class_tables
        from vfactor.net.infer import KeypointDetector
    except ImportError as exc:
        raise missing_extra("images", exc, "net,render") from None
    try:
        detector = KeypointDetector(weights)
    except Exception as exc:  # noqa: BLE001 - any failure to read the weights file is bad input
        raise InputError("--weights", str(exc)) from None
    from vfactor.track import TrackOptions

    track_options = TrackOptions(detector_offsets=detector_offsets)
    sections, pooled = [], defaultdict(list)
    for s in range(seed, seed + seeds):
        evaluation = evaluate_images(scenario_name, frames, s, detector, progress=progress("rendering"),
                                     track_options=track_options, clip_boxes=clipped_boxes,
                                     amodal_pass=amodal_pass, real_roofs=real_roofs)
        sections.append(images_report(evaluation))
        for method, rows in evaluation["rows"].items():
            pooled[method] += rows
    if seeds > 1:
        sections.append(f"### {evaluation['scenario']}, seeds {seed}-{seed + seeds - 1} pooled: rendered images -> "
                        f"keypoint network -> factor graph\n\n{network_class_tables(pooled)}")
    return sections


def _eval_association(scenario_name, frames, seed: int, seeds: int, engine=None, levels=(None,)) -> list[str]:
    import importlib.util

    if importlib.util.find_spec("motmetrics") is None:  # CLEAR-MOT's counts
        raise InputError("association", "this needs motmetrics; install with pip install -c constraints.txt motmetrics")
    from vfactor.association.evaluate import DEFAULT_NOISE, association_report, body_type_report, evaluate_association

    scenarios = [scenario_name] if scenario_name else ["association_4cam", "association_3cam"]
    runs = [run for level in levels for name in scenarios
            for run in evaluate_association(name, range(seed, seed + seeds), frames, progress=progress("associating"),
                                            engine=engine, level=level)]
    noise = ", ".join(f"{k} {v:g}" for k, v in DEFAULT_NOISE.items())
    if levels != (None,):
        noise += "; keypoint noise " + ", ".join(levels)
    return [f"### Association without ids ({noise}), beside the true ids\n\n{association_report(runs)}\n",
            f"Pose errors per body type and camera count (vehicles tracked within 2 m of a true one):\n\n"
            f"{body_type_report(runs)}\n"]


def _body_motion(text: str):
    """``--body-motion ROLL,PITCH`` (degrees per g, each in [0, ``BodyMotion.MAX_DEG_PER_G``]) as a
    :class:`vfactor.sim.BodyMotion`."""
    from vfactor.sim import BodyMotion

    parts = text.split(",")
    try:
        roll, pitch = (float(part) for part in parts)
    except ValueError:
        raise InputError("--body-motion", f"expected ROLL,PITCH in degrees per g, e.g. 5,2, got {text!r}") from None
    if not all(np.isfinite(v) and 0.0 <= v <= BodyMotion.MAX_DEG_PER_G for v in (roll, pitch)):
        raise InputError("--body-motion", f"expected ROLL and PITCH within [0, {BodyMotion.MAX_DEG_PER_G:g}] degrees "
                                          f"per g, got {text!r}")
    return BodyMotion(roll, pitch)


def _scenario(args, default: str, extrinsic_error):
    """The scenario of ``eval`` frames or tracks: ``--scenario`` (else ``default``), on the ``--rig``'s cameras
    where given, its scene's cameras off by ``extrinsic_error`` where given (``--extrinsic-error``)."""
    scenario = args.scenario or default
    if args.rig is not None:
        scenario = _on_rig(scenario, args.rig)
    if extrinsic_error is not None:
        from vfactor.sim import load_scenario

        scenario = dataclasses.replace(load_scenario(scenario), extrinsic_error=extrinsic_error)
    return scenario


def _extrinsic_error(text: str, declared: bool):
    """``--extrinsic-error DEG,M`` as a :class:`vfactor.sim.ExtrinsicError` (degrees and metres per camera axis),
    which checks the ranges."""
    from vfactor.errors import ScenarioError
    from vfactor.sim import ExtrinsicError

    rotation, translation = degrees_metres(text, "--extrinsic-error")
    try:
        return ExtrinsicError(rotation, translation, declared)
    except ScenarioError as exc:
        raise InputError("--extrinsic-error", f"{exc.field.split('.')[-1]}: {exc.problem}") from None


def _eval_tracks(scenario_name, frames, seed: int, seeds: int, draws: int = 0, lag: float = 0.5,
                 engine=None, body_motion=None) -> list[str]:
    """``vfactor eval tracks`` of ``scenario_name``: a packaged name, a file, or a :class:`~vfactor.sim.Scenario`
    (``--rig``)."""
    from vfactor.evaluation import nees_component_table
    from vfactor.parallel import InProcess
    from vfactor.sim import load_scenario

    scenario = load_scenario(scenario_name)
    if scenario.motion is None:
        raise InputError("--scenario", f"{scenario.name!r} has no motion: each frame holds new vehicles, so there "
                         "is nothing to track; use a scenario with tracks, e.g. tracks_3veh or tracks_3cam")
    if body_motion is not None:
        scenario = dataclasses.replace(scenario, body_motion=body_motion)
    units = [(scenario, s, frames, draws, lag) for s in range(seed, seed + seeds)]
    done = list((engine or InProcess()).map(_tracks_unit, units))
    sections = [section for unit_sections, *_ in done for section in unit_sections]
    if seeds > 1:
        sections.append(_tracks_pooled(scenario.name, seed, seeds, [c for _, c, _, _ in done], [s for _, _, s, _ in done]))
    components = defaultdict(list)  # method -> every seed's poses' NEES per axis
    for *_, unit_components in done:
        for method, parts in unit_components.items():
            components[method] += parts
    sections.append(f"Pose NEES per body-frame axis{', seeds pooled' if seeds > 1 else ''} (each coordinate's squared "
                    f"error over its variance; consistent: 1):\n\n{nees_component_table(components)}\n")
    return sections


def _tracks_pooled(name: str, seed: int, seeds: int, classes: list[dict], shapes: list[list]) -> str:
    """The seeds of ``vfactor eval tracks`` pooled per body type and camera count, and each body type's final
    shapes (isam2) against issue 10's 5 cm."""

    from vfactor.evaluation import class_tables, final_shape_table

    methods = ("frame_by_frame", "isam2_online", "isam2", "isam2_lag", "batch")
    pooled = defaultdict(list)
    for unit in classes:
        for method, rows in unit.items():
            pooled[(name, method)] += rows
    by_type = defaultdict(list)
    for body_type, cm in (pair for unit in shapes for pair in unit):
        by_type[body_type].append(cm)
    return (f"### {name}, seeds {seed}-{seed + seeds - 1} pooled\n\n{class_tables(pooled, methods, [name], 'scene')}"
            f"\n\nFinal shapes (isam2, mean body-frame keypoint error):\n\n{final_shape_table({name: by_type}, 'scene')}\n")


def _tracks_unit(unit: tuple) -> tuple[list[str], dict, list, dict]:
    """One seed of ``vfactor eval tracks``: its sections, its poses' :func:`~vfactor.evaluation.class_rows` per
    method, (body type, final shape error cm) of each track (isam2), and its poses' NEES per axis per method."""
    from vfactor.evaluation import compare_tracking, shape_draws_table, shape_over_noise_draws, tracking_table
    from vfactor.sim import simulate

    scenario, s, frames, draws, lag = unit
    sim = simulate(scenario, seed=s, num_frames=frames)
    ids = sorted({vid for f in sim.scene.frames for vid in f.vehicle_ids()})
    title = (f"### {scenario.name}, seed {s}: {len(sim.scene.frames)} frames, {len(ids)} vehicles, "
             f"{len(sim.scene.cameras)} cameras" + (", road plane given" if sim.scene.ground_plane else ""))
    comparison = compare_tracking(sim, lag=lag)
    sections = [f"{title}\n\n{tracking_table(comparison)}\n"]
    if draws:
        sections.append(f"Final shapes of batch smoothing over {draws} draws of the keypoint noise (same "
                        f"vehicles and motion):\n\n{shape_draws_table(shape_over_noise_draws(sim, draws))}\n")
    shapes = [(comparison["shape_types"][vid], cm) for vid, cm in comparison["shape_cm"]["isam2"].items()]
    components = {method: [row["pose_nees_components"] for row in rows if "pose_nees_components" in row]
                  for method, rows in comparison["errors"].items()}
    return sections, comparison["classes"], shapes, components
