"""``vfactor solve`` and ``vfactor track``: estimate every vehicle of a scene file, write the result."""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np

from vfactor.cli.common import (EXIT_INPUT, EXIT_OK, EXIT_UNSOLVED, amodal_pass, check_amodal_pass, check_out_file,
                                check_outputs, detect, note, open_command_engine, output, progress, report_unsolved,
                                say)
from vfactor.cli.scenes import scene_jobs
from vfactor.cli.stream import is_stream, track_stream_command
from vfactor.cli.interop import name_file_pairs
from vfactor.errors import InputError
from vfactor.result import Status

__all__ = ["solve", "track", "load_input", "associate", "write_output"]


def load_input(args):
    """The scene of ``solve`` and ``track``, with the ``--camera NAME=FILE`` calibrations in it."""
    from vfactor.scene import load_scene

    try:
        return load_scene(args.scene, allow_outside_paths=args.allow_outside_paths,
                          camera_files=name_file_pairs(args.camera, "--camera"))
    except InputError as exc:
        if exc.field.startswith("camera_files."):  # name the option the user typed
            name = exc.field.split(".", 1)[1].split(":", 1)[0]
            raise type(exc)(f"--camera {name}", exc.problem) from None
        raise


def associate(scene, args, force: bool | None = None, engine=None):
    """The scene with its vehicles found (vfactor.association) where the detections name none, or everywhere
    with ``force`` (default: ``--associate``), and the :class:`~vfactor.association.Association`; the scene as it
    is and None otherwise. ``engine``: where the frames' pair tests run (``--workers`` / ``--scheduler``)."""
    force = args.associate if force is None else force
    todo = len(scene.unassigned()) if not force else sum(len(f.detections) for f in scene.frames)
    if not todo:
        return scene, None
    from vfactor.association import associate_scene

    t0 = time.perf_counter()
    found = associate_scene(scene, force=force, progress=progress("associating", not args.quiet), engine=engine)
    for message in found.messages:
        note(message)
    single = sum(len(ids) for ids in found.single_view)
    vehicles = sum(len(groups) for groups in found.groups)
    output(args)(f"associated {todo - len(found.left_out)} detections into {vehicles} vehicles over the frames "
                 f"({single} seen by one camera only), {len(found.vehicle_ids)} ids"
                 + (f", {len(found.left_out)} left out" if found.left_out else "")
                 + f" ({time.perf_counter() - t0:.2f} s)")
    for line, every in left_out_lines(found.left_out):
        note(line)
        if every:
            logging.getLogger("vfactor").info(every)
    return found.scene, found


def left_out_lines(left_out: list[tuple[int, int, str]], shown: int = 5) -> list[tuple[str, str]]:
    """Per reason, the note on the detections the association left out (``(frame, detection, why)``): the first
    ``shown`` named, and the line that names every one (for ``-v``; empty when the note names them all), so that
    nothing the user gave goes unsaid."""
    reasons: dict[str, list[str]] = {}
    for f, j, why in left_out:
        reasons.setdefault(why, []).append(f"frames[{f}].detections[{j}]")
    return [(f"left out {len(where)} detections: {why}: " + ", ".join(where[:shown]) +
             (", ... (every one with -v)" if len(where) > shown else ""),
             f"left out {len(where)} detections: {why}: " + ", ".join(where) if len(where) > shown else "")
            for why, where in reasons.items()]


def write_output(args, results, scene) -> None:
    """Writes the results to ``--out`` in ``--format`` (vfactor.formats); says which unsolved vehicles a format
    has no place for, and what the output folder holds besides this run's."""
    from vfactor.formats import write_results

    options = {"frame": args.kitti_frame} if getattr(args, "kitti_frame", None) else {}
    report = write_results(args.out, results, scene, args.format, **options)
    if report.skipped or report.foreign:
        note(report.note())


class _Engine:
    """The engine of ``--workers`` / ``--scheduler`` (vfactor.parallel), started when first needed (a cluster takes
    seconds to start: not before the options and the first scene are checked) and shared by every scene."""

    def __init__(self, args):
        self.args, self.engine = args, None

    def get(self):
        if self.engine is None:
            self.engine = open_command_engine(self.args.workers, self.args.scheduler)
        return self.engine

    def close(self):
        if self.engine is not None:
            self.engine.close()


def _each_scene(args, run) -> int:
    """Runs ``run(args, engine)`` on the scene file, or on each scene of a folder or glob (docs/scaling.md)
    with its own result under the folder ``--out``. With many scenes a bad one is reported (its file and
    the field) and the others are still done; the exit code is then 2."""
    from vfactor.parallel import check_engine_options

    check_engine_options(args.workers, args.scheduler)
    jobs = scene_jobs(args)
    engine = _Engine(args)
    try:
        if jobs is None:
            return run(args, engine)
        codes = []
        for job in jobs:
            try:
                codes.append(run(job, engine))
            except InputError as exc:
                say(f"{job.scene}: {exc}")
                codes.append(EXIT_INPUT)
        if not args.quiet:
            print(f"{len(jobs)} scenes: {codes.count(EXIT_OK)} done, {codes.count(EXIT_UNSOLVED)} with unsolved "
                  f"vehicles, {codes.count(EXIT_INPUT)} not read; results in {args.out}")
        return EXIT_INPUT if EXIT_INPUT in codes else max(codes, default=EXIT_OK)
    finally:
        engine.close()


def solve(args) -> int:
    return _each_scene(args, _solve_one)


def _solve_one(args, engine: _Engine) -> int:
    from vfactor.factors.robust import RobustLoss
    from vfactor.graph import GraphConfig
    from vfactor.solve import SolveOptions, iter_solve_scene

    check_outputs(args)
    raw = load_input(args)
    check_amodal_pass(raw, args)
    given = detect(raw, args, engine.get())
    scene, association = associate(given, args, engine=engine.get())
    options = SolveOptions(graph=GraphConfig(loss=RobustLoss(args.loss)), covariance=not args.no_covariance)
    t0 = time.perf_counter()
    results = []
    solved_frames = iter_solve_scene(scene, options, progress=progress("solving", not args.quiet), engine=engine.get())
    if args.amodal_pass:  # the first solve gives the clipped vehicles' whole boxes; only the frames it changes again
        first, before = list(solved_frames), scene
        scene, _ = amodal_pass(scene, first, args, engine.get())
        again = {i for i, (old, new) in enumerate(zip(before.frames, scene.frames))
                 if any(a is not b for a, b in zip(old.detections, new.detections))}
        redone = iter_solve_scene(dataclasses.replace(scene, frames=[scene.frames[i] for i in sorted(again)]),
                                  options, progress=progress("solving again", not args.quiet), engine=engine.get())
        solved_frames = (next(redone) if i in again else frame for i, frame in enumerate(first))

    def frames():  # written to --out as they come (vfactor.formats.write_results)
        for frame in solved_frames:
            if association is not None:
                association.restore_indices([frame], len(results))
            results.append(frame)
            yield frame

    write_output(args, frames(), scene)
    _plane_note(results, scene)
    vehicles = [v for fr in results for v in fr.vehicles]
    solved = sum(v.ok for v in vehicles)
    poor = sum(v.status == Status.POOR_FIT for v in vehicles)
    if not args.quiet:
        print(f"solved {solved} of {len(vehicles)} vehicles" + (f" ({poor} a poor fit)" if poor else "")
              + f" in {len(results)} frames ({time.perf_counter() - t0:.2f} s); wrote {args.out}")
    return report_unsolved(results, scene, args.quiet)


def _plane_note(results, scene) -> None:
    """Says so where the solved vehicles do not stand on the scene's road plane
    (:func:`vfactor.ground_fit.plane_note`)."""
    if scene.ground_plane is not None:
        from vfactor.ground_fit import plane_note

        text = plane_note(results, scene.ground_plane)
        if text:
            note(text)


def track(args) -> int:
    if args.lag is not None and not (np.isfinite(args.lag) and args.lag > 0):
        raise InputError("--lag", f"expected a positive number of seconds, got {args.lag}")
    if args.batch and (args.lag is not None or args.online):
        raise InputError("--batch", "batch smoothing uses every frame: it takes neither --lag nor --online")
    if is_stream(args):
        if args.amodal_pass:
            raise InputError("--amodal-pass",
                             "not with a stream (--follow or standard input): it solves the scene twice")
        return track_stream_command(args)
    if args.idle_timeout is not None:
        raise InputError("--idle-timeout", "only with --follow")
    return _each_scene(args, _track_one)


def _track_one(args, engine: _Engine) -> int:
    from vfactor.solve import SolveOptions
    from vfactor.track import TrackOptions, scene_notes, smooth_scene, track_scene

    check_outputs(args)
    if args.plot:
        check_out_file(args.plot, "--plot", [("scene file", args.scene), ("result file --out", args.out)])
    raw = load_input(args)
    check_amodal_pass(raw, args)
    given = detect(raw, args, engine.get())
    scene, association = associate(given, args, engine=engine.get())
    options = TrackOptions(solve=SolveOptions(covariance=False), lag=args.lag, covariance=not args.no_covariance,
                           detector_offsets=args.detector_offsets)
    where = engine.get()
    t0 = time.perf_counter()

    def estimate(scene):
        if args.batch:
            smoothed = smooth_scene(scene, options, progress=progress("smoothing", not args.quiet), engine=where)
            return smoothed, scene_notes(scene, smoothed)
        run = track_scene(scene, options, progress=progress("tracking", not args.quiet), engine=where)
        return (run.online if args.online else run.frames), run.messages

    results, messages = estimate(scene)
    if args.amodal_pass:  # the tracks give the clipped vehicles' whole boxes; the scene is tracked again
        scene, replaced = amodal_pass(scene, results, args, where)
        if replaced:
            results, messages = estimate(scene)
    if association is not None:
        association.restore_indices(results)
    write_output(args, results, scene)
    for message in messages:
        note(message)
    _plane_note(results, scene)
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
    return report_unsolved(results, scene, args.quiet)

