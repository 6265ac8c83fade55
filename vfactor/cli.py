"""The ``vfactor`` command: solve scene files, simulate scenarios, run the demo and the accuracy evaluation.

Exit codes (:data:`EXIT_CODES`, docs/reliability.md): 0 success (every vehicle
solved); 2 bad input (a malformed or contradictory scene, scenario or
calibration, or a bad option: one line naming the field); 3 the input was
good but some vehicles could not be solved (each reported ``degenerate`` or
``failed`` in the result file and on stderr); 1 an internal error (run again
with ``--debug`` for the traceback); 130 interrupted.

Everything printed as a message (errors, notes, unsolved vehicles) goes
through :func:`vfactor.sanity.one_line`: one line, no terminal escapes.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from vfactor.errors import InputError
from vfactor.jsonio import write_text_atomic
from vfactor.sanity import one_line

__all__ = ["main", "build_parser", "EXIT_CODES", "EXIT_OK", "EXIT_INTERNAL", "EXIT_INPUT", "EXIT_UNSOLVED"]

EXIT_OK, EXIT_INTERNAL, EXIT_INPUT, EXIT_UNSOLVED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
#: Exit code -> meaning (the epilog of ``vfactor --help`` and docs/reliability.md).
EXIT_CODES = {
    EXIT_OK: "success: every vehicle solved",
    EXIT_INTERNAL: "internal error (a bug: run again with --debug for the traceback)",
    EXIT_INPUT: "bad input: a malformed scene, scenario, calibration or option (one line names the field)",
    EXIT_UNSOLVED: "some vehicles could not be solved: reported degenerate or failed (result file and stderr)",
    EXIT_INTERRUPTED: "interrupted",
}

_DESCRIPTION = """\
vfactor estimates each vehicle's 6-DoF pose (world_T_vehicle), its 12-keypoint
wireframe (metres) and their covariances from several fixed, calibrated cameras
that each see the vehicle from their own side, as a GTSAM factor graph.

Start here:
  vfactor demo                          simulate a two-camera intersection, solve it,
                                        compare with triangulation, write pictures
  vfactor simulate --list               the packaged scenarios (camera rigs, vehicles, noise)
  vfactor simulate intersection_2cam --out scene.json --truth truth.json
  vfactor solve scene.json --out result.json      every frame on its own
  vfactor track scene.json --out result.json      tracks over frames (iSAM2: shared shape, motion)
  vfactor eval                          accuracy against ground truth, beside baselines

Scene and result formats, conventions and the factors' maths: docs/ in the
repository (conventions.md, factors.md, tutorial.md); limits and exit codes:
docs/reliability.md."""

_EPILOG = "exit codes:\n" + "\n".join(f"  {code:<4}{text}" for code, text in EXIT_CODES.items())


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit 2)."""

    def error(self, message):
        self.exit(EXIT_INPUT, f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="vfactor", description=_DESCRIPTION, epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    p = sub.add_parser(
        "solve", help="estimate every vehicle of every frame of a scene file (frames solved one by one)",
        description="Estimate every vehicle of every frame of SCENE on its own (Levenberg-Marquardt, robust to "
        "outlier keypoints and left/right swaps) and write RESULT with poses, wireframes, covariances and a status "
        "per vehicle. A vehicle that cannot be solved is reported with status 'degenerate' or 'failed' and a "
        "message; the others are still solved. Detections given as boxes in the frames' images go through the "
        "keypoint network first (needs torch).",
    )
    p.add_argument("scene", help="scene file (JSON, see docs/scene-format.md)")
    p.add_argument("--out", required=True, help="result file to write (JSON; written atomically)")
    p.add_argument("--allow-outside-paths", action="store_true",
                   help="accept heatmap and image paths outside the scene file's folder (refused by default)")
    p.add_argument("--no-covariance", action="store_true", help="skip the marginal covariances (faster)")
    p.add_argument("--loss", default="cauchy", choices=("none", "huber", "cauchy", "geman_mcclure"),
                   help="robust loss per keypoint (default: cauchy)")
    p.add_argument("--weights", help="keypoint-network weights for detections given as image boxes "
                   "(default: the shipped weights; needs torch)")
    p.add_argument("--save-detections", metavar="SCENE_OUT",
                   help="also write the scene with the network's keypoints (and its heatmaps in SCENE_OUT's folder)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")

    p = sub.add_parser(
        "track", help="track every vehicle through the frames of a scene (iSAM2, shared shape, motion model)",
        description="Track every vehicle (by its track id) through the frames of SCENE with one incremental "
        "smoother (iSAM2) per track: one pose per frame, one shape per track, a non-holonomic motion model between "
        "poses, and a ground-plane factor when the scene gives a road plane. Writes RESULT in the format of "
        "'vfactor solve' (final, smoothed estimates; --online for the estimates as each frame arrived). Frames out "
        "of time order are tracked in time order and reported.",
    )
    p.add_argument("scene", help="scene file (JSON) with track ids in the detections' 'vehicle'")
    p.add_argument("--out", required=True, help="result file to write (JSON; written atomically)")
    p.add_argument("--allow-outside-paths", action="store_true",
                   help="accept heatmap and image paths outside the scene file's folder (refused by default)")
    p.add_argument("--lag", type=float, help="fixed lag in seconds: bounded memory and time per frame for long streams")
    p.add_argument("--batch", action="store_true", help="offline batch smoothing (Levenberg-Marquardt over each whole track)")
    p.add_argument("--online", action="store_true", help="write the estimates as each frame arrived (filtered)")
    p.add_argument("--plot", help="also write a PNG of the trajectories with covariance ellipses")
    p.add_argument("--no-covariance", action="store_true", help="skip the marginal covariances (faster)")
    p.add_argument("--weights", help="keypoint-network weights for detections given as image boxes "
                   "(default: the shipped weights; needs torch)")
    p.add_argument("--save-detections", metavar="SCENE_OUT",
                   help="also write the scene with the network's keypoints (and its heatmaps in SCENE_OUT's folder)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")

    for name, text in (
        ("train", "train the keypoint network (progress bar, checkpoints, resume, PCK per epoch); needs torch"),
        ("detect", "keypoints, confidences, covariances and heatmaps per vehicle box: IMAGE --roi X0 Y0 X1 Y1; needs torch"),
    ):
        p = sub.add_parser(name, help=text, add_help=False)
        p.add_argument("net_args", nargs=argparse.REMAINDER)

    p = sub.add_parser(
        "simulate", help="write a simulated scene (and its ground truth) from a scenario",
        description="Simulate SCENARIO (a packaged name such as intersection_2cam, or a scenario JSON file) and "
        "write the scene file the solver reads, plus the ground truth.",
    )
    p.add_argument("scenario", nargs="?", help="packaged scenario name or scenario file")
    p.add_argument("--out", help="scene file to write")
    p.add_argument("--truth", help="ground-truth file to write (default: next to --out, *_truth.json)")
    p.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    p.add_argument("--frames", type=int, help="number of frames (default: the scenario's)")
    p.add_argument("--list", action="store_true", help="list the packaged scenarios and exit")

    p = sub.add_parser(
        "demo", help="simulate, solve, compare with triangulation, write overlays and a 3D plot",
        description="The main job on a packaged scenario: simulate it, solve every frame, print the errors against "
        "ground truth next to a triangulation baseline, and write an overlay image per camera (projected "
        "wireframe on a drawn view) and a 3D plot with the position covariance ellipse. With --images the "
        "cameras' images are rendered, the keypoint network finds the keypoints in the vehicles' boxes, and the "
        "overlays show the images with the heatmaps, keypoints and the projected wireframe.",
    )
    p.add_argument("scenario", nargs="?", default="intersection_2cam", help="scenario (default: intersection_2cam)")
    p.add_argument("--out", default="vfactor_demo_out", help="output folder (default: ./vfactor_demo_out)")
    p.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    p.add_argument("--frames", type=int, help="number of frames (default: the scenario's; 3 with --images)")
    p.add_argument("--images", action="store_true",
                   help="render the cameras' images and find the keypoints with the network (needs torch, moderngl)")

    p = sub.add_parser(
        "eval", help="accuracy against simulated ground truth: one-frame methods, or tracking",
        description="frames (default): run the factor graph (each vehicle solved with a shape model learnt without "
        "it), the factor graph with the old car prior, multi-view triangulation, PnP and the known-shape reference "
        "(true wireframe given, pose solved from the truth) on the same simulated scenes, at clean noise (0.3%% of the "
        "box), paper-like noise and a harder setting (15%% outliers, 8%% left/right swaps, 10%% missing), and print "
        "the paper's metrics side by side, overall and per body type. "
        "tracks: track the vehicles of a simulated multi-frame scene with iSAM2 (online, final, fixed lag) and batch "
        "smoothing, beside frame-by-frame solving of the same frames. "
        "paper: the paper's comparison (its Tables I and II) on its three vehicles: the factor graph, CPO + HWC as "
        "published, the single-view deformable method, PnP and stereo, plus plots of the error against the noise "
        "and against the number of cameras (--figures). "
        "images: render the camera images of a simulated scenario, find the keypoints with the keypoint network in "
        "the vehicles' boxes and run the methods on them (needs torch and moderngl).",
    )
    p.add_argument("experiment", nargs="?", default="frames", choices=("frames", "tracks", "paper", "images"),
                   help="frames (one-frame accuracy), tracks (tracking), paper (the paper's tables) or images "
                   "(rendered images -> keypoint network -> graph); default: frames")
    p.add_argument("--figures", help="paper: folder for the plots (the Markdown links them as figures/NAME.png)")
    p.add_argument("--sweep-frames", type=int, default=30, help="paper: vehicles per point of the plots (default: 30)")
    p.add_argument("--scenario", help="scenario (default: library_2cam for frames, tracks_3veh for tracks, "
                   "accuracy_2cam for images)")
    p.add_argument("--levels", default="clean,paper,hard",
                   help="frames: noise levels, comma-separated, of clean, paper, hard (default: all three)")
    p.add_argument("--frames", type=int, help="number of scenes or frames (default: the scenario's)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--seeds", type=int, default=1,
                   help="frames, tracks: how many seeds from --seed on (frames: pooled in one table; default: 1)")
    p.add_argument("--draws", type=int, default=0,
                   help="tracks: also batch-smooth each seed's tracks over this many new draws of the keypoint noise "
                   "and report each final shape's mean error, bias and spread (default: 0)")
    p.add_argument("--lag", type=float, default=0.5,
                   help="tracks: the fixed lag of the isam2_lag row, seconds (default: 0.5)")
    p.add_argument("--markdown", help="also write the tables to this Markdown file")
    return parser


def main(argv=None) -> int:
    """Runs the ``vfactor`` command on ``argv`` (default: ``sys.argv[1:]``); returns the exit code (:data:`EXIT_CODES`)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("train", "detect"):  # the network's own parser; torch is imported only here
        return _guarded(argv[0], lambda: _net(argv), debug="--debug" in argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return EXIT_OK
    handlers = {"solve": _solve, "track": _track, "simulate": _simulate, "demo": _demo, "eval": _eval}
    return _guarded(args.command, lambda: handlers[args.command](args), args.debug)


def _say(text: str) -> None:
    """Prints a message on stderr: the one place where messages are made one line without escapes."""
    print(one_line(text, limit=2000), file=sys.stderr)


def _guarded(command: str, run, debug: bool) -> int:
    """Runs a command; any failure becomes one line on stderr and its exit code, never a traceback."""
    try:
        return run()
    except InputError as exc:
        _say(f"vfactor {command}: error: {exc}")
        return EXIT_INPUT
    except OSError as exc:
        _say(f"vfactor {command}: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "))
        return EXIT_INPUT
    except MemoryError:
        _say(f"vfactor {command}: error: out of memory (is an input far larger than it should be?)")
        return EXIT_INPUT
    except KeyboardInterrupt:
        _say("vfactor: interrupted")
        return EXIT_INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - the CLI reports, never dumps a bare traceback
        if debug:
            raise
        _say(f"vfactor {command}: internal error: {type(exc).__name__}: {exc} (run with --debug for details)")
        return EXIT_INTERNAL


def _net(argv: list[str]) -> int:
    """``vfactor train`` and ``vfactor detect``: the keypoint network's commands (vfactor.net.commands)."""
    try:
        from vfactor.net.commands import main as net_main
    except ImportError as exc:
        raise _missing_extra("", exc, "net") from None
    return net_main(argv, prog="vfactor")


# ---------------------------------------------------------------------------- helpers
def _progress(label: str, enabled: bool = True):
    """The progress callback of a command: a bar on a terminal, nothing otherwise."""
    from vfactor.progress import Progress

    return Progress(desc=label, enabled=enabled, tty_only=True)


def _missing_extra(field: str, exc: ImportError, extras: str, context: str = "") -> InputError:
    """The error for a command part that needs an optional extra ("net": PyTorch, "render": moderngl)."""
    needs = {"net": "PyTorch", "render": "moderngl"}
    what = " and ".join(needs[e] for e in extras.split(","))
    return InputError(field, f"{context}this needs {what} ({exc}); install with "
                             f"pip install -c constraints.txt -e '.[{extras}]'")


def _check_positive(value, name):
    if value is not None and value < 1:
        raise InputError(name, f"expected an integer >= 1, got {value}")
    return value


def _check_out_file(value, option: str, inputs=()) -> Path:
    """Checks an output file option before the work starts: not a folder, not one of ``inputs``,
    and in a folder that exists (or can be made) and is writable.

    Raises:
        InputError: (field: ``option``) what is wrong.
    """
    path = Path(value)
    if path.is_dir() or str(value).endswith(("/", os.sep)):
        raise InputError(option, f"{value} is a folder; give a file name")
    for name, given in inputs:
        if given is not None and Path(given).exists() and path.exists() and os.path.samefile(path, given):
            raise InputError(option, f"{value} is the {name} itself; write the output to another file")
    folder = path.absolute().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(option, f"cannot create {path.parent}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(option, f"cannot write into {folder}: permission denied")
    return path


def _check_out_dir(path: Path) -> Path:
    if path.exists() and not path.is_dir():
        raise InputError("--out", f"{path} exists and is not a folder")
    path.mkdir(parents=True, exist_ok=True)
    return path


def _report_unsolved(results, scene, quiet: bool) -> int:
    """Prints a line per vehicle that was not solved; returns the exit code (3 when any, else 0)."""
    code = EXIT_OK
    camera_index = {name: i for i, name in enumerate(scene.cameras)}
    for f, frame in enumerate(results):
        for v in frame.vehicles:
            if v.ok:
                continue
            message = v.message
            for name, i in camera_index.items():
                message = message.replace(f"camera '{name}'", f"camera '{name}' (cameras[{i}])")
            _say(f"frames[{f}] vehicle '{v.id}': {v.status.value}: {message}")
            code = EXIT_UNSOLVED
    return code


# ---------------------------------------------------------------------------- commands
def _detect(scene, args):
    """Runs the keypoint network on the scene's box-only detections (if any); optionally saves the result."""
    pending = scene.undetected()
    if not pending:
        if args.weights and not args.quiet:
            _say("note: every detection gives keypoints; --weights is not used")
        if args.save_detections:
            raise InputError("--save-detections", "no detection of the scene needs the keypoint network")
        return scene
    try:
        from vfactor.net.infer import KeypointDetector
        from vfactor.net.pipeline import detect_scene
    except ImportError as exc:
        f, j = pending[0]
        raise _missing_extra(f"frames[{f}].detections[{j}]", exc, "net", "given as an image box: ") from None
    try:
        detector = KeypointDetector(args.weights)
    except Exception as exc:  # noqa: BLE001 - any failure to read the weights file is bad input
        raise InputError("--weights", str(exc)) from None
    t0 = time.perf_counter()
    heatmaps_dir = None
    if args.save_detections:
        out = Path(args.save_detections)
        heatmaps_dir = out.with_name(out.stem + "_heatmaps")
    scene = detect_scene(scene, detector, heatmaps_dir=heatmaps_dir, progress=_progress("keypoints", not args.quiet))
    if args.save_detections:
        from vfactor.scene import save_scene

        save_scene(scene, args.save_detections)
    if not args.quiet:
        print(f"keypoint network: {len(pending)} boxes ({time.perf_counter() - t0:.2f} s)"
              + (f"; wrote {args.save_detections} and {heatmaps_dir}/" if args.save_detections else ""))
    return scene


def _check_outputs(args) -> None:
    """``solve`` and ``track``: --out and --save-detections checked before any work."""
    _check_out_file(args.out, "--out", [("scene file", args.scene)])
    if args.save_detections:
        _check_out_file(args.save_detections, "--save-detections",
                        [("scene file", args.scene), ("result file --out", args.out)])
        if os.path.abspath(args.save_detections) == os.path.abspath(args.out):
            raise InputError("--save-detections", f"{args.save_detections} is also --out; give another file")


def _solve(args) -> int:
    from vfactor.factors.robust import RobustLoss
    from vfactor.graph import GraphConfig
    from vfactor.scene import load_scene, save_results
    from vfactor.solve import SolveOptions, solve_scene

    _check_outputs(args)
    scene = _detect(load_scene(args.scene, allow_outside_paths=args.allow_outside_paths), args)
    options = SolveOptions(graph=GraphConfig(loss=RobustLoss(args.loss)), covariance=not args.no_covariance)
    t0 = time.perf_counter()
    results = solve_scene(scene, options, progress=_progress("solving", not args.quiet))
    save_results(args.out, results)
    vehicles = [v for fr in results for v in fr.vehicles]
    solved = sum(v.ok for v in vehicles)
    if not args.quiet:
        print(f"solved {solved} of {len(vehicles)} vehicles in {len(results)} frames "
              f"({time.perf_counter() - t0:.2f} s); wrote {args.out}")
    return _report_unsolved(results, scene, args.quiet)


def _track(args) -> int:
    from vfactor.scene import load_scene, save_results
    from vfactor.solve import SolveOptions
    from vfactor.track import TrackOptions, smooth_scene, track_scene

    if args.lag is not None and not (np.isfinite(args.lag) and args.lag > 0):
        raise InputError("--lag", f"expected a positive number of seconds, got {args.lag}")
    if args.batch and (args.lag is not None or args.online):
        raise InputError("--batch", "batch smoothing uses every frame: it takes neither --lag nor --online")
    _check_outputs(args)
    if args.plot:
        _check_out_file(args.plot, "--plot", [("scene file", args.scene), ("result file --out", args.out)])
    scene = _detect(load_scene(args.scene, allow_outside_paths=args.allow_outside_paths), args)
    options = TrackOptions(solve=SolveOptions(covariance=False), lag=args.lag, covariance=not args.no_covariance)
    t0 = time.perf_counter()
    if args.batch:
        results, messages = smooth_scene(scene, options), []
    else:
        run = track_scene(scene, options, progress=_progress("tracking", not args.quiet))
        results, messages = (run.online if args.online else run.frames), run.messages
    save_results(args.out, results)
    for message in messages:
        _say(f"note: {message}")
    vehicles = [v for fr in results for v in fr.vehicles]
    tracks = {v.id for v in vehicles}
    if not args.quiet:
        print(f"tracked {len(tracks)} vehicles over {len(results)} frames: {sum(v.ok for v in vehicles)} of "
              f"{len(vehicles)} poses solved ({time.perf_counter() - t0:.2f} s); wrote {args.out}")
    if args.plot:
        from vfactor.viz import plot_trajectories

        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        plot_trajectories(scene.cameras, results, args.plot)
        if not args.quiet:
            print(f"wrote {args.plot}")
    return _report_unsolved(results, scene, args.quiet)


def _simulate(args) -> int:
    from vfactor.sim import list_scenarios, load_scenario, simulate, write_simulation

    if args.list:
        for name in list_scenarios():
            print(f"{name:<32} {load_scenario(name).description.split('. ')[0]}")
        return EXIT_OK
    if not args.scenario or not args.out:
        raise InputError("", "give a SCENARIO and --out SCENE.json (or --list)")
    out = _check_out_file(args.out, "--out", [("scenario file", args.scenario)])
    truth = _check_out_file(args.truth if args.truth else out.with_name(out.stem + "_truth.json"), "--truth",
                            [("scenario file", args.scenario), ("scene file --out", args.out)])
    if os.path.abspath(out) == os.path.abspath(truth):
        raise InputError("--truth", f"{truth} is also --out; give another file")
    sim = simulate(load_scenario(args.scenario), seed=args.seed, num_frames=_check_positive(args.frames, "--frames"))
    write_simulation(sim, out, truth)
    ids = {vid for f in sim.scene.frames for vid in f.vehicle_ids()}
    print(f"wrote {out} ({len(sim.scene.frames)} frames, {len(ids)} vehicle ids, {len(sim.scene.cameras)} cameras) "
          f"and {truth}")
    return EXIT_OK


def _demo(args) -> int:
    from vfactor.baselines import triangulation
    from vfactor.graph import observations_from_detections
    from vfactor.metrics import pose_errors
    from vfactor.result import FrameResult
    from vfactor.scene import save_results
    from vfactor.sim import load_scenario, save_truth, simulate, write_simulation
    from vfactor.solve import SolveOptions, solve_observations
    from vfactor.viz import plot_estimates, write_overlays

    out = _check_out_dir(Path(args.out))
    scenario = load_scenario(args.scenario)
    frames = _check_positive(args.frames, "--frames")
    if args.images and frames is None:
        frames = min(scenario.num_frames, 3)  # rendering takes about a second per image
    sim = simulate(scenario, seed=args.seed, num_frames=frames)
    if args.images:  # the scene file is the rendered one (images and boxes), written by _demo_images
        save_truth(sim, out / "truth.json")
    else:
        write_simulation(sim, out / "scene.json", out / "truth.json")
    print(f"scenario {scenario.name}: {len(sim.scene.cameras)} cameras, {len(sim.scene.frames)} frames "
          f"(seed {sim.seed}); " + (f"truth in {out}/" if args.images else f"scene and truth in {out}/"))
    scene = _demo_images(sim, out) if args.images else sim.scene
    options = SolveOptions()
    results, rows = [], []
    header = f"{'frame':>5} {'vehicle':<8} {'body':<13} {'status':<10} | {'vfactor: rot deg':>16} {'trans cm':>9} {'kp cm':>7} | {'triangulation: rot':>18} {'trans':>7} {'kp':>7}"
    print(header)
    print("-" * len(header))
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
            print(f"{f:>5} {vid:<8} {truth.preset:<13} {ours.status.value:<10} | {cells[0]} | {cells[1]}")
        results.append(FrameResult(frame.t, vehicles))
    save_results(out / "result.json", results)
    for name, col in (("vfactor", 0), ("triangulation", 1)):
        ok = [r[col] for r in rows if r[col]]
        if ok:
            print(f"mean {name:<14} rotation {np.mean([e['rotation_deg'] for e in ok]):6.2f} deg   "
                  f"translation {np.mean([e['translation_cm'] for e in ok]):6.1f} cm   "
                  f"keypoints {np.mean([e['mean_keypoint_cm'] for e in ok]):6.1f} cm   ({len(ok)}/{len(rows)} solved)")
    truth0 = {vid: (t.world_T_vehicle, t.wireframe) for vid, t in sim.truth[0].items()}
    overlays = write_overlays(out, scene.cameras, scene.frames[0], results[0], truth=truth0, base_dir=scene.base_dir)
    plot = plot_estimates(scene.cameras, results[0].vehicles, truth0, out / "estimate_3d.png",
                          title=f"{scenario.name}, frame 0: estimate (solid) and truth (dashed), 3-sigma position")
    print("wrote " + ", ".join(str(p) for p in [out / "result.json", *overlays, plot]))
    return _report_unsolved(results, scene, quiet=False)


def _demo_images(sim, out: Path):
    """``vfactor demo --images``: renders the simulation's camera images and finds the keypoints with the network."""
    try:
        from vfactor.net.infer import KeypointDetector
        from vfactor.net.pipeline import detect_scene
        from vfactor.render import RenderingUnavailable
        from vfactor.render.scenes import render_simulation
        from vfactor.scene import save_scene
    except ImportError as exc:
        raise _missing_extra("--images", exc, "net,render") from None
    t0 = time.perf_counter()
    try:
        rendered = render_simulation(sim, out, seed=sim.seed, progress=_progress("rendering"))
    except RenderingUnavailable as exc:
        raise InputError("--images", f"cannot render: {exc}") from None
    except ValueError as exc:  # e.g. a scenario camera without image_size
        raise InputError("--images", str(exc)) from None
    print(f"rendered {sum(len(f.images) for f in rendered.scene.frames)} camera images into {out / 'images'}/ "
          f"({time.perf_counter() - t0:.1f} s); boxes only in {rendered.path}")
    t0 = time.perf_counter()
    scene = detect_scene(rendered.scene, KeypointDetector(), heatmaps_dir=out / "heatmaps")
    save_scene(scene, out / "scene_keypoints.json")
    boxes = sum(len(f.detections) for f in scene.frames)
    print(f"keypoint network: {boxes} boxes ({time.perf_counter() - t0:.1f} s); keypoints in "
          f"{out / 'scene_keypoints.json'}, heatmaps in {out / 'heatmaps'}/")
    return scene


def _error_cells(errors: dict | None, widths) -> str:
    if errors is None:
        return " ".join(f"{'-':>{w}}" for w in widths)
    values = (errors["rotation_deg"], errors["translation_cm"], errors["mean_keypoint_cm"])
    return " ".join(f"{v:>{w}.{2 if i == 0 else 1}f}" for i, (v, w) in enumerate(zip(values, widths)))


def _eval(args) -> int:
    t0 = time.perf_counter()
    if args.markdown:
        _check_out_file(args.markdown, "--markdown")
    frames = _check_positive(args.frames, "--frames")
    _check_positive(args.seeds, "--seeds")
    if args.draws < 0:
        raise InputError("--draws", f"expected an integer >= 0, got {args.draws}")
    if not (np.isfinite(args.lag) and args.lag > 0):
        raise InputError("--lag", f"expected a positive number of seconds, got {args.lag}")
    if args.experiment == "frames":
        sections = _eval_frames(args.scenario or "library_2cam", frames, args.seed, _levels(args.levels), args.seeds)
    elif args.experiment == "tracks":
        sections = _eval_tracks(args.scenario or "tracks_3veh", frames, args.seed, args.seeds, args.draws, args.lag)
    elif args.experiment == "images":
        sections = _eval_images(args.scenario or "accuracy_2cam", frames, args.seed)
    else:
        if args.scenario:
            raise InputError("--scenario", "the paper comparison uses its own scenario (paper_webots)")
        from vfactor.paper_comparison import paper_report

        sections = [paper_report(frames, args.seed, args.figures, _check_positive(args.sweep_frames, "--sweep-frames"))]
    default = {"frames": "library_2cam", "tracks": "tracks_3veh", "paper": None, "images": "accuracy_2cam"}[
        args.experiment]
    command = "vfactor eval" + (f" {args.experiment}" if args.experiment != "frames" else "") + \
        (f" --scenario {args.scenario}" if args.scenario and args.scenario != default else "") + \
        (f" --frames {args.frames}" if args.frames else "") + (f" --seed {args.seed}" if args.seed else "") + \
        (f" --seeds {args.seeds}" if args.seeds != 1 else "") + (f" --draws {args.draws}" if args.draws else "") + \
        (f" --lag {args.lag:g}" if args.experiment == "tracks" and args.lag != 0.5 else "") + \
        (f" --levels {args.levels}" if args.experiment == "frames" and args.levels != "clean,paper,hard" else "") + \
        (f" --figures {args.figures}" if args.figures else "") + \
        (f" --sweep-frames {args.sweep_frames}" if args.experiment == "paper" and args.sweep_frames != 30 else "")
    for section in sections:
        print(section)
    print(f"({command}; {time.perf_counter() - t0:.1f} s)")
    if args.markdown:
        write_text_atomic(args.markdown, f"<!-- made by: {command} -->\n\n" + "\n".join(sections))
    return EXIT_OK


def _levels(text: str) -> tuple[str, ...]:
    from vfactor.evaluation import NOISE_LEVELS

    levels = tuple(t.strip() for t in text.split(",") if t.strip())
    unknown = [t for t in levels if t not in NOISE_LEVELS]
    if not levels or unknown:
        raise InputError("--levels", f"expected a comma-separated list of {', '.join(NOISE_LEVELS)}, got {text!r}")
    return levels


def _eval_frames(scenario_name: str, frames, seed: int, levels=("clean", "paper", "hard"), seeds: int = 1) -> list[str]:
    from vfactor.evaluation import (accuracy_table, body_type_table, consistency_table, keypoint_table, run_accuracy,
                                    summarise_methods)

    sections = []
    which = f"seed {seed}" if seeds == 1 else f"seeds {seed}-{seed + seeds - 1}"
    for scenario, rows in run_accuracy(scenario_name, frames, seed, levels, seeds=seeds):
        n = scenario.noise
        summary = summarise_methods(rows)
        title = (f"### {scenario.name}: {n.outlier_rate:.0%} outliers, {n.swap_rate:.0%} left/right swaps, "
                 f"{n.missing_rate:.0%} missing, sigma {n.relative_sigma:.1%} of the box diagonal "
                 f"(x{n.occluded_factor:g} when self-occluded), {which}")
        sections.append(f"{title}\n\n{accuracy_table(summary)}\n\nPer body type (each vehicle solved with a "
                        f"shape model learnt without it):\n\n{body_type_table(rows)}\n\nConsistency of the factor "
                        f"graph's covariances (NEES; consistent: 1.00x and 95 %):\n\n{consistency_table(rows)}\n\n"
                        f"Mean error per keypoint (cm):\n\n{keypoint_table(summary)}\n")
    return sections


def _eval_images(scenario_name: str, frames, seed: int) -> list[str]:
    try:
        from vfactor.net.end_to_end import evaluate_images, images_report
    except ImportError as exc:
        raise _missing_extra("images", exc, "net,render") from None
    return [images_report(evaluate_images(scenario_name, frames, seed, progress=_progress("rendering")))]


def _eval_tracks(scenario_name: str, frames, seed: int, seeds: int, draws: int = 0, lag: float = 0.5) -> list[str]:
    from vfactor.evaluation import compare_tracking, shape_draws_table, shape_over_noise_draws, tracking_table
    from vfactor.sim import load_scenario, simulate

    scenario = load_scenario(scenario_name)
    if scenario.motion is None:
        raise InputError("--scenario", f"{scenario.name!r} has no motion: each frame holds new vehicles, so there "
                         "is nothing to track; use a scenario with tracks, e.g. tracks_3veh or tracks_3cam")
    sections = []
    for s in range(seed, seed + seeds):
        sim = simulate(scenario, seed=s, num_frames=frames)
        ids = sorted({vid for f in sim.scene.frames for vid in f.vehicle_ids()})
        title = (f"### {scenario.name}, seed {s}: {len(sim.scene.frames)} frames, {len(ids)} vehicles, "
                 f"{len(sim.scene.cameras)} cameras" + (", road plane given" if sim.scene.ground_plane else ""))
        sections.append(f"{title}\n\n{tracking_table(compare_tracking(sim, lag=lag))}\n")
        if draws:
            sections.append(f"Final shapes of batch smoothing over {draws} draws of the keypoint noise (same "
                            f"vehicles and motion):\n\n{shape_draws_table(shape_over_noise_draws(sim, draws))}\n")
    return sections


if __name__ == "__main__":
    sys.exit(main())
