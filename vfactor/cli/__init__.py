"""The ``vfactor`` command: solve scene files, simulate scenarios, run the demo and the accuracy evaluation.

This package holds the parser and the dispatch; each group of commands has its
own module: :mod:`vfactor.cli.estimate` (solve, track), :mod:`vfactor.cli.simulation`
(simulate, demo), :mod:`vfactor.cli.evaluate` (eval), :mod:`vfactor.cli.tools`
(schema, plot), :mod:`vfactor.cli.interop` (import), :mod:`vfactor.cli.common` (checks and messages they share).
The keypoint network's commands (train, detect, calibrate, calibrate-shape, calibrate-bias, score) are forwarded
to :mod:`vfactor.net.commands`, so that PyTorch is imported only for them.

Options every command takes, before or after its name: ``--debug`` (tracebacks
of internal errors), ``-v`` / ``-vv`` (more messages on stderr: the ``vfactor``
logger at INFO / DEBUG) and ``-q`` (nothing but errors).

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

from vfactor._version import __version__
from vfactor.cli.common import (EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_OK, EXIT_TERMINATED, EXIT_UNSOLVED,
                                configure_logging, say)
from vfactor.errors import InputError
from vfactor.sanity import one_line

__all__ = ["main", "build_parser", "EXIT_CODES", "EXIT_OK", "EXIT_INTERNAL", "EXIT_INPUT", "EXIT_UNSOLVED",
           "NET_COMMANDS"]

#: Exit code -> meaning (the epilog of ``vfactor --help`` and docs/reliability.md).
EXIT_CODES = {
    EXIT_OK: "success: every vehicle solved (some may be reported poor_fit: solved, with a warning)",
    EXIT_INTERNAL: "internal error (a bug: run again with --debug for the traceback)",
    EXIT_INPUT: "bad input: a malformed scene, scenario, calibration or option (one line names the field)",
    EXIT_UNSOLVED: "some vehicles could not be solved: reported degenerate or failed (result file and stderr)",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C): the result file left as it was",
    EXIT_TERMINATED: "terminated (SIGTERM, as a job scheduler stops a job): the result file left as it was",
}

_DESCRIPTION = """\
vfactor estimates each vehicle's 6-DoF pose (world_T_vehicle), its 12-keypoint
wireframe (metres) and their covariances from several fixed, calibrated cameras
that each see the vehicle from their own side, as a GTSAM factor graph.

Start here:
  vfactor demo                          simulate a two-camera intersection, solve it,
                                        compare with triangulation, write pictures
  vfactor simulate --list               the packaged scenarios (camera rigs, vehicles, noise)
  vfactor simulate intersection_2cam --out scene.json   (truth: scene_truth.json)
  vfactor solve scene.json --out result.json      every frame on its own
  vfactor track scene.json --out result.json      tracks over frames (iSAM2: shared shape, motion)
  vfactor eval                          accuracy against ground truth, beside baselines

Scene and result formats, conventions and the factors' maths: docs/ in the
repository (conventions.md, factors.md, tutorial.md); limits and exit codes:
docs/reliability.md."""

_EPILOG = "exit codes:\n" + "\n".join(f"  {code:<4}{text}" for code, text in EXIT_CODES.items())


#: The keypoint network's commands, forwarded to :mod:`vfactor.net.commands` (they need torch): name -> help.
NET_COMMANDS = {
    "train": "train the keypoint network (progress bar, checkpoints, resume, PCK per epoch); needs torch",
    "detect": "keypoints, confidences, covariances and heatmaps per vehicle box: IMAGE --roi X0 Y0 X1 Y1; needs torch",
    "calibrate": "fit the network's keypoint covariances to its errors on held-out crops; needs torch",
    "calibrate-shape": "fit the network's error shaped like a change of shape on solved rendered scenes; needs torch",
    "calibrate-bias": "fit the network's error that repeats over a vehicle's frames on rendered tracks; needs torch",
    "score": "PCK@0.1 of network weights on crops with known keypoints; needs torch",
}


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit 2)."""

    def error(self, message):
        self.exit(EXIT_INPUT, f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


def _common_options(defaults: bool) -> argparse.ArgumentParser:
    """The options of every command: on the main parser with their defaults, on each command without (so that
    an option given before the command name is not reset by the command's parser)."""
    p = argparse.ArgumentParser(add_help=False)
    g = p.add_argument_group("options of every command")

    def default(value):
        return value if defaults else argparse.SUPPRESS

    g.add_argument("--debug", action="store_true", default=default(False),
                   help="show the traceback of an internal error")
    g.add_argument("-v", "--verbose", action="count", default=default(0),
                   help="more messages on stderr: -v what each step does (INFO), -vv details (DEBUG)")
    g.add_argument("-q", "--quiet", action="store_true", default=default(False),
                   help="print nothing but errors (no summaries, notes or progress bars)")
    return p


def _rig_fit_options(p: argparse.ArgumentParser, scene: str, out: str, what: str, gain: str) -> None:
    """The arguments of a command that fits a rig to its traffic (fit-ground, fit-extrinsics): SCENE (``scene``
    says what it must hold), ``--out`` (``out``: what is written), more scenes of the rig, the keypoint network's
    weights, outside paths."""
    p.add_argument("scene", help=f"scene file (JSON, docs/scene-format.md) {scene}")
    p.add_argument("--out", required=True, help=f"scene file to write: SCENE with {out} (atomically)")
    p.add_argument("--traffic", action="append", metavar="FILE",
                   help=f"another scene file of the same cameras whose {what} join the fit (repeatable): more "
                   f"traffic, {gain}")
    p.add_argument("--weights", help="keypoint-network weights for detections given as image boxes (default: the "
                   "shipped weights; needs torch); the scene is written with its boxes as given")
    p.add_argument("--allow-outside-paths", action="store_true",
                   help="accept heatmap and image paths outside the scene file's folder (refused by default)")
    p.set_defaults(save_detections=None)  # of the keypoint network's options (vfactor.cli.common.detect) only --weights


def build_parser() -> argparse.ArgumentParser:
    """The ``vfactor`` parser (the network's commands, :data:`NET_COMMANDS`, only as names: their own parser
    lives in :mod:`vfactor.net.commands`)."""
    parser = _Parser(
        prog="vfactor", description=_DESCRIPTION, epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[_common_options(defaults=True)],
    )
    parser.add_argument("--version", action="version", version=f"vfactor {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    parser.commands = sub.choices  # command name -> its parser (vfactor help COMMAND)
    common = [_common_options(defaults=False)]

    def add(name, **kwargs):
        return sub.add_parser(name, parents=common, **kwargs)

    p = add(
        "solve", help="estimate every vehicle of every frame of a scene file (frames solved one by one)",
        description="Estimate every vehicle of every frame of SCENE on its own (Levenberg-Marquardt, robust to "
        "outlier keypoints and left/right swaps) and write RESULT with poses, wireframes, 3D boxes, covariances and a "
        "status per vehicle. A vehicle that cannot be solved is reported with status 'degenerate' or 'failed' and a "
        "message; the others are still solved. A vehicle whose keypoints fit at least twice worse than their sigmas "
        "is reported 'poor_fit' with its estimate and a warning. Detections given as boxes in the frames' images go through the "
        "keypoint network first (needs torch). Scene format: docs/scene-format.md (vfactor schema prints its "
        "JSON Schema).",
    )
    _estimate_options(p)
    p.add_argument("--loss", default="cauchy", choices=("none", "huber", "cauchy", "geman_mcclure"),
                   help="robust loss per keypoint (default: cauchy)")

    p = add(
        "track", help="track every vehicle through the frames of a scene (iSAM2, shared shape, motion model)",
        description="Track every vehicle (by its track id) through the frames of SCENE with one incremental "
        "smoother (iSAM2) per track: one pose per frame, one shape per track, a non-holonomic motion model between "
        "poses, and a ground-plane factor when the scene gives a road plane. Writes RESULT in the format of "
        "'vfactor solve' (final, smoothed estimates; --online for the estimates as each frame arrived). Frames out "
        "of time order are tracked in time order and reported. Scene format: docs/scene-format.md.",
    )
    _estimate_options(p)
    p.add_argument("--lag", type=float, help="fixed lag in seconds: bounded memory and time per frame for long streams")
    p.add_argument("--batch", action="store_true", help="offline batch smoothing (Levenberg-Marquardt over each whole track)")
    p.add_argument("--online", action="store_true", help="write the estimates as each frame arrived (filtered)")
    p.add_argument("--detector-offsets", action=argparse.BooleanOptionalAction, default=None,
                   help="give each camera's detections of a track a pose offset (a small rigid motion of the vehicle as "
                   "that camera sees it) whose prior comes from their shape_sigma (keypoint-network detections: "
                   "errors that repeat from frame to frame; docs/factors.md); default: on where the scene gives a "
                   "road plane (vfactor fit-ground), off without one. Detections with a bias_sigma (the network's "
                   "error shared by all cameras) give the track one offset its cameras share, unless "
                   "--no-detector-offsets")
    p.add_argument("--plot", help="also write a PNG of the trajectories with covariance ellipses")
    g = p.add_argument_group("live streams (docs/scaling.md): SCENE '-' reads JSON Lines from standard input")
    g.add_argument("--follow", action="store_true",
                   help="SCENE is a JSON Lines stream that another program is still writing: track each frame as "
                   "its line arrives (like tail -f); --out - writes a result line per frame to standard output")
    g.add_argument("--idle-timeout", type=float, metavar="SECONDS",
                   help="with --follow, stop after this long without a new line (default: until interrupted)")

    p = add(
        "fit-ground", help="fit a rig's road plane to the vehicles it tracks; write the scene with it",
        description="Track every vehicle of SCENE (which gives no road plane), fit a plane to the tracked wheel hubs "
        "(robust to vehicles metres off), move it down by the hub height and write SCENE_OUT: SCENE with that plane "
        "as its ground_plane. Solves and tracks of the rig's later scenes can then use it: it holds each vehicle's "
        "height, roll and pitch to the road (docs/factors.md, \"A plane nobody surveyed\"; docs/results.md, \"The "
        "road plane from the traffic\").",
    )
    _rig_fit_options(p, "without a ground_plane", "the fitted ground_plane", "tracks", "a better plane")
    p.add_argument("--hub-height", type=float,
                   help="height of the wheel hubs above the road, metres, for every vehicle (default: each vehicle's "
                        "body type's wheel radius, as the ground-plane factor takes it)")
    p.add_argument("--batch", action="store_true", help="fit to batch-smoothed tracks instead of iSAM2's")

    p = add(
        "fit-extrinsics", help="fit a rig's camera poses to the vehicles they see; write the scene with them",
        description="Solve every vehicle of SCENE one frame at a time, then all of them at once with each camera's "
        "error (its true pose: world_T_camera times that error) as a variable under the prior its extrinsic_sigma "
        "gives, and write SCENE_OUT: SCENE with each camera moved by its fitted error and the fit's standard "
        "deviations as its extrinsic_sigma. Vehicles seen by two cameras tell where each camera is relative to the "
        "others, a road plane the rig's height, roll and pitch; what the traffic does not show stays with the prior "
        "(docs/factors.md, \"The cameras' errors fitted to the traffic\"; docs/results.md, \"Cameras fitted to "
        "their traffic\"). Cameras that declare no extrinsic_sigma are held where they are, unless "
        "--extrinsic-sigma gives them one.",
    )
    _rig_fit_options(p, "whose cameras declare an extrinsic_sigma", "the fitted cameras", "vehicles", "a better fit")
    p.add_argument("--extrinsic-sigma", metavar="DEG,M",
                   help="the survey's accuracy (degrees and metres per camera axis) of the cameras that declare no "
                   "extrinsic_sigma, e.g. 0.5,0.1 (default: those cameras are held where they are)")
    _scale_options(p, "solve the vehicles (one frame at a time, both rounds) on")
    p.add_argument("--shape-per-frame", action="store_true",
                   help="give each vehicle a shape in each frame (default: one shape per vehicle id over its frames, "
                   "as the scene format's ids follow one vehicle; for scenes whose ids are numbered per frame)")

    for name, text in NET_COMMANDS.items():
        p = sub.add_parser(name, help=text, add_help=False)
        p.add_argument("net_args", nargs=argparse.REMAINDER)

    p = add(
        "simulate", help="write a simulated scene (and its ground truth) from a scenario",
        description="Simulate SCENARIO (a packaged name such as intersection_2cam, or a scenario JSON file, "
        "docs/scenarios.md) and write the scene file the solver reads, plus the ground truth.",
    )
    p.add_argument("scenario", nargs="?", help="packaged scenario name or scenario file")
    p.add_argument("--out", help="scene file to write")
    p.add_argument("--truth", help="ground-truth file to write (default: next to --out, NAME_truth.json)")
    p.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    p.add_argument("--frames", type=int, help="number of frames (default: the scenario's)")
    p.add_argument("--list", action="store_true", help="list the packaged scenarios and exit")

    p = add(
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
    p.add_argument("--frame", type=int, default=0, help="the frame the overlays and the 3D plot show (default: 0)")
    p.add_argument("--images", action="store_true",
                   help="render the cameras' images and find the keypoints with the network (needs torch, moderngl)")

    p = add(
        "plot", help="overlays per camera and a 3D plot of one frame of a scene and its result",
        description="Draw frame N of SCENE with the estimates of RESULT: one overlay PNG per camera (the "
        "detections, the projected wireframes and boxes, labelled by vehicle) and a 3D and top-down plot with the "
        "position covariance ellipses, into the folder --out.",
    )
    p.add_argument("scene", help="scene file (JSON)")
    p.add_argument("result", help="result file of vfactor solve or track (JSON)")
    p.add_argument("--out", required=True, help="folder for the pictures")
    p.add_argument("--frame", type=int, default=0, help="frame index in the scene file (default: 0)")
    p.add_argument("--truth", help="ground-truth file of vfactor simulate: also draw the true wireframes")
    p.add_argument("--allow-outside-paths", action="store_true",
                   help="accept heatmap and image paths outside the scene file's folder (refused by default)")

    p = add(
        "schema", help="print the JSON Schema of the scene file (or of the result file)",
        description="Print the JSON Schema (draft 2020-12) of vfactor's scene file, or with 'result' of its result "
        "file; docs/scene-format.md explains every field. The loader checks more than a schema can (e.g. that a "
        "rotation is a rotation, that detections name existing cameras) and names the field of any problem.",
    )
    p.add_argument("which", nargs="?", default="scene", choices=("scene", "result"),
                   help="scene (default) or result")
    p.add_argument("--out", help="write the schema to this file instead of standard output")

    p = add(
        "import", help="detections of other tools into a scene file (COCO keypoint results or annotations)",
        description="Build a scene file from a keypoint detector's or a data set's files: coco reads, per camera, a "
        "COCO keypoint results list (mmpose, OpenPifPaf, detectron2) or a COCO annotation file, in a named "
        "keypoint set (vfactor12, carfusion14, apollocar3d24, apollocar3d66) mapped to vfactor's 12 keypoints; "
        "docs/keypoint-sets.md gives the tables and every option. The cameras come from a scene or cameras file.",
    )
    p.add_argument("source", choices=("coco",), help="the files' format: coco")
    p.add_argument("--cameras", required=True, help="JSON file with the calibrated cameras (a scene file's 'cameras')")
    p.add_argument("--results", action="append", metavar="CAMERA=FILE", required=True,
                   help="a camera's COCO keypoint file (repeat for each camera)")
    p.add_argument("--keypoints", required=True, choices=("vfactor12", "carfusion14", "apollocar3d24", "apollocar3d66"),
                   help="the files' keypoint set")
    p.add_argument("--out", required=True, help="scene file to write")
    p.add_argument("--fps", type=float, help="frames per second: frame k at t = k / fps (default: the images' "
                   "timestamps, else t = k)")
    p.add_argument("--values", default="auto", choices=("auto", "confidence", "visibility"),
                   help="the third number per keypoint (default auto: confidence in results lists, COCO visibility "
                   "in annotation files)")
    p.add_argument("--min-score", type=float, default=0.0, help="leave out detections scored lower (default 0)")
    p.add_argument("--min-confidence", type=float, default=0.0,
                   help="a keypoint with a lower confidence is not seen (default 0)")
    p.add_argument("--frames", default="auto", choices=("auto", "image_id", "file_name"),
                   help="image -> frame: image_id is the frame index, or the k-th image by file_name is frame k "
                   "(default auto: file_name when every camera has an images list)")
    p.add_argument("--images", action="append", metavar="CAMERA=FILE",
                   help="a COCO annotation file whose 'images' a camera's results list refers to (repeatable)")
    p.add_argument("--pixel-origin", default="centre", choices=("centre", "corner"),
                   help="where pixel (0, 0) is: the centre of the top-left pixel (COCO, vfactor; default) or its "
                   "outer corner (0.5 px is subtracted)")
    p.add_argument("--track-ids", default="shared", choices=("shared", "per-camera"),
                   help="what an entry's track_id is: the vehicle id every camera shares (default), or the id a "
                   "camera's own 2D tracker gave (mmpose, OpenPifPaf): then the vehicles are found from geometry "
                   "and the ids help follow them (docs/association.md)")

    p = add("help", help="show the help of a command: vfactor help solve",
            description="Show the help of COMMAND (the same as vfactor COMMAND --help), or of vfactor itself.")
    p.add_argument("topic", nargs="?", metavar="COMMAND", help="a command")

    p = add(
        "eval", help="accuracy against simulated ground truth: one-frame methods, or tracking",
        description="frames (default): run the factor graph (each vehicle solved with a shape model learnt without "
        "it), the factor graph with the old car prior, multi-view triangulation, PnP and the known-shape reference "
        "(true wireframe given, pose solved from the truth) on the same simulated scenes, at clean noise (0.3% of the "
        "box), paper-like noise and a harder setting (15% outliers, 8% left/right swaps, 10% missing), and print "
        "the paper's metrics side by side, overall and per body type. "
        "tracks: track the vehicles of a simulated multi-frame scene with iSAM2 (online, final, fixed lag) and batch "
        "smoothing, beside frame-by-frame solving of the same frames. "
        "paper: the paper's comparison (its Tables I and II) on its three vehicles: the factor graph, CPO + HWC as "
        "published, the single-view deformable method, PnP and stereo, plus plots of the error against the noise "
        "and against the number of cameras (--figures). "
        "images: render the camera images of a simulated scenario, find the keypoints with the keypoint network in "
        "the vehicles' boxes and run the methods on them (needs torch and moderngl). "
        "association: remove the vehicle ids of simulated scenes of many vehicles (camera track ids with switches, "
        "missed and false detections), find the vehicles again, track them, and score it (pairs across cameras, "
        "CLEAR-MOT, pose errors) beside the same scenes tracked with the true ids (needs motmetrics).",
    )
    p.add_argument("experiment", nargs="?", default="frames", choices=("frames", "tracks", "paper", "images",
                                                                       "association"),
                   help="frames (one-frame accuracy), tracks (tracking), paper (the paper's tables), images "
                   "(rendered images -> keypoint network -> graph) or association (no ids); default: frames")
    p.add_argument("--figures", help="paper: folder for the plots (the Markdown links them as figures/NAME.png)")
    p.add_argument("--sweep-frames", type=int, help="paper: vehicles per point of the plots (default: 30)")
    p.add_argument("--scenario", help="scenario (default: library_2cam for frames, tracks_3veh for tracks, "
                   "accuracy_2cam for images, association_4cam and association_3cam for association)")
    p.add_argument("--levels",
                   help="frames, association: keypoint noise levels, comma-separated, of clean, paper, hard, "
                   "noisy, noisy_hard (6 %% of the box: twice the solve's nominal sigma), sharp (1 %%: a good "
                   "detector), gross (25 %% outliers), sharp_hard (1 %% with hard's gross errors), occluded (35 %% "
                   "missing) (default: clean, paper, hard for frames; the scenario's own, the paper's, for "
                   "association)")
    p.add_argument("--frames", type=int, help="number of scenes or frames (default: the scenario's)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--seeds", type=int, default=1,
                   help="frames, tracks, images, association: how many seeds from --seed on (frames: pooled in one "
                   "table; tracks and images: each seed, then pooled per body type; default: 1)")
    p.add_argument("--draws", type=int, default=0,
                   help="tracks: also batch-smooth each seed's tracks over this many new draws of the keypoint noise "
                   "and report each final shape's mean error, bias and spread (default: 0)")
    p.add_argument("--lag", type=float, help="tracks: the fixed lag of the isam2_lag row, seconds (default: 0.5)")
    p.add_argument("--body-motion", metavar="ROLL,PITCH",
                   help="tracks: the simulated bodies roll and pitch on their suspension, ROLL and PITCH degrees per g "
                   "of lateral and longitudinal acceleration (vfactor.sim.BodyMotion; default: rigid vehicles)")
    p.add_argument("--extrinsic-error", metavar="DEG,M",
                   help="frames, tracks: the scene's cameras err from the true ones (a survey's error) by draws of "
                   "DEG degrees and M metres per camera axis, and carry these as their extrinsic_sigma, which the "
                   "covariances take in (vfactor.sim.ExtrinsicError; default: exact cameras)")
    p.add_argument("--undeclared-extrinsics", action="store_true",
                   help="with --extrinsic-error: the cameras carry no extrinsic_sigma (as if taken as exact)")
    p.add_argument("--road-plane", action="store_true",
                   help="frames: the factor graph solves with the simulated road plane given (z = 0, "
                   "SolveOptions.ground_plane), as on a rig whose road is surveyed (default: no plane)")
    p.add_argument("--rig", metavar="SCENE",
                   help="frames, tracks: the cameras of this scene file (yours) in place of the scenario's, moved "
                   "along the road so that where they look is the scenario's centre (vfactor.sim.scenario_on_cameras; "
                   "frames: each vehicle whole in at least one view): how vfactor does on your rig, per body type "
                   "and camera count")
    p.add_argument("--markdown", help="also write the tables to this Markdown file")
    p.add_argument("--weights", help="images: keypoint-network weights to evaluate (default: the shipped weights)")
    p.add_argument("--clipped-boxes", action="store_true",
                   help="images: give the network each vehicle's box clipped to the image, as a 2D detector gives it "
                   "(default: the whole vehicle's box, beyond the image where the image cuts the vehicle)")
    p.add_argument("--real-roofs", action=argparse.BooleanOptionalAction, default=None,
                   help="images: draw each vehicle's roof at its real height (a library vehicle's published one; the "
                   "default); --no-real-roofs: at its window tops, the renderer's earlier default "
                   "(docs/rendering.md, \"Roofs\")")
    p.add_argument("--amodal-pass", action="store_true",
                   help="images, with --clipped-boxes: find the clipped vehicles' keypoints again in the boxes of the "
                   "vehicles a first solve found (tracked where the scenario moves), then evaluate "
                   "(vfactor.net.amodal)")
    p.add_argument("--detector-offsets", action=argparse.BooleanOptionalAction, default=None,
                   help="images: track with each camera's detector pose offset (TrackOptions.detector_offsets; "
                   "default: on where the scene gives a road plane)")
    _scale_options(p, "frames, tracks, association: spread the simulated scenes (one per noise level and seed) over")
    return parser


def _scale_options(p: argparse.ArgumentParser, what: str = "spread the work over") -> None:
    """``--workers`` and ``--scheduler`` (vfactor.parallel)."""
    g = p.add_argument_group("scale-out (docs/scaling.md; needs the 'dask' extra)")
    g.add_argument("--workers", type=int, metavar="N",
                   help=f"{what} a local Dask cluster of N worker processes (default: this process)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help=f"{what} the running Dask cluster whose scheduler is at ADDRESS (tcp://host:8786)")


def _estimate_options(p: argparse.ArgumentParser) -> None:
    """The arguments ``solve`` and ``track`` share: the scene, the result and its format, cameras, association,
    covariances, paths, the keypoint network."""
    p.add_argument("scene", help="scene file (JSON, see docs/scene-format.md; vfactor schema prints its JSON Schema); or "
                   "a folder or a quoted glob ('site*/scene.json') of scene files, each with its own result in the "
                   "folder --out (docs/scaling.md)")
    p.add_argument("--out", required=True, help="result file to write (written atomically; a folder for --format kitti, "
                   "and for many scenes)")
    _scale_options(p)
    p.add_argument("--no-covariance", action="store_true", help="skip the marginal covariances (faster)")
    p.add_argument("--associate", action="store_true",
                   help="find the vehicles from geometry even where the detections name them (ids not trusted); "
                   "without it, only frames that name no vehicle but hold several per camera are associated "
                   "(docs/association.md)")
    p.add_argument("--format", default="vfactor", choices=("vfactor", "openlabel", "kitti", "nuscenes", "csv"),
                   help="the result's format (docs/output-formats.md): vfactor (default; JSON with poses, wireframes, "
                   "covariances, boxes), openlabel (ASAM OpenLABEL 1.0 JSON), kitti (a folder of label files per "
                   "camera), nuscenes (detection results JSON), csv")
    p.add_argument("--kitti-frame", choices=("camera", "level"), default=None,
                   help="--format kitti: the label frame, the camera's own (default) or the camera turned level, "
                   "whose upright boxes are exact for level vehicles seen by a tilted roadside camera "
                   "(docs/output-formats.md)")
    p.add_argument("--camera", action="append", metavar="NAME=FILE",
                   help="take camera NAME's calibration from FILE (OpenCV, ROS camera_info, Kalibr camchain or a 3x4 "
                   "projection matrix; docs/calibration.md): its intrinsics, and its extrinsic where the file has one "
                   "(repeatable)")
    p.add_argument("--allow-outside-paths", action="store_true",
                   help="accept heatmap, image and calibration paths outside the scene file's folder (refused by "
                   "default)")
    p.add_argument("--weights", help="keypoint-network weights for detections given as image boxes "
                   "(default: the shipped weights; needs torch)")
    p.add_argument("--save-detections", metavar="SCENE_OUT",
                   help="also write the scene with the network's keypoints (and its heatmaps in SCENE_OUT's folder)")
    p.add_argument("--amodal-pass", action="store_true",
                   help="detections given as image boxes: where a box stops at the image border (a 2D detector's box "
                   "of a vehicle the border cuts), find that vehicle's keypoints again in the box of the vehicle the "
                   "first solve found, beyond the border, and solve again (vfactor.net.amodal; docs/network.md)")


class Terminated(KeyboardInterrupt):
    """SIGTERM (a job scheduler or ``kill`` stopping the command), raised where the command is, so that it ends as an
    interrupt does: the result file it was writing left as it was, its temporary file removed, one line said."""


def _terminated(signum, frame):
    raise Terminated()


def main(argv=None) -> int:
    """Runs the ``vfactor`` command on ``argv`` (default: ``sys.argv[1:]``); returns the exit code (:data:`EXIT_CODES`)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return _main(argv)
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        return _main(argv)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    if command in NET_COMMANDS:  # the network's own parser; torch is imported only here
        return _net(argv, command)
    parser = build_parser()
    args = parser.parse_args(argv)
    configure_logging(args.verbose, args.quiet)
    if args.command is None:
        parser.print_help()
        return EXIT_OK
    if args.command == "help":
        return _help(parser, args.topic)
    from vfactor.cli import estimate, evaluate, extrinsics, ground, interop, simulation, tools

    handlers = {"solve": estimate.solve, "track": estimate.track, "simulate": simulation.simulate,
                "demo": simulation.demo, "eval": evaluate.evaluate, "plot": tools.plot, "schema": tools.schema,
                "import": interop.import_detections, "fit-ground": ground.fit_ground,
                "fit-extrinsics": extrinsics.fit_extrinsics}
    return _guarded(args.command, lambda: handlers[args.command](args), args.debug)


def _help(parser: argparse.ArgumentParser, topic: str | None) -> int:
    """``vfactor help [COMMAND]``."""
    if topic is None:
        parser.print_help()
        return EXIT_OK
    if topic in NET_COMMANDS:
        return _net([topic, "--help"], topic)
    commands = parser.commands
    if topic not in commands:
        say(f"vfactor help: error: no command {topic!r}; the commands: {', '.join(commands)}")
        return EXIT_INPUT
    commands[topic].print_help()
    return EXIT_OK


def _guarded(command: str, run, debug: bool) -> int:
    """Runs a command; any failure becomes one line on stderr and its exit code, never a traceback."""
    try:
        return run()
    except InputError as exc:
        say(f"vfactor {command}: error: {exc}")
        return EXIT_INPUT
    except BrokenPipeError:  # the reader of stdout went away (vfactor ... | head): nothing left to say
        try:
            sys.stdout = open(os.devnull, "w")  # so that the interpreter's final flush does not fail again
        except OSError:
            pass
        return EXIT_OK
    except OSError as exc:
        say(f"vfactor {command}: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "))
        return EXIT_INPUT
    except MemoryError:
        say(f"vfactor {command}: error: out of memory (is an input far larger than it should be?)")
        return EXIT_INPUT
    except KeyboardInterrupt as exc:
        if isinstance(exc, Terminated):
            say("vfactor: terminated (SIGTERM)")
            return EXIT_TERMINATED
        say("vfactor: interrupted")
        return EXIT_INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - the CLI reports, never dumps a bare traceback
        if debug:
            raise
        say(f"vfactor {command}: internal error: {type(exc).__name__}: {exc} (run with --debug for details)")
        return EXIT_INTERNAL


def _net(argv: list[str], command: str) -> int:
    """``vfactor train|detect|calibrate|calibrate-shape|calibrate-bias|score``: the keypoint network's commands
    (:mod:`vfactor.net.commands`).

    The options of every command are taken out of ``argv`` wherever they stand; ``-q`` is passed on as the
    network's ``--quiet`` (no progress bar) where the command has one.
    """
    debug = "--debug" in argv
    verbose = sum(a.count("v") for a in argv if a in ("-v", "-vv", "-vvv")) + argv.count("--verbose")
    quiet = "-q" in argv or "--quiet" in argv
    rest = [a for a in argv if a not in ("--debug", "-v", "-vv", "-vvv", "--verbose", "-q", "--quiet")]
    if quiet and command == "train":
        rest.append("--quiet")
    configure_logging(verbose, quiet)

    def run():
        try:
            from vfactor.net.commands import main as net_main
        except ImportError as exc:
            from vfactor.cli.common import missing_extra

            if "-h" in rest or "--help" in rest:  # asked what the command is: say it, and what its options need
                print(f"vfactor {command}: {NET_COMMANDS[command]}.\n{missing_extra('', exc, 'net')}; "
                      f"then vfactor help {command} lists its options.")
                return EXIT_OK
            raise missing_extra("", exc, "net") from None
        return net_main(rest, prog="vfactor")

    return _guarded(command, run, debug)
